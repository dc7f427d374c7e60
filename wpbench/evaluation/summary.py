"""Run summaries: episode records -> ``summary.json`` and a terminal table.

``summarize(records, meta)`` aggregates one run (one policy on one task/split).
The result is a public format read by the leaderboard; its keys:

- ``format_version``, ``policy``, ``task``, ``split``, ``asset_source``, ``seed``
- ``episodes`` (n), ``successes``, ``success_rate``, ``success_ci95`` [low, high]
  (Wilson score interval, z = 1.96)
- ``success_once_rate`` / ``success_once_ci95``, ``success_at_end_rate`` /
  ``success_at_end_ci95`` when the records carry those flags
- ``rot_err_deg``, ``trans_err_m``, ``point_err_m``, ``point_mse``: each
  ``{"mean", "median", "nan_count", "n"}`` over the finite values
- ``nan_failures``: episodes the task called successful but whose pose errors
  were NaN; a NaN error always counts as a failure (docs/design.md), never as 0
- ``per_category``: ``{category: {"episodes", "successes", "success_rate",
  "success_ci95", "rot_err_deg_mean", "trans_err_m_mean", "point_err_m_mean",
  "nan_count"}}``
- ``objects``: number of distinct ``object_id`` (the furniture instances)
- ``success_instance_ci95`` [low, high]: a 95 % interval that resamples instances, not
  episodes (``wpbench.evaluation.intervals``); episodes of one instance are not independent
- ``failure_reasons``: ``{reason: count}`` over the failed episodes, most common first
  (:func:`episode_failure_reason`)
- ``timings``: per-episode ``{name: {"mean_s", "median_s", "total_s"}}`` from the
  records' ``timings`` dicts, plus ``"run"``: ``meta["timings"]`` if given
- ``meta``: the remaining run configuration

Undefined numbers (no finite values, no episodes) are ``None`` in the dict and
``null`` in the JSON file, so the file is always valid JSON.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Mapping
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from wpbench.evaluation.intervals import instance_bootstrap_interval
from wpbench.evaluation.records import ERROR_KEYS, dumps_json, records_from

__all__ = [
    "SUMMARY_FILE",
    "SUMMARY_FORMAT_VERSION",
    "Z_95",
    "wilson_interval",
    "episode_failure_reason",
    "summarize",
    "write_summary",
    "refresh_summary",
    "load_summary",
    "format_summary_table",
]

SUMMARY_FILE = "summary.json"
SUMMARY_FORMAT_VERSION = 2  # 2: success_instance_ci95 and failure_reasons
# Two-sided 95 % normal quantile.
Z_95 = 1.959963984540054

_IDENTITY_KEYS = ("policy", "task", "split", "asset_source")


def wilson_interval(successes: int, n: int, z: float = Z_95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion ``successes / n``.

    Unlike the normal approximation it stays inside [0, 1] and is informative
    at 0 % and 100 %, which small benchmark runs hit often. ``n == 0`` gives
    ``(nan, nan)``: there is no information.
    """
    if n < 0 or successes < 0 or successes > n:
        raise ValueError(f"need 0 <= successes <= n, got successes={successes}, n={n}")
    if n == 0:
        return (math.nan, math.nan)
    p = successes / n
    z2 = z * z
    denominator = 1.0 + z2 / n
    centre = (p + z2 / (2 * n)) / denominator
    half_width = (z / denominator) * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    # At 0 and n the exact bound is 0 or 1; do not let rounding show 0.9999999.
    low = 0.0 if successes == 0 else max(0.0, centre - half_width)
    high = 1.0 if successes == n else min(1.0, centre + half_width)
    return (low, high)


def episode_failure_reason(record: Mapping[str, Any]) -> str:
    """Why a failed episode failed: its own ``failure_reason`` (the episode could not run),
    else that of its first failed stage. A reason with details ("policy error: ...") counts
    by the part before the colon. "unknown" when nothing says."""
    reason = record.get("failure_reason") or ""
    if not reason:
        for stage in record.get("stages") or []:
            if isinstance(stage, Mapping) and not stage.get("success") and stage.get("failure_reason"):
                reason = stage["failure_reason"]
                break
    reason = str(reason).split(":", 1)[0].strip()
    return reason or "unknown"


def _nan_to_none(value: float | None) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def _error_stats(values: "Any") -> dict[str, Any]:
    """mean/median over the finite entries of a float Series; NaNs are counted."""
    finite = values[values.map(math.isfinite)]
    return {
        "mean": _nan_to_none(finite.mean()) if len(finite) else None,
        "median": _nan_to_none(finite.median()) if len(finite) else None,
        "nan_count": int(len(values) - len(finite)),
        "n": int(len(finite)),
    }


def _as_flags(values: "Any") -> "Any":
    """A boolean Series; missing values (None/NaN) are False."""
    return values.map(lambda v: bool(v) if v is not None and v == v else False).astype(bool)


def _rate(flags: "Any") -> dict[str, Any]:
    successes, n = int(flags.sum()), int(len(flags))
    low, high = wilson_interval(successes, n)
    return {
        "successes": successes,
        "n": n,
        "rate": successes / n if n else None,
        "ci95": [_nan_to_none(low), _nan_to_none(high)],
    }


def _unique_field(frame: "Any", key: str, meta: Mapping[str, Any]) -> Any:
    """``meta[key]`` if given, else the single value the records agree on."""
    if meta.get(key) is not None:
        return meta[key]
    if key not in frame.columns:
        return None
    values = frame[key].dropna().unique().tolist()
    if len(values) > 1:
        raise ValueError(
            f"records mix several {key} values {sorted(map(str, values))}; summarize one run at a time"
        )
    return values[0] if values else None


def summarize(
    records: Iterable[Mapping[str, Any]] | str | os.PathLike[str],
    meta: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Aggregate episode records of one run into the summary dict described above.

    ``records``: mappings (or a path to ``episodes.jsonl`` / its directory);
    error fields may be NaN or None. ``meta``: run configuration (policy, task,
    split, asset_source, seed, ... and optionally ``timings``).
    """
    import pandas as pd  # deferred: keeps CLI start-up fast

    meta = dict(meta or {})
    rows = records_from(records)
    frame = pd.DataFrame(rows)
    n = len(frame)

    summary: dict[str, Any] = {"format_version": SUMMARY_FORMAT_VERSION}
    for key in _IDENTITY_KEYS:
        summary[key] = _unique_field(frame, key, meta) if n else meta.get(key)
    summary["seed"] = meta.get("seed")
    summary["episodes"] = n
    summary["created_utc"] = datetime.now(timezone.utc).isoformat(timespec="seconds")

    if n == 0:
        frame = pd.DataFrame(columns=["success", "category", "object_id", *ERROR_KEYS])
    for key in ERROR_KEYS:
        if key not in frame.columns:
            frame[key] = math.nan
        frame[key] = pd.to_numeric(frame[key], errors="coerce").astype(float)

    # An episode whose pose error is NaN failed, whatever the task said.
    error_is_nan = frame[list(ERROR_KEYS)].isna().any(axis=1)
    claimed = _as_flags(frame["success"])
    success = claimed & ~error_is_nan
    overall = _rate(success)
    summary["successes"] = overall["successes"]
    summary["success_rate"] = overall["rate"]
    summary["success_ci95"] = overall["ci95"]
    summary["nan_failures"] = int((claimed & error_is_nan).sum())

    for flag in ("success_once", "success_at_end"):
        if flag in frame.columns and frame[flag].notna().any():
            known = frame[flag].notna()
            flag_rate = _rate(_as_flags(frame.loc[known, flag]) & ~error_is_nan[known])
            summary[f"{flag}_rate"] = flag_rate["rate"]
            summary[f"{flag}_ci95"] = flag_rate["ci95"]

    for key in ERROR_KEYS:
        summary[key] = _error_stats(frame[key])

    per_category: dict[str, Any] = {}
    if n and "category" in frame.columns:
        categories = frame["category"].fillna("unknown").astype(str)
        for category in sorted(categories.unique()):
            mask = categories == category
            group = frame[mask]
            rate = _rate(success[mask])
            per_category[category] = {
                "episodes": rate["n"],
                "successes": rate["successes"],
                "success_rate": rate["rate"],
                "success_ci95": rate["ci95"],
                "rot_err_deg_mean": _error_stats(group["rot_err_deg"])["mean"],
                "trans_err_m_mean": _error_stats(group["trans_err_m"])["mean"],
                "point_err_m_mean": _error_stats(group["point_err_m"])["mean"],
                "nan_count": int(error_is_nan[mask].sum()),
            }
    summary["per_category"] = per_category
    summary["objects"] = int(frame["object_id"].nunique()) if n and "object_id" in frame.columns else 0
    if n and "object_id" in frame.columns:
        instances = frame["object_id"].fillna("unknown").astype(str).tolist()
        low, high = instance_bootstrap_interval(success.tolist(), instances)
        summary["success_instance_ci95"] = [_nan_to_none(low), _nan_to_none(high)]
    else:
        summary["success_instance_ci95"] = [None, None]
    reasons: dict[str, int] = {}
    for row, ok, nan_error in zip(rows, success.tolist(), error_is_nan.tolist()):
        if not ok:
            reason = "nan_pose_error" if nan_error and row.get("success") else episode_failure_reason(row)
            reasons[reason] = reasons.get(reason, 0) + 1
    summary["failure_reasons"] = dict(sorted(reasons.items(), key=lambda item: (-item[1], item[0])))

    summary["timings"] = _timings(rows, meta.get("timings"))
    summary["meta"] = {
        key: value for key, value in meta.items() if key not in (*_IDENTITY_KEYS, "seed", "timings")
    }
    return summary


def _timings(rows: list[dict[str, Any]], run_timings: Any) -> dict[str, Any]:
    import pandas as pd

    per_episode = [row["timings"] for row in rows if isinstance(row.get("timings"), Mapping)]
    result: dict[str, Any] = {}
    if per_episode:
        table = pd.DataFrame(per_episode).apply(pd.to_numeric, errors="coerce")
        for name in table.columns:
            column = table[name].dropna()
            result[str(name)] = {
                "mean_s": _nan_to_none(column.mean()) if len(column) else None,
                "median_s": _nan_to_none(column.median()) if len(column) else None,
                "total_s": _nan_to_none(column.sum()),
            }
    if run_timings:
        result["run"] = dict(run_timings)
    return result


def write_summary(out_dir: str | os.PathLike[str], summary: Mapping[str, Any]) -> Path:
    """Write ``summary`` to ``<out_dir>/summary.json`` (atomically; NaN as null)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / SUMMARY_FILE
    temporary = path.with_suffix(".json.tmp")
    temporary.write_text(dumps_json(summary, indent=2) + "\n", encoding="utf-8")
    os.replace(temporary, path)
    return path


def refresh_summary(run_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """Recompute ``<run_dir>/summary.json`` from its ``episodes.jsonl`` in the current format.

    The run's configuration, run timings and peak memory are kept from the old summary
    (they are not in the records); every number derived from the episodes is recomputed.
    """
    run_dir = Path(run_dir)
    old = load_summary(run_dir)
    meta = dict(old.get("meta") or {})
    for key in (*_IDENTITY_KEYS, "seed"):
        meta[key] = old.get(key)
    run_timings = (old.get("timings") or {}).get("run")
    if run_timings:
        meta["timings"] = run_timings
    summary = summarize(run_dir / "episodes.jsonl", meta)
    summary["created_utc"] = old.get("created_utc", summary["created_utc"])
    write_summary(run_dir, summary)
    return summary


def load_summary(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a ``summary.json`` (or the one in a run directory)."""
    path = Path(path)
    if path.is_dir():
        path = path / SUMMARY_FILE
    summary = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(summary, dict):
        raise ValueError(f"{path} does not hold a summary object")
    return summary


def _percent(rate: float | None) -> str:
    return "n/a" if rate is None else f"{100.0 * rate:.1f}%"


def _rate_with_ci(rate: float | None, ci: Any) -> str:
    if rate is None:
        return "n/a"
    if not ci or ci[0] is None or ci[1] is None:
        return _percent(rate)
    return f"{_percent(rate)} [{100.0 * ci[0]:.1f}, {100.0 * ci[1]:.1f}]"


def _number(value: float | None, digits: int) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def _error_cell(stats: Mapping[str, Any] | None, digits: int) -> str:
    if not stats:
        return "n/a"
    text = f"{_number(stats.get('mean'), digits)} / {_number(stats.get('median'), digits)}"
    if stats.get("nan_count"):
        text += f"  ({stats['nan_count']} NaN)"
    return text


def format_summary_table(summary: Mapping[str, Any]) -> str:
    """A plain-text table of one summary (overall metrics, then per category)."""
    from tabulate import tabulate

    rows: list[tuple[str, str]] = [
        ("policy", str(summary.get("policy"))),
        ("task", str(summary.get("task"))),
        ("split", str(summary.get("split"))),
        ("asset source", str(summary.get("asset_source"))),
        ("observation", str((summary.get("meta") or {}).get("obs"))),
        ("executor", str((summary.get("meta") or {}).get("executor") or "ideal")),
        ("episodes", str(summary.get("episodes"))),
        ("success rate [95% CI]", _rate_with_ci(summary.get("success_rate"), summary.get("success_ci95"))),
    ]
    for flag in ("success_once", "success_at_end"):
        if f"{flag}_rate" in summary:
            rows.append(
                (flag.replace("_", " "), _rate_with_ci(summary[f"{flag}_rate"], summary.get(f"{flag}_ci95")))
            )
    rows += [
        ("rot err deg (mean / median)", _error_cell(summary.get("rot_err_deg"), 2)),
        ("trans err m (mean / median)", _error_cell(summary.get("trans_err_m"), 4)),
        ("point err m (mean / median)", _error_cell(summary.get("point_err_m"), 4)),
    ]
    if summary.get("nan_failures"):
        rows.append(("successes voided by NaN errors", str(summary["nan_failures"])))
    reasons = summary.get("failure_reasons") or {}
    if reasons:
        ordered = sorted(reasons.items(), key=lambda item: (-item[1], item[0]))
        rows.append(("failure reasons", ", ".join(f"{reason} {count}" for reason, count in ordered)))
    text = tabulate(rows, tablefmt="simple", disable_numparse=True)

    per_category = summary.get("per_category") or {}
    if per_category:
        category_rows = [
            (
                category,
                stats.get("episodes"),
                _rate_with_ci(stats.get("success_rate"), stats.get("success_ci95")),
                _number(stats.get("rot_err_deg_mean"), 2),
                _number(stats.get("trans_err_m_mean"), 4),
                _number(stats.get("point_err_m_mean"), 4),
            )
            for category, stats in per_category.items()
        ]
        text += "\n\n" + tabulate(
            category_rows,
            headers=["category", "n", "success [95% CI]", "rot err deg", "trans err m", "point err m"],
            tablefmt="simple",
            disable_numparse=True,
        )
    return text
