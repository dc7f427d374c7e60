"""Join the shards of one run (``wpbench run --shard i/N``) into one run folder (``wpbench merge``)."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Sequence

from wpbench.evaluation.records import (
    EPISODES_FILE, RESUME_MAY_DIFFER, RUN_CONFIG_FILE, RunMismatchError, dumps_json, read_episodes)

__all__ = ["merge_shards", "SHARD_MAY_DIFFER"]

# run.json keys that differ between the shards of one run.
SHARD_MAY_DIFFER = frozenset(RESUME_MAY_DIFFER | {"shard"})


def _config(folder: Path) -> dict[str, Any]:
    path = folder / RUN_CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{folder} holds no {RUN_CONFIG_FILE}: not a run folder of `wpbench run --shard`")
    return json.loads(path.read_text())


def merge_shards(shards: Sequence[str | os.PathLike[str]], out: str | os.PathLike[str]) -> dict[str, Any]:
    """Check that ``shards`` are the N shards of one run (same settings, shards 0..N-1 once
    each, every episode of each shard present) and write ``out`` with their episodes in
    order, ``run.json`` (without the shard) and ``summary.json``; returns the summary."""
    from wpbench.evaluation.runner import parse_shard
    from wpbench.evaluation.summary import summarize, write_summary

    folders = [Path(s) for s in shards]
    configs = [_config(f) for f in folders]
    first = configs[0]
    for folder, config in zip(folders[1:], configs[1:]):
        keys = (set(first) | set(config)) - SHARD_MAY_DIFFER
        differences = [f"{k}: {first.get(k)!r} vs {config.get(k)!r}" for k in sorted(keys) if first.get(k) != config.get(k)]
        if differences:
            raise RunMismatchError(f"{folder} is a shard of another run than {folders[0]} ({'; '.join(differences)}); "
                                   "merge only the shards of one run")
    specs = [config.get("shard") for config in configs]
    if None in specs:
        raise RunMismatchError(f"{folders[specs.index(None)]} is not a shard (run without --shard)")
    parsed = [parse_shard(spec) for spec in specs]
    count = parsed[0][1]
    if {n for _, n in parsed} != {count} or sorted(i for i, _ in parsed) != list(range(count)):
        raise RunMismatchError(f"need shards 0/{count} ... {count - 1}/{count} once each, got {', '.join(specs)}")
    episodes = max(int(config.get("episodes", 0)) for config in configs)
    records = []
    for folder, (index, _) in zip(folders, parsed):
        got = read_episodes(folder)
        missing = sorted({i for i in range(episodes) if i % count == index} - {int(r["episode"]) for r in got})
        if missing:
            raise RunMismatchError(f"{folder} lacks episodes {missing[:5]}{'...' if len(missing) > 5 else ''}; "
                                   "finish it with --resume before merging")
        records += got
    records.sort(key=lambda r: int(r["episode"]))
    target = Path(out)
    if (target / EPISODES_FILE).exists():
        raise FileExistsError(f"{target / EPISODES_FILE} exists; merge into a new folder")
    target.mkdir(parents=True, exist_ok=True)
    merged = {**{k: v for k, v in first.items()}, "shard": None, "out": str(target), "episodes": episodes}
    (target / RUN_CONFIG_FILE).write_text(dumps_json(merged, indent=2, sort_keys=True) + "\n")
    (target / EPISODES_FILE).write_text("".join(dumps_json(r) + "\n" for r in records))
    meta = {"policy": first["policy"], "task": first["task"], "split": first["split"],
            "asset_source": first["assets"], "obs": first["obs"], "seed": first["seed"],
            "executor": first.get("executor", "ideal"), "merged_from": [str(f) for f in folders]}
    summary = summarize(records, meta)
    write_summary(target, summary)
    return summary
