"""Train / val / test splits of a folder of real objects (``wpbench assets split DIR``).

A split assigns whole objects (one folder = one object id) to train, val or test, so
no object is ever on both sides; it is stratified by category: within each category
the objects are shuffled with the seed and the first ``round(n * test_fraction)`` go
to test, the next ``round(n * val_fraction)`` to val, the rest to train (a category
with a single object keeps it in train).

The split file is ``DIR/wpbench-splits.json``. When DIR is read-only (a shared
download), it goes to ``$WPBENCH_CACHE/splits/<DIR name>-<hash of DIR's path>.json``
instead; :func:`find_split_file` looks in both places, DIR first. Format::

    {"format": 1, "seed": 0, "val_fraction": 0.2, "test_fraction": 0.2, "folder": "/abs/DIR",
     "splits": {"train": [ids], "val": [ids], "test": [ids]}, "categories": {id: category}}
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import zlib
from pathlib import Path

import numpy as np

from wpbench.names import SPLITS

SPLIT_FILE_NAME = "wpbench-splits.json"
SPLIT_FORMAT = 1


def stratified_split(categories: dict[str, str], val_fraction: float, test_fraction: float,
                     seed: int) -> dict[str, list[str]]:
    """{object id: category} -> {"train"|"val"|"test": sorted ids}; see the module docstring."""
    if not (0 <= val_fraction < 1 and 0 <= test_fraction < 1 and val_fraction + test_fraction < 1):
        raise ValueError(f"val fraction {val_fraction} and test fraction {test_fraction} must be in [0, 1) "
                         "and leave some objects for training (their sum below 1)")
    out: dict[str, list[str]] = {s: [] for s in SPLITS}
    for category in sorted(set(categories.values())):
        ids = sorted(i for i, c in categories.items() if c == category)
        rng = np.random.default_rng([int(seed), zlib.crc32(category.encode())])
        ids = [ids[k] for k in rng.permutation(len(ids))]
        n_test = int(np.floor(len(ids) * test_fraction + 0.5)) if len(ids) > 1 else 0
        n_val = int(np.floor(len(ids) * val_fraction + 0.5)) if len(ids) > 1 else 0
        n_test = min(n_test, len(ids) - 1)
        n_val = min(n_val, len(ids) - 1 - n_test)
        out["test"] += ids[:n_test]
        out["val"] += ids[n_test:n_test + n_val]
        out["train"] += ids[n_test + n_val:]
    return {s: sorted(ids) for s, ids in out.items()}


def _cache_split_path(folder: Path) -> Path:
    from wpbench.assets.library import cache_root

    key = hashlib.sha256(str(folder.resolve()).encode()).hexdigest()[:12]
    return cache_root() / "splits" / f"{folder.resolve().name}-{key}.json"


def find_split_file(folder: Path) -> Path | None:
    """The split file of ``folder`` (in it, else in the cache), or None when it has none."""
    folder = Path(folder)
    for path in (folder / SPLIT_FILE_NAME, _cache_split_path(folder)):
        if path.is_file():
            return path
    return None


def read_split_file(path: Path) -> dict:
    """The split file's contents; ValueError saying how to rewrite it when it is broken."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"{path} cannot be read ({err}); rewrite it with `wpbench assets split`") from err
    if data.get("format") != SPLIT_FORMAT or set(data.get("splits", {})) != set(SPLITS):
        raise ValueError(f"{path} is not a wpbench split file (format {SPLIT_FORMAT}); rewrite it with "
                         "`wpbench assets split`")
    return data


def split_of_objects(folder: Path) -> dict[str, str] | None:
    """{object id: split} from ``folder``'s split file, or None when it has none."""
    path = find_split_file(folder)
    if path is None:
        return None
    data = read_split_file(path)
    return {object_id: split for split in SPLITS for object_id in data["splits"][split]}


def split_digest(path: Path) -> str:
    """Short hash of a split file's bytes (recorded with data made from it)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def write_split_file(folder: Path, val_fraction: float = 0.2, test_fraction: float = 0.2,
                     seed: int = 0) -> tuple[Path, dict, dict[str, str]]:
    """Split the objects of ``folder`` and write its split file (where: see the module docstring).

    Objects are read from their text files only (no meshes, no physics); a folder whose
    category cannot be read is left out. Returns (path written, file contents,
    {folder name: reason} for the folders left out).
    """
    from wpbench.assets.partnet import PartNetLoadError, describe_object, object_folders

    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"{folder} is not a directory; pass the folder that holds your PartNet-Mobility objects")
    categories, skipped = {}, {}
    for sub in object_folders(folder):
        try:
            categories[sub.name] = describe_object(sub).category
        except PartNetLoadError as err:
            skipped[sub.name] = " ".join(str(err).split())
    if not categories:
        raise ValueError(f"{folder} holds no usable object folders ({len(skipped)} left out); "
                         "pass the folder that holds your PartNet-Mobility objects")
    data = {"format": SPLIT_FORMAT, "seed": int(seed), "val_fraction": float(val_fraction),
            "test_fraction": float(test_fraction), "folder": str(folder.resolve()),
            "splits": stratified_split(categories, val_fraction, test_fraction, seed),
            "categories": dict(sorted(categories.items()))}
    text = json.dumps(data, indent=2, sort_keys=True) + "\n"
    candidates = [folder / SPLIT_FILE_NAME, _cache_split_path(folder)]
    for path in candidates:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
            with os.fdopen(fd, "w") as f:
                f.write(text)
            os.replace(tmp, path)
        except OSError:
            if path == candidates[-1]:
                raise
            continue
        # A stale file in the other place must not win over the new one.
        other = _cache_split_path(folder)
        if path != other and other.is_file():
            other.unlink()
        return path, data, skipped
    raise AssertionError("unreachable")
