"""``wpbench bench``: speed and memory benchmarks that print tables.

Each command imports its benchmark module (``wpbench.bench.*``, which pulls in
torch and maybe SAPIEN) only when it runs. Timings are wall-clock on the current
machine: on a shared CPU they are pessimistic, so compare numbers from one run.
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path
from types import ModuleType
from typing import Any, Optional

import typer

app = typer.Typer(
    help="Speed and memory benchmarks (each prints a table; --json also saves it).",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,  # plain help, like the top-level `wpbench --help`
)

_JSON_HELP = "Also write the measurements to this JSON file."


def _load(module_name: str) -> ModuleType:
    """Import a benchmark module or exit with a one-line error saying why."""
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        if error.name and module_name.startswith(error.name):
            typer.echo(f"Error: benchmark module {module_name} is not part of this checkout yet.", err=True)
            raise typer.Exit(1) from error
        raise


def _call_with_supported(function: Any, **candidates: Any) -> Any:
    """Call ``function`` with the options the user gave (``None`` = not given).

    Options not given are left out so the benchmark's own defaults apply. A given
    option the benchmark's signature does not take is an error, not silently
    ignored.
    """
    given = {k: v for k, v in candidates.items() if v is not None}
    parameters = inspect.signature(function).parameters
    takes_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values())
    unused = [k for k in given if not takes_any and k not in parameters]
    if unused:
        options = ", ".join("--" + name.replace("_", "-") for name in unused)
        typer.echo(f"Error: this benchmark does not take {options}.", err=True)
        raise typer.Exit(2)
    return function(**given)


@app.command()
def svd(
    batch: int = typer.Option(64, min=1, help="Batch size B of the weighted SVD."),
    points: int = typer.Option(1024, min=3, help="Points per cloud N."),
    json_path: Optional[Path] = typer.Option(None, "--json", help=_JSON_HELP),
) -> None:
    """Weighted Procrustes / weighted-pose SVD: time and memory vs batch and points."""
    _load("wpbench.bench.svd").run(batch=batch, points=points, json_path=json_path)


@app.command()
def models(
    json_path: Optional[Path] = typer.Option(None, "--json", help=_JSON_HELP),
) -> None:
    """Forward/backward time and parameter counts of TAX-Pose, Goal Flow, WeightedPose."""
    _load("wpbench.bench.models").run(json_path=json_path)


@app.command()
def episodes(
    episodes: Optional[int] = typer.Option(None, min=1, help="Episodes per task and observation mode."),
    task: Optional[list[str]] = typer.Option(None, help="Task to time; repeat for several (default: all)."),
    obs: Optional[list[str]] = typer.Option(None, help="Observation mode; repeat for several (default: all)."),
    policy: Optional[str] = typer.Option(None, help="Policy to time, if the benchmark supports choosing one."),
    executor: Optional[str] = typer.Option(None, help="Executor (ideal, gripper, panda); default: ideal."),
    json_path: Optional[Path] = typer.Option(None, "--json", help=_JSON_HELP),
) -> None:
    """Simulation throughput: episodes per minute and peak memory per task."""
    module = _load("wpbench.bench.episodes")
    _call_with_supported(
        module.run,
        episodes=episodes,
        tasks=tuple(task) if task else None,
        obs_modes=tuple(obs) if obs else None,
        policy=policy,
        executor=executor,
        json_path=json_path,
    )


@app.command()
def workers(
    episodes: int = typer.Option(100, min=4, help="Episodes per schedule (1 worker, 2 workers, Ray with 2)."),
    policy: str = typer.Option("wp", help="Policy to run."),
    task: str = typer.Option("open-then-place", help="Task to run."),
    obs: str = typer.Option("mesh", help="Observation mode."),
    json_path: Optional[Path] = typer.Option(None, "--json", help=_JSON_HELP),
) -> None:
    """Episodes per minute with 1 and 2 workers, Ray's overhead per episode, and a scaling model."""
    from wpbench.cli.choices import check_choice
    from wpbench.names import BUILTIN_TASKS, OBS_MODES
    from wpbench.policies.registry import available_policies

    check_choice("policy", policy, available_policies())
    check_choice("task", task, BUILTIN_TASKS)
    check_choice("observation mode", obs, OBS_MODES)
    _load("wpbench.bench.workers").run(episodes=episodes, policy=policy, task=task, obs=obs, json_path=json_path)
