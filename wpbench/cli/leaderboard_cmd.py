"""``wpbench leaderboard``: gather every summary.json into leaderboard md/csv/png."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from wpbench.cli.choices import choice_callback

# Mirrors wpbench.evaluation.leaderboard.SORT_KEYS; kept literal so --help
# does not import pandas. test_cli checks the two agree.
SORT_CHOICES = ("success", "policy", "task", "rot", "trans")


def leaderboard(
    results: Path = typer.Option(Path("results"), "--results", help="Folder searched recursively for summary.json."),
    out: Optional[Path] = typer.Option(None, "--out", help="Where to write leaderboard.{md,csv,png} (default: --results)."),
    sort_by: str = typer.Option(
        "success", "--sort-by", callback=choice_callback("sort key", SORT_CHOICES),
        help="Row order: " + ", ".join(SORT_CHOICES) + " (success: by task, best first).",
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Do not print the table."),
    refresh: bool = typer.Option(
        False, "--refresh",
        help="First recompute every summary.json from its episodes.jsonl (after a summary format change).",
    ),
) -> None:
    """Collect results/**/summary.json into results/leaderboard.md, .csv and .png."""
    from wpbench.evaluation.leaderboard import find_summaries, write_leaderboard
    from wpbench.evaluation.summary import refresh_summary

    def warn(text: str) -> None:
        typer.echo(f"warning: {text}", err=True)

    try:
        if refresh:
            for path in find_summaries(results):
                if (path.parent / "episodes.jsonl").is_file():
                    refresh_summary(path.parent)
        files = write_leaderboard(results, out_dir=out, sort_by=sort_by, on_warning=warn)
    except FileNotFoundError as error:
        typer.echo(f"Error: {error}", err=True)
        raise typer.Exit(1) from error
    if not quiet:
        typer.echo(files.markdown.read_text(encoding="utf-8"))
    typer.echo(f"wrote {files.markdown}, {files.csv}, {files.png} ({files.runs} runs)")
