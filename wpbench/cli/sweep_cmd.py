"""``wpbench sweep``: many runs at once, then the leaderboard."""

from __future__ import annotations

from pathlib import Path

import typer

from wpbench import names
from wpbench.cli.choices import check_choice, split_names


def sweep(
    policies: str = typer.Option(..., help="Policies, comma- or space-separated."),
    tasks: str = typer.Option(",".join(names.BUILTIN_TASKS), help="Tasks."),
    executors: str = typer.Option(names.DEFAULT_EXECUTOR, help=f"Executors ({', '.join(names.EXECUTORS)})."),
    assets: str = typer.Option("procedural", help="Asset sources: 'procedural' and/or PartNet-Mobility folders."),
    splits: str = typer.Option("val", help=f"Furniture splits ({', '.join(names.RUN_SPLITS)})."),
    episodes: int = typer.Option(50, min=1, help="Episodes per run."),
    obs: str = typer.Option("camera", help=f"Observation mode ({', '.join(names.OBS_MODES)})."),
    seed: int = typer.Option(0, help="Run seed of every run."),
    results: Path = typer.Option(Path("results"), help="Results folder: runs go to RESULTS/runs/<run>, the "
                                                        "leaderboard to RESULTS."),
    workers: int = typer.Option(None, min=1, help="Worker processes (default: the number of cores)."),
    ray: str = typer.Option(None, "--ray", metavar="ADDRESS", help="Run on a Ray cluster instead: 'local' (or --ray "
                                                                   "alone), 'auto' or HOST:PORT."),
    progress: bool = typer.Option(True, help="Show the progress bar."),
) -> None:
    """Every combination of POLICIES x TASKS x EXECUTORS x ASSETS x SPLITS, all episodes scheduled at once over
    all workers, each run resumable in its own folder; the leaderboard is rebuilt at the end."""
    from wpbench.cli.run_cmd import execute, ray_address
    from wpbench.evaluation.local_workers import available_cores
    from wpbench.evaluation.sweep import run_sweep, sweep_configs
    from wpbench.policies.registry import available_policies

    lists = {"policy": (split_names(policies), available_policies()), "task": (split_names(tasks), names.task_names()),
             "executor": (split_names(executors), names.EXECUTORS), "split": (split_names(splits), names.RUN_SPLITS)}
    for what, (given, valid) in lists.items():
        for item in given:
            check_choice(what, item, valid)
    check_choice("observation mode", obs, names.OBS_MODES)
    for source in split_names(assets):
        if source != "procedural" and not Path(source).is_dir():
            raise typer.BadParameter(f"--assets must be 'procedural' or existing folders; {source!r} is neither")
    configs = sweep_configs(lists["policy"][0], lists["task"][0], episodes, results, split_names(assets),
                            lists["split"][0], lists["executor"][0], obs, seed)
    count = workers if ray is not None else (workers or available_cores())
    summaries = execute(lambda: run_sweep(configs, results, workers=count, use_ray=ray is not None,
                                          ray_address=ray_address(ray), progress=progress), out_dir=results)
    for summary in summaries:
        for note in summary.get("_notes", []):
            typer.echo(f"note: {note}", err=True)
    typer.echo(f"{len(summaries)} runs in {results}/runs; leaderboard: {results}/leaderboard.md")
