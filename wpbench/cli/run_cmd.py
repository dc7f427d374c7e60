"""``wpbench run``: evaluate one policy on one task in the simulator."""

from __future__ import annotations

from pathlib import Path

import typer

from wpbench import names
from wpbench.cli.choices import check_choice

def _policy_names() -> list[str]:
    from wpbench.policies.registry import available_policies

    return available_policies()


def run(
    policy: str = typer.Option("wp", help="Policy name (see `wpbench run --policy list`)."),
    task: str = typer.Option("open-then-place", help=f"One of: {', '.join(names.BUILTIN_TASKS)}, or a task of "
                                                       f"your own registered through ${names.PLUGINS_VARIABLE}."),
    split: str = typer.Option("val", help=f"Furniture split: {', '.join(names.RUN_SPLITS)}."),
    episodes: int = typer.Option(50, min=1, help="Number of episodes."),
    seed: int = typer.Option(0, help="Run seed; episode i uses a seed derived from (seed, i)."),
    assets: str = typer.Option("procedural", help="'procedural' (built-in furniture) or a PartNet-Mobility folder."),
    obs: str = typer.Option("camera", help="Observation: camera (depth + segmentation) or mesh (surface samples)."),
    out: Path = typer.Option(None, help="Output folder [default: results/runs/<policy>__<task>__<split>__<assets>__<obs>]."),
    resume: bool = typer.Option(False, help="Skip episodes already written in --out."),
    record: Path = typer.Option(None, help="Write a rerun recording (.rrd) of the run."),
    num_action_points: int = typer.Option(256, min=8, help="Action-object points per observation."),
    num_anchor_points: int = typer.Option(1024, min=8, help="Anchor-object points per observation."),
    progress: bool = typer.Option(True, help="Show a progress bar."),
    weights_root: Path = typer.Option(
        None, help="Load trained policies from this folder instead of policies/weights (an experiment's "
                   "weights); the run then goes to <weights-root>/runs/ unless --out says otherwise."),
    subsets: int = typer.Option(
        None, min=1, help="Trained policies: random subsets of each observation answered and fused into one pose "
                          "[default: the policy's, wpbench.models.configs.DEFAULT_SUBSETS]."),
    mirror_views: bool = typer.Option(
        None, help="Trained policies: answer every second subset in the mirrored scene "
                   "[default: the policy's, wpbench.models.configs.DEFAULT_MIRROR_VIEWS]."),
) -> None:
    """Run POLICY on TASK for N episodes: progress bar, summary table, episodes.jsonl and summary.json."""
    if policy == "list":
        typer.echo("\n".join(_policy_names()))
        raise typer.Exit(0)
    check_choice("policy", policy, _policy_names())
    try:
        task_names = names.task_names()
    except ValueError as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(2)
    check_choice("task", task, task_names)
    check_choice("split", split, names.RUN_SPLITS)
    check_choice("observation mode", obs, names.OBS_MODES)
    if assets != "procedural" and not Path(assets).is_dir():
        raise typer.BadParameter(f"--assets must be 'procedural' or an existing folder; {assets!r} is neither")
    policy_kwargs = {}
    learned = names.WEIGHTED_POLICIES
    for flag, value in (("--weights-root", weights_root), ("--subsets", subsets), ("--[no-]mirror-views", mirror_views)):
        if value is not None and policy not in learned:
            raise typer.BadParameter(f"{flag} applies to the trained policies ({', '.join(learned)}); "
                                     f"{policy!r} loads no weights")
    if subsets is not None:
        policy_kwargs["subsets"] = subsets
    if mirror_views is not None:
        policy_kwargs["mirror_views"] = mirror_views
    if weights_root is not None:
        if not weights_root.is_dir():
            raise typer.BadParameter(f"--weights-root {weights_root} is not a folder; train into it with "
                                     f"`wpbench train --policy NAME --weights-root {weights_root}`")
        # A string, so that run.json records it as written.
        policy_kwargs["weights_root"] = str(weights_root)
    from wpbench.evaluation.runner import RunConfig, run_benchmark
    from wpbench.evaluation.summary import format_summary_table

    cfg = RunConfig(policy=policy, task=task, split=split, episodes=episodes, seed=seed, assets=assets,
                    obs=obs, out=out, resume=resume, record=record, num_action_points=num_action_points,
                    num_anchor_points=num_anchor_points, policy_kwargs=policy_kwargs)
    if out is None and weights_root is not None:
        # Keep an experiment's runs beside its weights, away from the shipped results/runs/.
        cfg.out = weights_root / "runs" / cfg.default_out().name
    observer = None
    if record is not None:
        from wpbench.evaluation.recording import RerunRecorder

        observer = RerunRecorder(record, application=f"wpbench {policy} {task}")
    try:
        summary = run_benchmark(cfg, progress=progress, observer=observer)
    except (ValueError, FileExistsError, FileNotFoundError) as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(2)
    finally:
        if observer is not None:
            observer.close()
    typer.echo(format_summary_table(summary))
    typer.echo(f"results: {summary['_out_dir']}/episodes.jsonl, summary.json")
    if record is not None:
        typer.echo(f"recording: {record} (open with `rerun {record}`)")
