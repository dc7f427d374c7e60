"""Leaderboard: every ``summary.json`` under a results folder -> md, csv and png.

``write_leaderboard(results_dir)`` searches ``results_dir`` recursively for
``summary.json`` files (see :mod:`wpbench.evaluation.summary`) and writes

- ``leaderboard.md``: one row per run (policy x task x split x asset source x
  observation x executor),
  success rate with its 95 % Wilson interval, rotation/translation errors,
  episode count and the run directory;
- ``leaderboard.csv``: the same rows with raw numbers, for other tools;
- ``leaderboard.png``: success rates as bars with 95 % interval error bars,
  grouped by task.

Runs are not pooled: two runs of the same policy on the same task stay two
rows (their ``run`` column differs), because pooling runs that share seeds
would count the same episodes twice.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wpbench.evaluation.executor_version import older_executor_reason
from wpbench.evaluation.furniture_version import other_furniture_reason
from wpbench.evaluation.summary import SUMMARY_FILE, load_summary

__all__ = [
    "LEADERBOARD_COLUMNS",
    "SORT_KEYS",
    "LeaderboardFiles",
    "find_summaries",
    "collect_summaries",
    "leaderboard_markdown",
    "plot_leaderboard",
    "write_leaderboard",
]

LEADERBOARD_COLUMNS: tuple[str, ...] = (
    "task",
    "policy",
    "split",
    "asset_source",
    "obs",
    "executor",
    "episodes",
    "successes",
    "success_rate",
    "success_ci95_low",
    "success_ci95_high",
    "success_instance_ci95_low",
    "success_instance_ci95_high",
    "instances",
    "top_failure",
    "success_once_rate",
    "success_at_end_rate",
    "rot_err_deg_mean",
    "rot_err_deg_median",
    "trans_err_m_mean",
    "trans_err_m_median",
    "point_err_m_mean",
    "nan_count",
    "run",
)

# name -> (columns, ascending flags). Ties fall back to task then policy.
SORT_KEYS: dict[str, tuple[list[str], list[bool]]] = {
    "success": (["task", "success_rate", "policy"], [True, False, True]),
    "policy": (["policy", "task", "split"], [True, True, True]),
    "task": (["task", "policy", "split"], [True, True, True]),
    "rot": (["task", "rot_err_deg_mean", "policy"], [True, True, True]),
    "trans": (["task", "trans_err_m_mean", "policy"], [True, True, True]),
}


@dataclass(frozen=True)
class LeaderboardFiles:
    """Paths written by :func:`write_leaderboard` and the number of runs listed."""

    markdown: Path
    csv: Path
    png: Path
    runs: int
    skipped: tuple[Path, ...] = ()


# Runs of earlier releases (other furniture or weights) are kept under this folder name; the
# leaderboard leaves them out, since their numbers are not comparable with the current ones.
ARCHIVE_DIR = "archive"


def find_summaries(results_dir: str | os.PathLike[str]) -> list[Path]:
    """All ``summary.json`` files under ``results_dir`` (sorted; hidden folders and
    :data:`ARCHIVE_DIR` folders skipped)."""
    root = Path(results_dir)
    if not root.is_dir():
        raise FileNotFoundError(f"results folder {root} does not exist; run `wpbench run ...` first")
    found = []
    for path in root.rglob(SUMMARY_FILE):
        relative_parts = path.relative_to(root).parts
        if any(part.startswith(".") or part == ARCHIVE_DIR for part in relative_parts[:-1]):
            continue
        found.append(path)
    return sorted(found)


def _get(summary: dict[str, Any], key: str, field: str | None = None) -> float:
    value = summary.get(key)
    if field is not None:
        value = value.get(field) if isinstance(value, dict) else None
    return math.nan if value is None else float(value)


def _obs_label(summary: dict[str, Any]) -> str:
    """The observation mode, with the camera noise's tag for a noisy camera (camera-depth0.002)."""
    from wpbench.sim.camera_noise import CameraNoise

    meta = summary.get("meta") or {}
    obs = meta.get("obs") or summary.get("obs") or "-"
    tag = CameraNoise.from_settings(meta.get("camera_noise") or {}).tag()
    return f"{obs}-{tag}" if tag else obs


def _row(summary: dict[str, Any], run: str) -> dict[str, Any]:
    ci = summary.get("success_ci95") or [None, None]
    instance_ci = summary.get("success_instance_ci95") or [None, None]
    reasons = summary.get("failure_reasons") or {}
    rot_stats = summary.get("rot_err_deg")
    return {
        "task": summary.get("task") or "?",
        "policy": summary.get("policy") or "?",
        "split": summary.get("split") or "-",
        "asset_source": summary.get("asset_source") or "-",
        "obs": _obs_label(summary),
        # Runs made before executors existed used the ideal one.
        "executor": (summary.get("meta") or {}).get("executor") or "ideal",
        "episodes": int(summary.get("episodes") or 0),
        "successes": int(summary.get("successes") or 0),
        "success_rate": _get(summary, "success_rate"),
        "success_ci95_low": math.nan if ci[0] is None else float(ci[0]),
        "success_ci95_high": math.nan if ci[1] is None else float(ci[1]),
        "success_instance_ci95_low": math.nan if instance_ci[0] is None else float(instance_ci[0]),
        "success_instance_ci95_high": math.nan if instance_ci[1] is None else float(instance_ci[1]),
        "instances": int(summary.get("objects") or 0),
        # Summaries list the reasons most common first.
        "top_failure": next(iter(reasons), "") if isinstance(reasons, dict) else "",
        "success_once_rate": _get(summary, "success_once_rate"),
        "success_at_end_rate": _get(summary, "success_at_end_rate"),
        "rot_err_deg_mean": _get(summary, "rot_err_deg", "mean"),
        "rot_err_deg_median": _get(summary, "rot_err_deg", "median"),
        "trans_err_m_mean": _get(summary, "trans_err_m", "mean"),
        "trans_err_m_median": _get(summary, "trans_err_m", "median"),
        "point_err_m_mean": _get(summary, "point_err_m", "mean"),
        # Episodes whose predicted pose was NaN (the rotation error is NaN then).
        "nan_count": int(rot_stats.get("nan_count") or 0) if isinstance(rot_stats, dict) else 0,
        "run": run,
    }


def collect_summaries(
    results_dir: str | os.PathLike[str], sort_by: str = "success"
) -> tuple["Any", list[Path]]:
    """(DataFrame with :data:`LEADERBOARD_COLUMNS`, unreadable summary paths)."""
    import pandas as pd

    if sort_by not in SORT_KEYS:
        raise ValueError(f"unknown sort key {sort_by!r}; valid: {', '.join(SORT_KEYS)}")
    root = Path(results_dir)
    rows, skipped = [], []
    for path in find_summaries(root):
        reason = other_furniture_reason(path.parent) or older_executor_reason(path.parent)
        if reason:
            warnings.warn(f"leaving out {reason}", stacklevel=2)
            skipped.append(path)
            continue
        try:
            summary = load_summary(path)
            rows.append(_row(summary, run=str(path.parent.relative_to(root)) or "."))
        except (ValueError, TypeError, AttributeError) as error:
            warnings.warn(f"skipping unreadable {path}: {error}", stacklevel=2)
            skipped.append(path)
    frame = pd.DataFrame(rows, columns=list(LEADERBOARD_COLUMNS))
    columns, ascending = SORT_KEYS[sort_by]
    frame = frame.sort_values(columns, ascending=ascending, na_position="last", kind="stable")
    return frame.reset_index(drop=True), skipped


def _fmt(value: float, digits: int) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def _short_source(source: str) -> str:
    """``procedural`` stays; a folder path shows as its last component."""
    return Path(source).name or source if ("/" in source or os.sep in source) else source


def _success_cell(row: Any) -> str:
    if not math.isfinite(row.success_rate):
        return "n/a"
    text = f"{100 * row.success_rate:.1f}%"
    if math.isfinite(row.success_ci95_low) and math.isfinite(row.success_ci95_high):
        text += f" [{100 * row.success_ci95_low:.1f}, {100 * row.success_ci95_high:.1f}]"
    return text


def _instance_interval_cell(row: Any) -> str:
    if math.isfinite(row.success_instance_ci95_low) and math.isfinite(row.success_instance_ci95_high):
        return f"[{100 * row.success_instance_ci95_low:.1f}, {100 * row.success_instance_ci95_high:.1f}]"
    return "n/a"


def _failure_cell(row: Any) -> str:
    return row.top_failure if row.top_failure else ("-" if row.successes == row.episodes else "n/a")


def leaderboard_markdown(frame: "Any", skipped: list[Path] | tuple[Path, ...] = ()) -> str:
    """The markdown document for a DataFrame from :func:`collect_summaries`."""
    from tabulate import tabulate

    headers = [
        "task",
        "policy",
        "split",
        "assets",
        "obs",
        "executor",
        "success [95% CI]",
        "instance CI",
        "instances",
        "most common failure",
        "rot err deg (mean / median)",
        "trans err m (mean / median)",
        "episodes",
        "run",
    ]
    rows = [
        [
            row.task,
            f"`{row.policy}`",
            row.split,
            _short_source(row.asset_source),
            row.obs,
            row.executor,
            _success_cell(row),
            _instance_interval_cell(row),
            str(row.instances),
            _failure_cell(row),
            f"{_fmt(row.rot_err_deg_mean, 2)} / {_fmt(row.rot_err_deg_median, 2)}",
            f"{_fmt(row.trans_err_m_mean, 4)} / {_fmt(row.trans_err_m_median, 4)}",
            str(row.episodes),
            f"`{row.run}`",
        ]
        for row in frame.itertuples(index=False)
    ]
    lines = [
        "# wpbench leaderboard",
        "",
        "Generated by `wpbench leaderboard` from every `summary.json` under this folder.",
        "Success is scored in simulation. The interval beside it is the 95 % Wilson score interval",
        "(episodes independent); the instance CI resamples furniture instances, the honest unit when",
        "episodes repeat instances. 'most common failure' is the leading failure reason of the run.",
        "Pose errors are over finite values; NaN predictions count as failures.",
        "",
        tabulate(rows, headers=headers, tablefmt="github", disable_numparse=True),
        "",
    ]
    other_furniture = [p for p in skipped if other_furniture_reason(p.parent)]
    older_executor = [p for p in skipped if p not in other_furniture and older_executor_reason(p.parent)]
    unreadable = [p for p in skipped if p not in other_furniture and p not in older_executor]
    if other_furniture:
        lines += ["Runs on built-in furniture of another generator version left out (move them under "
                  f"`{ARCHIVE_DIR}/` or score them again): " + ", ".join(f"`{p}`" for p in other_furniture), ""]
    if older_executor:
        lines += ["Runs carried out by an older version of their executor left out (score them again; "
                  "`wpbench.evaluation.executor_version` lists what changed): "
                  + ", ".join(f"`{p}`" for p in older_executor), ""]
    if unreadable:
        lines += ["Unreadable summaries left out: " + ", ".join(f"`{p}`" for p in unreadable), ""]
    return "\n".join(lines)


def _bar_labels(frame: "Any") -> list[str]:
    """Policy names, plus split / asset source / run where needed to tell bars apart."""
    varying = [key for key in ("split", "asset_source", "obs", "executor") if frame[key].nunique() > 1]
    labels = []
    for row in frame.itertuples(index=False):
        extra = [_short_source(str(getattr(row, key))) for key in varying]
        labels.append(row.policy + (f" ({', '.join(extra)})" if extra else ""))
    keyed = list(zip(frame["task"], labels))
    return [
        f"{label} [{run}]" if keyed.count((task, label)) > 1 else label
        for (task, label), run in zip(keyed, frame["run"])
    ]


def plot_leaderboard(frame: "Any", path: str | os.PathLike[str]) -> Path:
    """Success rate (with its 95 % interval) of every run: one panel per task, one labelled
    horizontal bar per run, best first. Labels sit on the axis, so no colour legend has to be
    decoded however many runs there are; bar colour marks the asset source."""
    from matplotlib.figure import Figure  # no pyplot: no global state, no display

    path = Path(path)
    labels = _bar_labels(frame)
    tasks = list(dict.fromkeys(frame["task"]))
    sources = list(dict.fromkeys(str(s) for s in frame["asset_source"]))
    colour_of = {source: f"C{i % 10}" for i, source in enumerate(sources)}
    rows_per_task = [sum(1 for t in frame["task"] if t == task) for task in tasks] or [1]
    figure = Figure(figsize=(13.0, 1.2 + 0.28 * max(rows_per_task)))
    for panel, task in enumerate(tasks or ["(no runs)"]):
        axes = figure.add_subplot(1, max(1, len(tasks)), panel + 1)
        runs = [(row, label) for row, label in zip(frame.itertuples(index=False), labels)
                if row.task == task and math.isfinite(row.success_rate)]
        runs.sort(key=lambda item: (item[0].success_rate, item[1]))  # best at the top
        for y, (row, label) in enumerate(runs):
            low = row.success_ci95_low if math.isfinite(row.success_ci95_low) else row.success_rate
            high = row.success_ci95_high if math.isfinite(row.success_ci95_high) else row.success_rate
            error = [[100 * max(0.0, row.success_rate - low)], [100 * max(0.0, high - row.success_rate)]]
            axes.barh(y, 100 * row.success_rate, color=colour_of[str(row.asset_source)], xerr=error,
                      capsize=2, ecolor="black", height=0.75)
        axes.set_yticks(range(len(runs)), [label for _, label in runs], fontsize="small")
        axes.set_xlim(0, 105)
        axes.set_xlabel("success rate (%)")
        axes.set_title(task)
        axes.grid(axis="x", alpha=0.3)
    if sources:
        from matplotlib.patches import Patch

        handles = [Patch(color=colour_of[s], label=_short_source(s)) for s in sources]
        figure.legend(handles=handles, loc="upper right", ncol=len(handles), fontsize="small", frameon=False)
    figure.suptitle("wpbench: success in simulation (whiskers: 95% Wilson interval)")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    return path


def write_leaderboard(
    results_dir: str | os.PathLike[str] = "results",
    out_dir: str | os.PathLike[str] | None = None,
    sort_by: str = "success",
    on_warning: Callable[[str], None] | None = None,
) -> LeaderboardFiles:
    """Gather summaries under ``results_dir``; write leaderboard.{md,csv,png} to
    ``out_dir`` (default ``results_dir``). Raises ``FileNotFoundError`` if there
    are no summaries, so an empty leaderboard never replaces a real one."""
    root = Path(results_dir)
    target = Path(out_dir) if out_dir is not None else root
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frame, skipped = collect_summaries(root, sort_by=sort_by)
    for warning in caught:
        (on_warning or (lambda text: warnings.warn(text, stacklevel=2)))(str(warning.message))
    if frame.empty:
        raise FileNotFoundError(
            f"no readable {SUMMARY_FILE} under {root}; run `wpbench run ...` to produce results first"
        )
    target.mkdir(parents=True, exist_ok=True)
    markdown = target / "leaderboard.md"
    csv = target / "leaderboard.csv"
    png = target / "leaderboard.png"
    markdown.write_text(leaderboard_markdown(frame, skipped), encoding="utf-8")
    frame.to_csv(csv, index=False, float_format="%.6g")
    plot_leaderboard(frame, png)
    return LeaderboardFiles(markdown=markdown, csv=csv, png=png, runs=len(frame), skipped=tuple(skipped))
