"""``wpbench merge``: join the shards of one run into one run folder."""

from __future__ import annotations

from pathlib import Path

import typer


def merge(
    shards: list[Path] = typer.Argument(..., help="The shard folders (of `wpbench run --shard i/N`)."),
    out: Path = typer.Option(..., help="The merged run folder to write."),
) -> None:
    """Join the N shards of one run into OUT (episodes in order, run.json, summary.json); refuses shards
    of different runs, missing shards and unfinished ones."""
    from wpbench.evaluation.merge import merge_shards
    from wpbench.evaluation.records import RunMismatchError
    from wpbench.evaluation.summary import format_summary_table

    try:
        summary = merge_shards(shards, out)
    except (RunMismatchError, FileNotFoundError, FileExistsError, ValueError) as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(2)
    typer.echo(format_summary_table(summary))
    typer.echo(f"merged {len(shards)} shards into {out}")
