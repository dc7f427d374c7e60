"""``wpbench run``: evaluate one policy on one task in the simulator."""

from __future__ import annotations

from pathlib import Path

import typer

from wpbench import names
from wpbench.cli.camera_noise_options import (
    camera_noise_settings,
    depth_holes_option,
    depth_noise_option,
    edge_holes_option,
    seg_noise_option,
)
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
    depth_noise: float = depth_noise_option(),
    depth_holes: float = depth_holes_option(),
    edge_holes: bool = edge_holes_option(),
    seg_noise_px: int = seg_noise_option(),
    out: Path = typer.Option(None, help="Output folder [default: results/runs/<policy>__<task>__<split>__<assets>__<obs>]."),
    resume: bool = typer.Option(False, help="Skip episodes already written in --out."),
    record: Path = typer.Option(None, help="Write a rerun recording (.rrd) of the run."),
    num_action_points: int = typer.Option(256, min=8, help="Action-object points per observation."),
    num_anchor_points: int = typer.Option(1024, min=8, help="Anchor-object points per observation."),
    progress: bool = typer.Option(True, help="Show a progress bar."),
    workers: int = typer.Option(
        None, min=1, help="Worker processes running episodes side by side [default: the number of cores; "
                          "1 with --record]. The records are the same whatever the number."),
    ray: str = typer.Option(
        None, "--ray", metavar="ADDRESS",
        help="Run the episodes on a Ray cluster: 'local' (or --ray alone) starts one on this machine, 'auto' joins "
             "the one this machine belongs to, HOST:PORT another one. --workers then caps the actors (default: one per CPU "
             "of the cluster)."),
    shard: str = typer.Option(
        None, metavar="I/N", help="Run only the episodes whose index is I modulo N (job arrays), into a folder of "
                                  "its own; join the shards with `wpbench merge`."),
    executor: str = typer.Option(names.DEFAULT_EXECUTOR, help=f"How a predicted cross-pose is carried out: "
                                                              f"{', '.join(names.EXECUTORS)} (docs/executors.md)."),
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
    check_choice("executor", executor, names.EXECUTORS)
    camera_noise = camera_noise_settings(obs, depth_noise, depth_holes, edge_holes, seg_noise_px)
    if shard is not None:
        from wpbench.evaluation.runner import parse_shard

        try:
            parse_shard(shard)
        except ValueError as err:
            raise typer.BadParameter(str(err)) from None
    if record is not None:
        if workers not in (None, 1) or ray is not None:
            raise typer.BadParameter("--record needs the episodes in this process: use --workers 1 without --ray")
        record = free_recording_path(record)
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
                    num_anchor_points=num_anchor_points, policy_kwargs=policy_kwargs, executor=executor,
                    shard=shard, camera_noise=camera_noise)
    if out is None and weights_root is not None:
        # Keep an experiment's runs beside its weights, away from the shipped results/runs/.
        cfg.out = weights_root / "runs" / cfg.default_out().name
    observer = None
    if record is not None:
        from wpbench.evaluation.recording import RerunRecorder

        observer = RerunRecorder(record, application=f"wpbench {policy} {task}")
    from wpbench.evaluation.local_workers import available_cores

    count = 1 if record is not None else workers if ray is not None else (workers or available_cores())
    summary = execute(lambda: run_benchmark(cfg, progress=progress, observer=observer, workers=count,
                                            use_ray=ray is not None, ray_address=ray_address(ray)),
                      out_dir=cfg.out or cfg.default_out(), finally_=observer.close if observer else None)
    for note in summary.get("_notes", []):
        typer.echo(f"note: {note}", err=True)
    typer.echo(format_summary_table(summary))
    typer.echo(f"results: {summary['_out_dir']}/episodes.jsonl, summary.json")
    if record is not None:
        typer.echo(f"recording: {record} (open with `rerun {record}`)")


def ray_address(option: str | None) -> str | None:
    """``--ray`` as Ray's ``address``: None (start a local cluster) for 'local', else as given."""
    return None if option in (None, "local") else option


def free_recording_path(path: Path) -> Path:
    """``path``, or ``<stem>-2.rrd``, ``-3``... if it exists: an earlier recording is never
    overwritten (``--resume --record`` records the new episodes beside it)."""
    if path.is_dir():
        fail(f"--record {path} is a folder; give a file name such as {path / 'run.rrd'}")
    fresh, number = path, 2
    while fresh.exists():
        fresh = path.with_name(f"{path.stem}-{number}{path.suffix}")
        number += 1
    try:  # rerun reports an unwritable path only as a RuntimeError deep inside
        fresh.parent.mkdir(parents=True, exist_ok=True)
        with open(fresh, "xb"):
            pass
        fresh.unlink()
    except OSError as err:
        fail(f"cannot write the recording {fresh} ({err.strerror or err}); choose a writable --record path")
    if fresh != path:
        typer.echo(f"note: {path} exists (an earlier recording, kept); recording to {fresh}", err=True)
    return fresh


def fail(message: str, code: int = 2) -> None:
    typer.echo(f"Error: {message}", err=True)
    raise typer.Exit(code)


def resume_command() -> str:
    """The command line that was run, with --resume: how to continue an interrupted run."""
    import shlex
    import sys

    arguments = [a for a in sys.argv[1:]]
    if "--resume" not in arguments:
        arguments.append("--resume")
    return shlex.join(["wpbench", *arguments])


def execute(call, out_dir: Path, finally_=None):
    """``call()`` with the run's errors as one-line messages that say what to do (exit 2),
    and Ctrl-C as the resume command (exit 130)."""
    from wpbench.evaluation.driver import RunInterrupted
    from wpbench.evaluation.interrupt import INTERRUPTED_EXIT_CODE
    from wpbench.evaluation.local_workers import WorkerError
    from wpbench.evaluation.run_lock import RunLockedError

    try:
        return call()
    except RunInterrupted as err:
        typer.echo(f"{err}; continue with:\n  {resume_command()}", err=True)
        raise typer.Exit(INTERRUPTED_EXIT_CODE)
    except KeyboardInterrupt:
        typer.echo(f"aborted; finished episodes are kept in {out_dir}; continue with:\n  {resume_command()}",
                   err=True)
        raise typer.Exit(INTERRUPTED_EXIT_CODE)
    except (ValueError, FileExistsError, FileNotFoundError, RunLockedError, WorkerError) as err:
        fail(str(err))
    except OSError as err:
        fail(filesystem_message(err, out_dir))
    finally:
        if finally_ is not None:
            finally_()


def filesystem_message(err: OSError, out_dir: Path) -> str:
    """One line for a file-system error: what failed and what to do."""
    import errno

    from wpbench.evaluation.records import RecordWriteError

    if isinstance(err, RecordWriteError):
        return str(err)
    where = err.filename or out_dir
    if err.errno == errno.ENOSPC:
        return f"disk full writing {where}; free space, then rerun with --resume (finished episodes are kept)"
    if err.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
        return f"cannot write to {where} ({err.strerror}); choose a writable --out"
    return f"cannot use {where} ({err.strerror or err}); check the path and rerun (with --resume to continue)"
