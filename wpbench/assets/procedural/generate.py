"""Generate procedural furniture folders and a fixed train/val/test split.

Each instance draws from its own numpy Generator seeded by (library seed, category,
index), so an object does not change when other categories or counts change, and
the same seed writes byte-identical files.

Indices ``0 .. per_category - 1`` are train then val, extra training instances follow
them, and test instances are numbered from :data:`TEST_FIRST_INDEX`, which no train or
val index may reach: a test instance is never one that was trained or selected on.
"""

from __future__ import annotations

import json
import zlib
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from wpbench.assets.procedural import dishwasher, fridge, microwave, oven, safe, storage
from wpbench.assets.procedural.blueprint import Blueprint, check_blueprint
from wpbench.assets.procedural.writer import write_model
from wpbench.assets.spec import FurnitureAsset, OrientedBox

# Bump when a change to any builder changes the files it writes (cache keys use it).
GENERATOR_VERSION = 4

BUILDERS: dict[str, Callable[[np.random.Generator, str], Blueprint]] = {
    "oven": oven.build,
    "microwave": microwave.build,
    "dishwasher": dishwasher.build,
    "fridge": fridge.build,
    "safe": safe.build,
    "storage": storage.build,
}
CATEGORIES: tuple[str, ...] = tuple(BUILDERS)

# Test instances are numbered from here; per_category + extra_train may not reach it.
TEST_FIRST_INDEX = 9000
# Test instances per category in the built-in library.
TEST_PER_CATEGORY = 8


def check_category(category: str) -> None:
    if category not in BUILDERS:
        raise ValueError(f"unknown category {category!r}; valid categories: {', '.join(CATEGORIES)}")


def instance_rng(seed: int, category: str, index: int) -> np.random.Generator:
    """The generator for one instance; crc32 gives a category key stable across Python runs."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(category.encode()), int(index)]))


def object_id(category: str, index: int) -> str:
    return f"{category}-{index:04d}"


def build_blueprint(category: str, index: int, seed: int = 0) -> Blueprint:
    """Build (in memory, nothing written) instance ``index`` of ``category``."""
    check_category(category)
    bp = BUILDERS[category](instance_rng(seed, category, index), object_id(category, index))
    check_blueprint(bp)
    return bp


def generate_object(category: str, index: int, out: Path, seed: int = 0, split: str | None = None) -> FurnitureAsset:
    """Write one object into ``out/<category>-<index>/`` and return its asset description."""
    bp = build_blueprint(category, index, seed)
    folder = Path(out) / bp.model.name
    urdf = write_model(bp.model, folder)
    low, high = bp.model.bounds()
    region = bp.in_region
    asset = FurnitureAsset(
        object_id=bp.model.name,
        category=category,
        urdf=urdf,
        scale=1.0,
        target_link=bp.target_link,
        target_joint=bp.target_joint,
        joint_type=bp.joint_type,
        closed_qpos=float(bp.closed_qpos),
        open_qpos=float(bp.open_qpos),
        in_region=OrientedBox(
            center=tuple(round(float(v), 6) for v in (region[0] + region[1]) / 2),
            half_extents=tuple(round(float(v), 6) for v in (region[1] - region[0]) / 2),
        ),
        bounds_low=tuple(round(float(v), 6) for v in low),
        bounds_high=tuple(round(float(v), 6) for v in high),
        front=(1.0, 0.0, 0.0),
        source="procedural",
        split=split,
        extra=_plain(bp.extra),
    )
    asset.save(folder / "wpbench.json")
    meta = {"category": category, "id": bp.model.name, "seed": int(seed), "index": int(index),
            "generator": "wpbench.assets.procedural", "generator_version": GENERATOR_VERSION}
    (folder / "meta.json").write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
    return asset


def _plain(value):
    """JSON-friendly copy: numpy scalars to floats, tuples to lists, floats rounded."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in sorted(value.items())}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return round(float(value), 6)
    return value


def split_of(index: int, per_category: int, val_per_category: int) -> str:
    """Split of instance ``index``: the last ``val_per_category`` of the first ``per_category``
    are validation, indices from :data:`TEST_FIRST_INDEX` are test, every other one is train."""
    if index >= TEST_FIRST_INDEX:
        return "test"
    if per_category - val_per_category <= index < per_category:
        return "val"
    return "train"


def indices_of_test_split(test_per_category: int) -> range:
    """Indices of the test instances of each category."""
    return range(TEST_FIRST_INDEX, TEST_FIRST_INDEX + int(test_per_category))


def generate_library(
    out: Path,
    per_category: int = 16,
    val_per_category: int = 4,
    seed: int = 0,
    categories: Iterable[str] | None = None,
    progress: Callable[[Iterable], Iterable] | None = None,
    extra_train: int = 0,
    test_per_category: int = 0,
) -> list[FurnitureAsset]:
    """Write ``per_category`` objects of each category into ``out`` plus ``split.json``.

    ``split.json`` = {"train": [ids], "val": [ids], "test": [ids], "seed": S,
    "per_category": N, "val_per_category": V, "extra_train": X, "test_per_category": T,
    "test_first_index": I, "generator_version": G, "categories": [...]}.
    ``extra_train``: further training instances per category, numbered after the
    first ``per_category`` (an instance does not depend on the library size, so the
    val instances stay exactly those of the library without them).
    ``test_per_category``: held-out test instances per category, numbered from
    :data:`TEST_FIRST_INDEX` (they leave every train and val instance unchanged).
    ``progress`` optionally wraps the job list (e.g. ``tqdm``).
    """
    categories = tuple(categories) if categories is not None else CATEGORIES
    for c in categories:
        check_category(c)
    if per_category < 1:
        raise ValueError(f"per_category must be >= 1, got {per_category}")
    if not 0 <= val_per_category < per_category:
        raise ValueError(f"val_per_category must be in [0, per_category), got {val_per_category} with per_category={per_category}")
    if extra_train < 0:
        raise ValueError(f"extra_train must be >= 0, got {extra_train}")
    if per_category + extra_train > TEST_FIRST_INDEX:
        raise ValueError(f"per_category + extra_train must be at most {TEST_FIRST_INDEX} (test instances are numbered "
                         f"from there), got {per_category} + {extra_train}")
    if test_per_category < 0:
        raise ValueError(f"test_per_category must be >= 0, got {test_per_category}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    indices = [*range(per_category + extra_train), *indices_of_test_split(test_per_category)]
    jobs = [(c, i) for c in categories for i in indices]
    assets = []
    for c, i in progress(jobs) if progress else jobs:
        assets.append(generate_object(c, i, out, seed, split_of(i, per_category, val_per_category)))
    split = {
        "train": [a.object_id for a in assets if a.split == "train"],
        "val": [a.object_id for a in assets if a.split == "val"],
        "test": [a.object_id for a in assets if a.split == "test"],
        "seed": int(seed),
        "per_category": int(per_category),
        "val_per_category": int(val_per_category),
        "extra_train": int(extra_train),
        "test_per_category": int(test_per_category),
        "test_first_index": TEST_FIRST_INDEX,
        "categories": list(categories),
        "generator_version": GENERATOR_VERSION,
    }
    (out / "split.json").write_text(json.dumps(split, indent=2, sort_keys=True) + "\n")
    return assets
