"""Per-episode result records: ``<out_dir>/episodes.jsonl`` plus ``<out_dir>/run.json``.

This is a public format; later tools (summaries, the leaderboard, notebooks)
read it. One run of one policy on one task/split writes one directory:

- ``run.json``: the run configuration (policy, task, split, seed, asset source,
  ...) written when the directory is first used. ``--resume`` compares against
  it so that episodes of different runs are never mixed in one file.
- ``episodes.jsonl``: one JSON object per line, one line per finished episode,
  appended (flushed and fsync'ed) as each episode ends, so a crash loses at most
  the episode in progress. A truncated last line left by a crash is dropped when
  the directory is reopened; any other unreadable line is an error, and so is an
  episode recorded twice or a record of another run (another policy, task, split,
  observation or seed). Parallel workers finish episodes out of order: the file is
  put back in episode order when the run ends.

Required keys of an episode record (others are allowed and kept):
``episode`` (int index), ``seed`` (int), ``task``, ``policy``, ``object_id``,
``category``, ``success`` (bool), ``rot_err_deg``, ``trans_err_m``,
``point_err_m``, ``point_mse`` (floats; NaN allowed). Optional keys the summary
understands: ``success_once``, ``success_at_end`` (bool), ``split``,
``asset_source``, ``timings`` (dict name -> seconds). ``furniture_pool``: the hash of
the furniture the episode was drawn from (``wpbench.assets.library.furniture_pool_digest``);
a run whose records name two different pools is refused, on writing and on resuming.

JSON has no NaN: non-finite floats are written as ``null`` and read back as NaN
for the numeric error fields.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

__all__ = [
    "EPISODES_FILE",
    "RUN_CONFIG_FILE",
    "REQUIRED_KEYS",
    "ERROR_KEYS",
    "RESUME_MAY_DIFFER",
    "RunMismatchError",
    "RecordFormatError",
    "RecordWriteError",
    "EpisodeWriter",
    "read_episodes",
    "records_from",
    "validate_record",
    "to_json_safe",
    "dumps_json",
]

EPISODES_FILE = "episodes.jsonl"
RUN_CONFIG_FILE = "run.json"

REQUIRED_KEYS: tuple[str, ...] = (
    "episode",
    "seed",
    "task",
    "policy",
    "object_id",
    "category",
    "success",
    "rot_err_deg",
    "trans_err_m",
    "point_err_m",
    "point_mse",
)
# Numeric fields where null in the file means NaN in memory.
ERROR_KEYS: tuple[str, ...] = ("rot_err_deg", "trans_err_m", "point_err_m", "point_mse")

# Run-config keys that may change between a run and its resumption: asking for
# more episodes, or toggling output options, does not change what an episode is.
RESUME_MAY_DIFFER: frozenset[str] = frozenset(
    {"episodes", "num_episodes", "resume", "out_dir", "out", "record", "render", "progress", "workers"}
)
# Run-config keys added after runs were first written: a run.json without one of them
# was written with this value ...
RESUME_DEFAULTS: dict[str, Any] = {"executor": "ideal", "shard": None, "camera_noise": {}, "executor_version": 1}
# ... or, for these, with a value nobody knows (not compared).
RESUME_UNKNOWN_IF_MISSING: frozenset[str] = frozenset({"assets_digest"})
# Record keys that must equal the run config's value of the same name.
RECORD_CONFIG_KEYS: tuple[str, ...] = ("policy", "task", "split", "obs")


def stored_run_config(run_dir: str | Path) -> dict | None:
    """The ``run.json`` in ``run_dir`` as a dict, or None when it is missing, unreadable or not an object
    (reports that only look at it leave such runs as they are)."""
    try:
        stored = json.loads((Path(run_dir) / RUN_CONFIG_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return stored if isinstance(stored, dict) else None


class RecordFormatError(ValueError):
    """An episode record or an episodes.jsonl file is malformed."""


class RunMismatchError(ValueError):
    """``--resume`` was asked for a directory holding a different run."""


class RecordWriteError(OSError):
    """The file system refused an episode record (read-only, full, gone); ``errno`` is the cause's."""

    def __init__(self, code: int | None, message: str) -> None:
        super().__init__(message)
        self.errno = code

    def __str__(self) -> str:
        return str(self.args[0])


def to_json_safe(value: Any) -> Any:
    """Convert ``value`` to plain JSON types: NaN/inf -> None, numpy/torch scalars
    and arrays -> Python numbers/lists, tuples -> lists, Paths -> str."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): to_json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [to_json_safe(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    # numpy / torch scalars and arrays, without importing either here.
    if hasattr(value, "tolist"):
        return to_json_safe(value.tolist())
    if hasattr(value, "item"):
        return to_json_safe(value.item())
    raise TypeError(f"cannot store {type(value).__name__} in a JSON record: {value!r}")


def dumps_json(value: Any, **kwargs: Any) -> str:
    """``json.dumps`` that always produces valid JSON (NaN written as null)."""
    return json.dumps(to_json_safe(value), allow_nan=False, **kwargs)


def _restore_nans(record: dict[str, Any]) -> dict[str, Any]:
    for key in ERROR_KEYS:
        if key in record and record[key] is None:
            record[key] = float("nan")
    return record


def validate_record(record: Mapping[str, Any]) -> None:
    """Raise :class:`RecordFormatError` if ``record`` lacks a required key or has
    an obviously wrong type for ``episode``/``seed``/``success``."""
    missing = [key for key in REQUIRED_KEYS if key not in record]
    if missing:
        raise RecordFormatError(
            f"episode record is missing required keys {missing}; required: {list(REQUIRED_KEYS)}"
        )
    for key in ("episode", "seed"):
        value = record[key]
        if isinstance(value, bool) or not hasattr(value, "__index__"):
            raise RecordFormatError(f"episode record key {key!r} must be an int, got {value!r}")
    # numpy.bool_ is accepted too: tasks often compute success with numpy.
    success_type = type(record["success"])
    is_numpy_bool = success_type.__module__ == "numpy" and success_type.__name__ in ("bool", "bool_")
    if not isinstance(record["success"], bool) and not is_numpy_bool:
        raise RecordFormatError(f"episode record key 'success' must be a bool, got {record['success']!r}")


def _scan_lines(path: Path) -> tuple[list[dict[str, Any]], int, int]:
    """Parse ``path``; return (records, byte length of the good prefix, dropped bytes).

    Only the last line may be damaged (a crash mid-write): it is reported as
    dropped. A damaged line anywhere else raises :class:`RecordFormatError`.
    """
    data = path.read_bytes()
    records: list[dict[str, Any]] = []
    good_end = 0
    position = 0
    while position < len(data):
        newline = data.find(b"\n", position)
        is_last = newline == -1 or newline == len(data) - 1
        end = len(data) if newline == -1 else newline + 1
        line = data[position:end]
        text = line.strip()
        if text:
            try:
                if newline == -1:
                    # An unterminated final line was never completely written.
                    raise ValueError("line not terminated")
                parsed = json.loads(text)
                if not isinstance(parsed, dict):
                    raise ValueError("not a JSON object")
            except ValueError as error:
                if is_last:
                    return records, good_end, len(data) - good_end
                line_number = data.count(b"\n", 0, position) + 1
                raise RecordFormatError(
                    f"{path}:{line_number}: unreadable episode record ({error}); only a "
                    "truncated last line is repaired automatically: fix or remove the file"
                ) from error
            records.append(_restore_nans(parsed))
        good_end = end
        position = end
    return records, good_end, 0


def read_episodes(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """All complete records of an ``episodes.jsonl`` (or of a run directory).

    A truncated last line is ignored (with a warning); the file is not changed.
    Error fields stored as null come back as ``float('nan')``.
    """
    path = Path(path)
    if path.is_dir():
        path = path / EPISODES_FILE
    if not path.exists():
        raise FileNotFoundError(f"no episode records at {path}")
    records, _, dropped = _scan_lines(path)
    if dropped:
        warnings.warn(f"{path}: ignoring a truncated last line ({dropped} bytes)", stacklevel=2)
    return records


def _normalise_config(config: Mapping[str, Any]) -> dict[str, Any]:
    # A JSON round trip makes tuples and lists, numpy ints and ints compare equal.
    return json.loads(dumps_json(dict(config)))


def _config_differences(stored: Mapping[str, Any], requested: Mapping[str, Any]) -> list[str]:
    keys = (set(stored) | set(requested)) - RESUME_MAY_DIFFER
    differences = []
    for key in sorted(keys):
        if key not in stored and key in RESUME_UNKNOWN_IF_MISSING:
            continue  # an older run.json that did not record it: nothing to compare
        old = stored[key] if key in stored else RESUME_DEFAULTS.get(key)
        if old != requested.get(key):
            differences.append(f"{key}: stored {old!r}, requested {requested.get(key)!r}")
    return differences


class EpisodeWriter:
    """Appends episode records to ``<out_dir>/episodes.jsonl`` as episodes end.

    ``run_config`` describes the run (at least policy, task, split, seed) and is
    stored in ``run.json``. If the directory already holds episodes:

    - ``resume=False``: refuse (:class:`FileExistsError`), so a new run never
      silently appends to an old one;
    - ``resume=True``: the stored config must equal ``run_config`` (except keys in
      :data:`RESUME_MAY_DIFFER`), else :class:`RunMismatchError`; a truncated last
      line is removed from the file; :meth:`completed_episodes` tells the caller
      which episode indices to skip.

    Use as a context manager or call :meth:`close`.
    """

    def __init__(
        self,
        out_dir: str | os.PathLike[str],
        run_config: Mapping[str, Any] | None = None,
        *,
        resume: bool = False,
        expected_seed: Callable[[int], int] | None = None,
    ) -> None:
        self.out_dir = Path(out_dir)
        self.expected_seed = expected_seed
        self.path = self.out_dir / EPISODES_FILE
        self.run_config_path = self.out_dir / RUN_CONFIG_FILE
        self.run_config = _normalise_config(run_config or {})
        self._completed: set[int] = set()
        self.records: list[dict[str, Any]] = []
        self._pool: tuple[str, int] | None = None  # (furniture_pool, first episode with it)
        self.dropped_bytes = 0
        self.written = 0

        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._created = not self.path.exists(), not self.run_config_path.exists()
        has_episodes = self.path.exists() and self.path.stat().st_size > 0
        if has_episodes and not resume:
            raise FileExistsError(
                f"{self.path} already holds episodes; pass --resume to continue that run "
                "or choose another output directory"
            )
        self._check_or_store_config(resume=resume, has_episodes=has_episodes)
        if has_episodes:
            self._load_and_repair()
        self._file = open(self.path, "a", encoding="utf-8")

    # -- setup ---------------------------------------------------------------
    def _check_or_store_config(self, *, resume: bool, has_episodes: bool) -> None:
        if self.run_config_path.exists():
            try:
                stored = json.loads(self.run_config_path.read_text(encoding="utf-8"))
            except ValueError as error:
                raise RunMismatchError(
                    f"{self.run_config_path} is not valid JSON ({error}); remove the directory "
                    "or choose another output directory"
                ) from error
            if resume or has_episodes:
                differences = _config_differences(stored, self.run_config)
                if differences:
                    raise RunMismatchError(
                        f"cannot resume {self.out_dir}: it holds a different run ("
                        + "; ".join(differences)
                        + "); use another output directory or the original settings"
                    )
                return
        elif has_episodes:
            raise RunMismatchError(
                f"{self.out_dir} holds episodes but no {RUN_CONFIG_FILE}, so it cannot be "
                "checked to be the same run; use another output directory"
            )
        self._write_json_atomically(self.run_config_path, self.run_config)

    def _load_and_repair(self) -> None:
        records, good_end, dropped = _scan_lines(self.path)
        if dropped:
            warnings.warn(
                f"{self.path}: dropping a truncated last line ({dropped} bytes) left by an "
                "interrupted run; that episode will be run again",
                stacklevel=3,
            )
            with open(self.path, "r+b") as handle:
                handle.truncate(good_end)
                handle.flush()
                os.fsync(handle.fileno())
            self.dropped_bytes = dropped
        self._check_records(records)
        self.records = records
        self._completed = {int(record["episode"]) for record in records}

    def _check_records(self, records: list[dict[str, Any]]) -> None:
        """Refuse a file that two writers filled at once (an episode twice) or that holds
        episodes of another run (another policy, task, split, observation or seed)."""
        seen: set[int] = set()
        for line, record in enumerate(records, start=1):
            validate_record(record)
            episode = int(record["episode"])
            if episode in seen:
                raise RunMismatchError(
                    f"{self.path} holds episode {episode} more than once (two runs wrote to it at the same "
                    "time?); its numbers cannot be trusted: rerun into a new --out"
                )
            seen.add(episode)
            foreign = [f"{key} {record[key]!r} (run: {self.run_config[key]!r})" for key in RECORD_CONFIG_KEYS
                       if key in record and key in self.run_config and record[key] != self.run_config[key]]
            if self.expected_seed is not None and int(record["seed"]) != self.expected_seed(episode):
                foreign.append(f"seed {record['seed']} (run: {self.expected_seed(episode)})")
            if foreign:
                raise RunMismatchError(
                    f"{self.path}: record {line} (episode {episode}) belongs to another run: "
                    + ", ".join(foreign) + "; rerun into a new --out"
                )
            self._check_pool(record)

    def _check_pool(self, record: Mapping[str, Any]) -> None:
        """Refuse a record drawn from other furniture than the run's earlier records: the
        same seed would then mean different objects within one run."""
        pool = record.get("furniture_pool")
        if pool is None:
            return
        if self._pool is None:
            self._pool = (str(pool), int(record["episode"]))
        elif str(pool) != self._pool[0]:
            raise RunMismatchError(
                f"{self.path}: episode {record['episode']} was drawn from other furniture (pool {pool}) than "
                f"episode {self._pool[1]} (pool {self._pool[0]}): the processes of this run did not load the "
                "same objects (a skipped object is named in the log's warnings); rerun into a new --out"
            )

    @staticmethod
    def _write_json_atomically(path: Path, value: Any) -> None:
        temporary = path.with_suffix(path.suffix + ".tmp")
        temporary.write_text(dumps_json(value, indent=2, sort_keys=True) + "\n", encoding="utf-8")
        os.replace(temporary, path)

    # -- public --------------------------------------------------------------
    def completed_episodes(self) -> set[int]:
        """Indices of the episodes already recorded in this directory."""
        return set(self._completed)

    def write(self, record: Mapping[str, Any]) -> None:
        """Validate ``record`` and append it as one line, durably (flush + fsync).

        If the file system refuses (full, read-only), the file is cut back to its last
        complete record and :class:`RecordWriteError` says so.
        """
        if self._file.closed:
            raise ValueError(f"EpisodeWriter for {self.out_dir} is closed")
        validate_record(record)
        episode = int(record["episode"])
        if episode in self._completed:
            raise RecordFormatError(f"episode {episode} is already recorded in {self.path}")
        self._check_pool(record)
        line = dumps_json(record, sort_keys=False)
        good_end = self._file.tell()
        try:
            self._file.write(line + "\n")
            self._file.flush()
            os.fsync(self._file.fileno())
        except OSError as error:
            self._cut_back(good_end)
            raise RecordWriteError(
                error.errno, f"cannot write episode {episode} to {self.path} ({error.strerror or error}); "
                f"the {len(self._completed)} episodes before it are kept: free space or make the folder "
                "writable, then rerun with --resume"
            ) from None
        self._completed.add(episode)
        self.written += 1
        self.records.append(_restore_nans(json.loads(line)))

    def _cut_back(self, good_end: int) -> None:
        """Drop whatever part of a failed line reached the file (best effort)."""
        try:
            self._file.close()
        except OSError:
            pass
        try:
            os.truncate(self.path, good_end)
        except OSError:
            pass
        self._file = open(self.path, "a", encoding="utf-8")

    def sort_by_episode(self) -> None:
        """Rewrite the file in episode order if records arrived out of order (parallel
        workers); atomic, so a crash leaves either the old or the new file."""
        order = sorted(range(len(self.records)), key=lambda i: int(self.records[i]["episode"]))
        if order == list(range(len(self.records))):
            return
        lines = self.path.read_bytes().splitlines(keepends=True)
        lines = [line for line in lines if line.strip()]
        if len(lines) != len(self.records):
            raise RecordFormatError(f"{self.path} changed while it was being written")
        self._file.close()
        temporary = self.path.with_suffix(self.path.suffix + ".tmp")
        with open(temporary, "wb") as handle:
            handle.writelines(lines[i] for i in order)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, self.path)
        self.records = [self.records[i] for i in order]
        self._file = open(self.path, "a", encoding="utf-8")

    def discard_if_unused(self) -> None:
        """Close; if this writer created the files and wrote no episode, remove them."""
        self.close()
        if self.written or self.records:
            return
        for created, path in zip(self._created, (self.path, self.run_config_path)):
            if created:
                try:
                    path.unlink()
                except FileNotFoundError:
                    pass

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()

    def __enter__(self) -> "EpisodeWriter":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __iter__(self) -> Iterator[dict[str, Any]]:
        return iter(list(self.records))


def records_from(source: str | os.PathLike[str] | Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Records from a path (file or run directory) or an iterable of mappings."""
    if isinstance(source, (str, os.PathLike)):
        return read_episodes(source)
    return [dict(record) for record in source]
