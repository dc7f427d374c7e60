"""The ``wpbench`` command line (typer).

Command groups live in sibling modules, one per group, and are imported only
when used, so ``wpbench --help`` stays fast and never imports torch or SAPIEN:

| command       | module                       | object |
|---------------|------------------------------|--------|
| `run`         | `wpbench.cli.run_cmd`        | `run` (a function) |
| `merge`       | `wpbench.cli.merge_cmd`      | `merge` (a function) |
| `sweep`       | `wpbench.cli.sweep_cmd`      | `sweep` (a function) |
| `assets`      | `wpbench.cli.assets_cmd`     | `app` (typer) |
| `data`        | `wpbench.cli.data_cmd`       | `app` (typer) |
| `train`       | `wpbench.cli.train_cmd`      | `app` (typer) |
| `bench`       | `wpbench.cli.bench_cmd`      | `app` (typer) |
| `leaderboard` | `wpbench.cli.leaderboard_cmd`| `leaderboard` (a function) |

A group whose module does not exist (yet) is simply not listed. A group whose
module exists but fails to import is listed and reports the import error when
invoked, instead of breaking every other command.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass
from difflib import get_close_matches
from typing import Any

import typer
from typer.core import TyperGroup

try:  # typer >= 0.16 vendors click
    from typer._click.exceptions import UsageError
except ImportError:  # pragma: no cover - older typer uses click itself
    from click.exceptions import UsageError

__all__ = ["app", "main", "LazyCommand", "LAZY_COMMANDS"]


@dataclass(frozen=True)
class LazyCommand:
    """Where to find a command: ``module:attribute``, and its one-line help.

    The attribute may be a ``typer.Typer`` (mounted as a group), a click
    command, or a plain function (mounted as a single command).
    """

    name: str
    module: str
    attribute: str
    short_help: str


LAZY_COMMANDS: tuple[LazyCommand, ...] = (
    LazyCommand("run", "wpbench.cli.run_cmd", "run", "Run a policy on a task in simulation and score it."),
    LazyCommand("sweep", "wpbench.cli.sweep_cmd", "sweep",
                "Run every combination of policies, tasks, ... at once, then the leaderboard."),
    LazyCommand("merge", "wpbench.cli.merge_cmd", "merge", "Join the shards of a run (run --shard i/N) into one."),
    LazyCommand("assets", "wpbench.cli.assets_cmd", "app", "List, build and inspect furniture assets."),
    LazyCommand("data", "wpbench.cli.data_cmd", "app", "Generate training data from the simulator."),
    LazyCommand("train", "wpbench.cli.train_cmd", "app", "Train the cross-pose models."),
    LazyCommand("bench", "wpbench.cli.bench_cmd", "app", "Speed and memory benchmarks (print tables)."),
    LazyCommand("paper-table", "wpbench.cli.paper_table_cmd", "paper_table",
                "Write results/paper-table.md (the paper's Table 1 layout + simulated success)."),
    LazyCommand(
        "leaderboard", "wpbench.cli.leaderboard_cmd", "leaderboard",
        "Collect results/**/summary.json into leaderboard md/csv/png.",
    ),
    LazyCommand("sensitivity", "wpbench.cli.sensitivity_cmd", "sensitivity",
                "gt under perturbed cross-poses: success against perturbation size (CSV, PNG)."),
)
_BY_NAME = {entry.name: entry for entry in LAZY_COMMANDS}
# ctx.meta flag: set while the top-level help is being formatted.
_LISTING_FLAG = "wpbench.listing_commands"


def _module_exists(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def _to_click_command(name: str, target: Any) -> Any:
    """Turn a Typer app, a click command or a function into a click command."""
    if isinstance(target, typer.Typer):
        # get_group keeps a one-command sub-app a group (`wpbench bench svd`, not `wpbench bench`).
        return typer.main.get_group(target)
    if callable(target) and not hasattr(target, "make_context"):
        single = typer.Typer(add_completion=False)
        single.command(name=name)(target)
        return typer.main.get_command(single)
    return target


class _ImportFailed(typer.core.TyperCommand):
    """Stands in for a command whose module raised on import."""

    def __init__(self, entry: LazyCommand, error: BaseException) -> None:
        message = f"`wpbench {entry.name}` is unavailable: importing {entry.module} failed: {error!r}"

        def _fail() -> None:
            typer.echo(f"Error: {message}", err=True)
            raise typer.Exit(1)

        super().__init__(
            name=entry.name, callback=_fail, help=message, short_help=f"(unavailable: {error!r})"[:70],
            context_settings={"ignore_unknown_options": True, "allow_extra_args": True},
        )


class LazyTyperGroup(TyperGroup):
    """A TyperGroup that adds :data:`LAZY_COMMANDS` and imports each on first use."""

    def list_commands(self, ctx: Any) -> list[str]:
        eager = [name for name in super().list_commands(ctx) if name not in _BY_NAME]
        lazy = [entry.name for entry in LAZY_COMMANDS if _module_exists(entry.module)]
        return lazy + eager

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        command = super().get_command(ctx, cmd_name)
        if command is not None:
            return command
        entry = _BY_NAME.get(cmd_name)
        if entry is None or not _module_exists(entry.module):
            return None
        if ctx is not None and ctx.meta.get(_LISTING_FLAG):
            # Listing commands in --help: the one-line help is enough.
            return typer.core.TyperCommand(name=entry.name, help=entry.short_help, short_help=entry.short_help)
        try:
            module = importlib.import_module(entry.module)
            target = getattr(module, entry.attribute)
        except Exception as error:  # noqa: BLE001 - a broken module must not break the CLI
            return _ImportFailed(entry, error)
        command = _to_click_command(entry.name, target)
        self.commands[cmd_name] = command  # cache
        return command

    def format_help(self, ctx: Any, formatter: Any) -> None:
        ctx.meta[_LISTING_FLAG] = True
        try:
            super().format_help(ctx, formatter)
        finally:
            ctx.meta.pop(_LISTING_FLAG, None)

    def resolve_command(self, ctx: Any, args: list[str]) -> Any:
        # Typer's own "did you mean" only knows eagerly registered commands.
        resolve = getattr(super(), "_click_resolve_command", None) or super().resolve_command
        try:
            return resolve(ctx, args)
        except UsageError as error:
            matches = get_close_matches(args[0], self.list_commands(ctx)) if args else []
            if matches and "Did you mean" not in error.message:
                suggestions = ", ".join(repr(match) for match in matches)
                error.message = f"{error.message.rstrip('.')}. Did you mean {suggestions}?"
            raise


app = typer.Typer(
    name="wpbench",
    cls=LazyTyperGroup,
    help=(
        "wpbench: a simulation-in-the-loop benchmark for cross-pose estimation "
        "(WeightedPose, TAX-Pose, Goal Flow and baselines)."
    ),
    no_args_is_help=True,
    add_completion=False,
    # Plain click output: errors stay on one line, help needs no rich import.
    rich_markup_mode=None,
    pretty_exceptions_enable=False,
)


@app.callback()
def _root() -> None:
    # Having a callback makes typer build a group even before any command exists.
    pass


def bare_ray_means_local(argv: list[str]) -> list[str]:
    """``--ray`` given without an address (last, or followed by another option) means a local
    cluster: ``--ray local``. Typer has no option whose value may be left out, so the command
    line is completed before it is parsed."""
    completed = []
    for i, arg in enumerate(argv):
        completed.append(arg)
        if arg == "--ray" and (i + 1 == len(argv) or argv[i + 1].startswith("-")):
            completed.append("local")
    return completed


def main() -> None:
    """Console-script entry point (``wpbench = "wpbench.cli:main"``)."""
    import sys

    app(args=bare_ray_means_local(sys.argv[1:]))
