"""The index of a split directory: ``<split_dir>/manifest.json``.

It is rebuilt from the shard files on disk (never edited incrementally), so
two generator processes working on different kinds of the same split, or a
run that was interrupted, always leave a manifest that describes exactly the
shards that exist. ``content_hash`` identifies the data a model was trained
on (it goes into the model's ``config.json``): it hashes the config fingerprint and
every shard's path, kind, count and ``digest`` (the shard's ``content_digest``, a sha256
of its arrays), so data written with the same options from other furniture differs in it.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections import Counter
from pathlib import Path
from typing import Any

from wpbench.data.config import KINDS, SPLITS, GenerationConfig
from wpbench.data.shards import read_shard, shard_digest

MANIFEST_NAME = "manifest.json"
FORMAT_VERSION = 1


def split_dir(root: Path, split: str) -> Path:
    return Path(root) / split


def list_shards(directory: Path) -> list[Path]:
    """Complete shard files under a split directory, by kind then index."""
    directory = Path(directory)
    return sorted(p for kind in KINDS for p in (directory / kind).glob("shard-*.npz"))


def asset_split_record(assets: str) -> dict | None:
    """For data made from a folder of one's own objects: its split file, the file's digest and
    the held-out (test) object ids at generation time; None for the built-in library."""
    from wpbench.assets.object_split import find_split_file, read_split_file, split_digest

    if assets == "procedural":
        return None
    path = find_split_file(Path(assets))
    if path is None:
        return None
    return {"file": str(path.resolve()), "digest": split_digest(path), "test": read_split_file(path)["splits"]["test"]}


def check_not_test_data(directory: Path, manifest: dict, object_ids: list[str] | None = None) -> None:
    """Refuse data that would let a test object into training or model selection.

    ``directory`` named after a split (train/, val/) must hold data generated from that
    split, never from test; and none of its ``object_ids`` may be a held-out object of
    the split file the data came from, as that file says now (a split rewritten after the
    data was made moves objects). ValueError saying what to do.
    """
    name = Path(directory).name
    made_from = manifest.get("split")
    if name in SPLITS and name != "test" and made_from != name:
        raise ValueError(f"{directory} holds data generated from the {made_from!r} split, not {name!r}: training and "
                         f"model selection never read test data; regenerate it with `wpbench data generate --split {name}`")
    record = manifest.get("asset_split")
    if name == "test" or not record or object_ids is None:
        return
    from wpbench.assets.object_split import read_split_file

    held_out = set(record.get("test", []))
    if Path(record["file"]).is_file():
        held_out |= set(read_split_file(Path(record["file"]))["splits"]["test"])
    leaked = sorted(held_out & set(object_ids))
    if leaked:
        raise ValueError(f"{directory} holds samples of held-out (test) objects {leaked[:5]} of {record['file']}; "
                         "the split was rewritten after the data was made: regenerate the data "
                         f"(`wpbench data generate --split {name}`) into a new folder")


def build_manifest(directory: Path, config: GenerationConfig, generation: dict[str, Any] | None = None) -> dict:
    """Describe every shard under ``directory`` (a split directory)."""
    directory = Path(directory)
    shards, by_kind, by_category = [], Counter(), {kind: Counter() for kind in KINDS}
    fingerprints = set()
    for path in list_shards(directory):
        data = read_shard(path, ("category", "fingerprint"))
        kind = path.parent.name
        count = len(data["category"])
        shards.append({"path": str(path.relative_to(directory)), "kind": kind, "count": count,
                       "digest": shard_digest(path)})
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
        **({"asset_split": record} if (record := asset_split_record(config.assets)) is not None else {}),
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
