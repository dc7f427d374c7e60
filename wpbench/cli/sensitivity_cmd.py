"""``wpbench sensitivity``: gt under controlled perturbations of the true cross-pose,
success rate against perturbation size, as CSV and PNG (wpbench.evaluation.sensitivity)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from wpbench.cli.choices import choice_callback
from wpbench.names import EXECUTORS, OBS_MODES

GRASPS = ("friction", "suction")   # mirrors wpbench.sim.gripper_executor.GRASPS (kept literal: --help stays light)


def sensitivity(
    executor: Optional[str] = typer.Option(None, "--executor", callback=choice_callback("executor", EXECUTORS),
                                           help="Executor: " + ", ".join(EXECUTORS) + " (required unless --plot-only)."),
    task: str = typer.Option(..., "--task", help="Task name (e.g. open-door, place-in, open-then-place)."),
    episodes: int = typer.Option(16, "--episodes", min=1, help="Episodes (seeds) per perturbation size."),
    grasp: str = typer.Option("suction", "--grasp", callback=choice_callback("grasp", GRASPS),
                              help="Gripper grasp (executor gripper only)."),
    perturbation: Optional[list[str]] = typer.Option(None, "--perturbation",
                                                     help="Only these perturbations (repeatable; default: all that apply)."),
    obs: str = typer.Option("mesh", "--obs", callback=choice_callback("observation mode", OBS_MODES),
                            help="Observation mode."),
    split: str = typer.Option("val", "--split", help="Furniture split."),
    out: Path = typer.Option(Path("results/sensitivity"), "--out", help="Folder for the CSV and PNG."),
    plot_only: bool = typer.Option(False, "--plot-only",
                                   help="Run nothing: redraw <out>/<task>.png from the CSVs already in <out>."),
) -> None:
    """Run gt under rotation, translation (random, toward the nearest wall, and into it by a
    given overlap) and, for doors, hinge tilt and motion scale; write
    <out>/<task>_<executor>[_<grasp>].csv and .png, then redraw <out>/<task>.png with every
    executor's CSV in <out> side by side."""
    from wpbench.evaluation.sensitivity import plot_curves, plot_task, read_csv, run_sensitivity, write_csv
    from wpbench.names import task_info

    try:
        task_info(task)
    except ValueError as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(2) from err
    if plot_only:
        try:
            typer.echo(f"wrote {plot_task(out, task)}")
        except ValueError as err:
            typer.echo(f"Error: {err}", err=True)
            raise typer.Exit(2) from err
        return
    if executor is None:
        typer.echo("Error: --executor is required (or pass --plot-only to redraw from existing CSVs).", err=True)
        raise typer.Exit(2)

    def show(point) -> None:
        stages = f"  stages {'/'.join(map(str, point.stage_successes))}" if len(point.stage_successes) > 1 else ""
        errors = f"  ({point.errors} simulator errors)" if point.errors else ""
        typer.echo(f"{point.perturbation:>16} {point.size:6.2f}: {point.successes}/{point.episodes}{stages}{errors}")

    try:
        points = run_sensitivity(task, executor, grasp, episodes, obs_mode=obs, split=split,
                                 perturbations=tuple(perturbation) if perturbation else None, on_point=show)
    except ValueError as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(2) from err
    stem = f"{task}_{executor}" + (f"_{grasp}" if executor == "gripper" else "")
    csv_path = write_csv(points, out / f"{stem}.csv")
    png = plot_curves(read_csv(csv_path), out / f"{stem}.png", title=f"{task}, {executor}")
    typer.echo(f"wrote {csv_path}, {png} and {plot_task(out, task)}")
