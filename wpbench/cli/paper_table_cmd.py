"""``wpbench paper-table``: results/paper-table.md in one command."""

from __future__ import annotations

from pathlib import Path

import typer


def paper_table(
    data: Path = typer.Option(Path("data"), help="Data root made by `wpbench data generate` (train/ and val/)."),
    samples: int = typer.Option(200, min=1, help="Samples per split and kind for the pose errors."),
    episodes: int = typer.Option(100, min=1, help="Simulated episodes per policy and task."),
    obs: str = typer.Option("camera", help="Observation mode of the simulated runs."),
    run_missing: bool = typer.Option(True, help="Run the simulations that results/runs lacks."),
    subsets: int = typer.Option(None, min=1, help="Random point subsets per sample, fused into one pose "
                                                  "[default: as the learned policies answer]."),
    mirror_views: bool = typer.Option(None, help="Answer every second subset in the mirrored scene "
                                                 "[default: as the learned policies answer]."),
    results: Path = typer.Option(Path("results"), help="Results folder: the runs are read from RESULTS/runs, and "
                                                        "missing ones are written there."),
    out: Path = typer.Option(None, help="Markdown file to write [default: RESULTS/paper-table.md]."),
    workers: int = typer.Option(None, min=1, help="Worker processes for the missing runs, all run as one sweep "
                                                  "[default: the number of cores]."),
    ray: str = typer.Option(None, "--ray", metavar="ADDRESS", help="Run the missing runs on a Ray cluster instead: "
                                                                   "'local' (or --ray alone), 'auto' or HOST:PORT."),
    executors: str = typer.Option("ideal", help="Executors whose missing val runs are run (comma-separated: ideal, "
                                                "gripper, panda); the table shows every executor's runs it finds."),
) -> None:
    """Pose errors (train/val x free-floating/articulated) and simulated success of every learned policy."""
    from wpbench.cli.choices import check_choice, split_names
    from wpbench.evaluation.paper_table import PaperTableConfig, make_paper_table

    from wpbench.names import EXECUTORS, OBS_MODES

    check_choice("observation mode", obs, OBS_MODES)
    executor_names = tuple(split_names(executors))
    for name in executor_names:
        check_choice("executor", name, EXECUTORS)
    if not (data / "train").is_dir() or not (data / "val").is_dir():
        raise typer.BadParameter(f"{data} lacks train/ and val/; make them with `wpbench data generate --out {data}`")
    ensemble = {key: value for key, value in (("subsets", subsets), ("mirror_views", mirror_views)) if value is not None}
    from wpbench.cli.run_cmd import ray_address
    from wpbench.evaluation.local_workers import available_cores

    cfg = PaperTableConfig(data=data, samples_per_kind=samples, episodes=episodes, obs=obs, run_missing=run_missing,
                           results=results, workers=workers if ray is not None else (workers or available_cores()),
                           use_ray=ray is not None, ray_address=ray_address(ray), executors=executor_names,
                           **ensemble)
    from wpbench.evaluation.executor_version import OlderExecutorError
    from wpbench.evaluation.furniture_version import OtherFurnitureError

    try:
        path = make_paper_table(cfg, out)
    except (OtherFurnitureError, OlderExecutorError) as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(2)
    typer.echo(path.read_text())
    typer.echo(f"written: {path}")
