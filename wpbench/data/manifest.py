"""The index of a split directory: ``<split_dir>/manifest.json``.

It is rebuilt from the shard files on disk (never edited incrementally), so
two generator processes working on different kinds of the same split, or a
run that was interrupted, always leave a manifest that describes exactly the
shards that exist. ``content_hash`` identifies the data a model was trained
on (it goes into the model's ``config.json``).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections import Counter
from pathlib import Path
from typing import Any

from wpbench.data.config import KINDS, GenerationConfig
from wpbench.data.shards import read_shard

MANIFEST_NAME = "manifest.json"
FORMAT_VERSION = 1


def split_dir(root: Path, split: str) -> Path:
    return Path(root) / split


def list_shards(directory: Path) -> list[Path]:
    """Complete shard files under a split directory, by kind then index."""
    directory = Path(directory)
    return sorted(p for kind in KINDS for p in (directory / kind).glob("shard-*.npz"))


def build_manifest(directory: Path, config: GenerationConfig, generation: dict[str, Any] | None = None) -> dict:
    """Describe every shard under ``directory`` (a split directory)."""
    directory = Path(directory)
    shards, by_kind, by_category = [], Counter(), {kind: Counter() for kind in KINDS}
    fingerprints = set()
    for path in list_shards(directory):
        data = read_shard(path, ("category", "fingerprint"))
        kind = path.parent.name
        count = len(data["category"])
        shards.append({"path": str(path.relative_to(directory)), "kind": kind, "count": count})
        by_kind[kind] += count
        by_category[kind].update(str(c) for c in data["category"])
        fingerprints.add(str(data["fingerprint"]))
    if len(fingerprints) > 1:
        raise ValueError(
            f"{directory} mixes shards generated with different configs ({sorted(fingerprints)}); "
            "delete the directory (or use another --out) and regenerate"
        )
    content = json.dumps({"fingerprint": sorted(fingerprints), "shards": shards}, sort_keys=True)
    return {
        "format": FORMAT_VERSION,
        "split": config.split,
        "config": config.to_json(),
        "fingerprint": config.sample_fingerprint(),
        "shards": shards,
        "counts": {kind: by_kind[kind] for kind in KINDS},
        "counts_by_category": {kind: dict(sorted(by_category[kind].items())) for kind in KINDS},
        "content_hash": hashlib.sha256(content.encode()).hexdigest()[:16],
        "generation": generation or {},
    }


def write_manifest(directory: Path, manifest: dict) -> Path:
    path = Path(directory) / MANIFEST_NAME
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    tmp.write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, path)
    return path


def read_manifest(directory: Path) -> dict:
    """The manifest of a split directory; FileNotFoundError naming the command that makes it."""
    path = Path(directory) / MANIFEST_NAME
    if not path.is_file():
        root, split = Path(directory).parent, Path(directory).name
        raise FileNotFoundError(
            f"no training data at {path}; make it with `wpbench data generate --out {root} --split {split}`"
        )
    try:
        manifest = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path} is not valid JSON ({err}); rerun `wpbench data generate` to rewrite it") from err
    if manifest.get("format") != FORMAT_VERSION:
        raise ValueError(f"{path} has format {manifest.get('format')!r}, expected {FORMAT_VERSION}; regenerate the data")
    return manifest
