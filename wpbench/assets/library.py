"""Find furniture: the built-in procedural library (generated once, cached) or a folder.

``load_library("procedural", split="train")`` is what tasks call. The procedural
library lives in ``$WPBENCH_CACHE/procedural/seed-<S>-n<N>-v<G>-t<T>`` (``$WPBENCH_CACHE``
defaults to ``~/.cache/wpbench``); it is generated into a temporary sibling folder
and renamed into place, so a crash or a concurrent run never leaves a half-written
library behind.

Splits: ``train`` (training data), ``val`` (model selection and development numbers)
and ``test`` (held out: scored once per release of the weights, after every choice is
made). Test instances are numbered apart from the others
(``wpbench.assets.procedural.TEST_FIRST_INDEX``), so no train or val instance, and no
extra training instance, can ever be one of them.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import os
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path

from wpbench.assets.spec import FurnitureAsset
from wpbench.names import SPLITS

log = logging.getLogger(__name__)


def cache_root() -> Path:
    """``$WPBENCH_CACHE`` or ``~/.cache/wpbench``."""
    env = os.environ.get("WPBENCH_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "wpbench"


def default_val_per_category(per_category: int) -> int:
    """4 of 16 by default: a quarter, at least one when there are two or more instances."""
    return 0 if per_category < 2 else max(1, per_category // 4)


def procedural_library(seed: int = 0, per_category: int = 16, cache_dir: Path | None = None,
                       extra_train: int = 0, test_per_category: int | None = None) -> Path:
    """Folder of the procedural library for (seed, per_category), generating it on first use.

    ``cache_dir`` replaces ``cache_root()``; the library goes to
    ``<cache>/procedural/seed-<seed>-n<per_category>-v<generator version>`` plus
    ``-x<extra_train>`` with extra training instances (same val split, more train
    furniture) and ``-t<test_per_category>`` (default ``TEST_PER_CATEGORY``) with test
    instances.
    """
    from wpbench.assets.procedural import GENERATOR_VERSION, TEST_PER_CATEGORY, generate_library

    tests = TEST_PER_CATEGORY if test_per_category is None else int(test_per_category)
    root = Path(cache_dir) if cache_dir is not None else cache_root()
    name = (f"seed-{int(seed)}-n{int(per_category)}-v{GENERATOR_VERSION}" + (f"-x{int(extra_train)}" if extra_train else "")
            + (f"-t{tests}" if tests else ""))
    folder = root / "procedural" / name
    if (folder / "split.json").is_file():
        return folder
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.tmp-", dir=folder.parent))
    try:
        log.info("generating the procedural furniture library into %s", folder)
        generate_library(tmp, per_category=per_category, val_per_category=default_val_per_category(per_category), seed=seed,
                         extra_train=extra_train, test_per_category=tests)
        try:
            os.rename(tmp, folder)
        except OSError:
            # Another process finished first: its library is identical (same seed), keep it.
            if not (folder / "split.json").is_file():
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return folder


def _check_names(kind: str, given: Iterable[str] | None, valid: Iterable[str]) -> None:
    valid = sorted(set(valid))
    for name in given or ():
        if name not in valid:
            raise ValueError(f"unknown {kind} {name!r}; valid {kind}s: {', '.join(valid) or '(none)'}")


def is_generated_library(folder: Path) -> bool:
    """True for a folder ``wpbench assets generate`` wrote (it has ``split.json``): its objects are
    read as they are, never loaded or decomposed as PartNet-Mobility objects."""
    return (Path(folder) / "split.json").is_file()


def _load_split_folder(folder: Path, split: str | None) -> list[FurnitureAsset]:
    meta = json.loads((folder / "split.json").read_text())
    ids = [(i, s) for s in SPLITS if split in (None, s) for i in meta.get(s, [])]
    if split is not None and not ids:
        raise ValueError(f"{folder} has no {split} instances; generate the library with some "
                         f"(wpbench assets generate --out DIR, see --help)")
    assets = []
    for object_id, s in ids:
        spec = folder / object_id / "wpbench.json"
        if not spec.is_file():
            raise FileNotFoundError(f"{spec} listed in {folder / 'split.json'} is missing; regenerate the library")
        asset = FurnitureAsset.load(spec)
        if asset.split != s:
            from dataclasses import replace

            asset = replace(asset, split=s)
        assets.append(asset)
    return assets


def load_library(
    source: str | Path = "procedural",
    split: str | None = None,
    categories: Iterable[str] | None = None,
    seed: int = 0,
    per_category: int = 16,
    extra_train: int = 0,
) -> list[FurnitureAsset]:
    """Furniture assets from ``source``.

    Args:
        source: "procedural" (the cached built-in library for ``seed``/``per_category``),
            a folder with ``split.json`` and ``<id>/wpbench.json`` (a generated library),
            or any other folder, read by ``wpbench.assets.partnet.load_partnet_folder``
            (PartNet-Mobility objects; those that fail to load are logged and skipped).
        split: "train", "val", "test" or None for all. A PartNet-Mobility folder with a
            split file (``wpbench assets split``, ``wpbench.assets.object_split``) gives
            that split's objects; without one the split is ignored (every object is a
            held-out object).
        categories: keep only these categories (None: all).
        extra_train: procedural only: that many more training instances per category
            (for training data; the val and test instances are unchanged and can never
            be among them).

    Raises:
        ValueError: unknown split or category (the message lists the valid ones), or a
            folder with no furniture in it.
    """
    if split is not None and split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; valid splits: {', '.join(SPLITS)} (or None for all)")
    categories = list(categories) if categories is not None else None
    if isinstance(source, str) and source == "procedural":
        from wpbench.assets.procedural import CATEGORIES

        _check_names("category", categories, CATEGORIES)
        folder = procedural_library(seed=seed, per_category=per_category, extra_train=extra_train)
        assets = _load_split_folder(folder, split)
    else:
        folder = Path(source).expanduser()
        if not folder.is_dir():
            raise ValueError(f"asset source {str(source)!r} is neither 'procedural' nor an existing folder")
        if is_generated_library(folder):
            assets = _load_split_folder(folder, split)
        elif importlib.util.find_spec("wpbench.assets.partnet") is not None:
            from wpbench.assets.partnet import load_partnet_folder

            from wpbench.assets.object_split import split_of_objects

            split_by_id = split_of_objects(folder)
            only = None
            if split_by_id is not None and split is not None:
                only = {object_id for object_id, s in split_by_id.items() if s == split}
                if not only:
                    raise ValueError(f"the split file of {folder} puts no object in {split}; rewrite it with other "
                                     f"fractions (wpbench assets split {folder} --help)")
            assets, errors = load_partnet_folder(folder, only=only)
            for name, reason in sorted(errors.items()):
                log.warning("skipped %s: %s", name, reason)
            if split_by_id is not None:
                from dataclasses import replace

                assets = [replace(a, split=split_by_id.get(a.object_id)) for a in assets]
        else:
            raise ValueError(f"{folder} has no split.json and the PartNet-Mobility loader is not available")
        _check_names("category", categories, {a.category for a in assets})
    if categories is not None:
        assets = [a for a in assets if a.category in categories]
    return assets


def furniture_pool_digest(assets: Iterable[FurnitureAsset]) -> str:
    """A short hash of the furniture an env draws its episodes from, in draw order.

    An episode's furniture is ``assets[draw(seed)]``, so two processes give a seed the same
    furniture only if they loaded the same objects in the same order. Episode records carry
    this hash and a run refuses to mix two of them (``wpbench.evaluation.records``): a
    worker that could not load an object would otherwise draw other furniture for the
    same seeds without a word.
    """
    import hashlib

    digest = hashlib.sha256()
    for asset in assets:
        digest.update(f"{asset.source}\t{asset.category}\t{asset.object_id}\n".encode())
    return digest.hexdigest()[:16]


def run_split(source: str | Path, split: str | None) -> str | None:
    """The split a run on ``source`` loads: None for "all"; for a folder, ``split`` only when the
    folder has a split file of its objects (``wpbench assets split``), else None (every object)."""
    if split in ("all", None):
        return None
    if isinstance(source, str) and source == "procedural":
        return split
    from wpbench.assets.object_split import find_split_file

    return split if find_split_file(Path(source).expanduser()) is not None else None
