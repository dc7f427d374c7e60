"""Scoring outputs of wpbench runs: episode records, run summaries, leaderboards.

- :mod:`wpbench.evaluation.records`: ``episodes.jsonl`` + ``run.json`` per run
  (:class:`EpisodeWriter`, :func:`read_episodes`).
- :mod:`wpbench.evaluation.summary`: ``summarize`` -> ``summary.json``, Wilson
  intervals, terminal tables.
- :mod:`wpbench.evaluation.leaderboard`: all summaries -> leaderboard md/csv/png.

Importing this package is cheap (pandas, tabulate and matplotlib are imported
inside the functions that need them), so the CLI can use it at start-up.
"""

from wpbench.evaluation.records import (
    EPISODES_FILE,
    REQUIRED_KEYS,
    RUN_CONFIG_FILE,
    EpisodeWriter,
    RecordFormatError,
    RunMismatchError,
    read_episodes,
)
from wpbench.evaluation.summary import (
    SUMMARY_FILE,
    format_summary_table,
    load_summary,
    summarize,
    wilson_interval,
    write_summary,
)

__all__ = [
    "EPISODES_FILE",
    "REQUIRED_KEYS",
    "RUN_CONFIG_FILE",
    "SUMMARY_FILE",
    "EpisodeWriter",
    "RecordFormatError",
    "RunMismatchError",
    "read_episodes",
    "summarize",
    "write_summary",
    "load_summary",
    "format_summary_table",
    "wilson_interval",
]
