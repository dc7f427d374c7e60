"""Decompose a whole PartNet-Mobility folder ahead of time, all objects' links at once.

``wpbench assets prepare DIR --workers N`` fills the collision cache that the loader
reads (``wpbench.assets.partnet.default_cache_dir``), so later runs, and every worker
of a run, find each object's pieces ready. The links of every object go into one
queue of worker processes (``wpbench.assets.decompose``): a big body and a small knob
of different objects run side by side, and a link whose decomposition crashes costs
only itself. Objects the text files already refuse (no door, missing files) are
never decomposed. Runs and data generation on local worker processes call
:func:`prepare_asset_sources` before their first worker starts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

from wpbench.assets.collision import CollisionBuildError, DerivedCollision, finish_collision, plan_collision
from wpbench.assets.decompose import CoacdConfig, read_entry, run_jobs
from wpbench.assets.partnet import PartNetLoadError, default_cache_dir, describe_object, object_folders


@dataclass
class PreparedObject:
    """One object folder after preparation.

    derived: its collision geometry (None when it could not be built).
    error: why the object cannot be used, in one line (None when it can so far).
    seconds: decomposition time of its links, summed (measured when first computed).
    crashes: {link: reason} for links whose decomposition crashed (they got a fallback).
    """

    folder: Path
    derived: DerivedCollision | None = None
    error: str | None = None
    seconds: float = 0.0
    crashes: dict[str, str] = field(default_factory=dict)


def _object_cache(cache_dir: Path | None, object_id: str) -> Path:
    return default_cache_dir(object_id) if cache_dir is None else Path(cache_dir) / object_id


def prepare_folder(root: Path, workers: int | None = None, cache_dir: Path | None = None,
                   coacd: CoacdConfig | None = None, progress: bool = True,
                   decomposer: str | None = None) -> list[PreparedObject]:
    """Build the collision cache of every object under ``root``; one result per folder, sorted.

    ``cache_dir``: base cache directory (object ``<id>`` uses ``cache_dir/<id>``; default
    :func:`wpbench.assets.partnet.default_cache_dir`). ``workers``: decomposition
    processes at once (default: one per core). ``decomposer``: see ``plan_collision``.
    """
    root = Path(root)
    if not root.is_dir():
        raise PartNetLoadError(f"{root} is not a directory; pass the folder that holds PartNet-Mobility objects.")
    results = [PreparedObject(folder) for folder in object_folders(root)]
    plans = {}
    for result in results:
        try:
            describe_object(result.folder)
            plans[result.folder.name] = plan_collision(result.folder, _object_cache(cache_dir, result.folder.name),
                                                       coacd, decomposer=decomposer)
        except (PartNetLoadError, CollisionBuildError) as err:
            result.error = _one_line(str(err), result.folder.name)
    try:
        jobs = [job for plan in plans.values() for job in plan.jobs]
        crashes = run_jobs(jobs, workers=workers, progress=progress)
    finally:
        for plan in plans.values():
            plan.cleanup()
    for result in results:
        plan = plans.get(result.folder.name)
        if plan is None:
            continue
        result.crashes = {label.split("/", 1)[1]: reason for label, reason in crashes.items()
                          if label.split("/", 1)[0] == result.folder.name}
        try:
            result.derived = finish_collision(plan)
        except CollisionBuildError as err:
            result.error = _one_line(str(err), result.folder.name)
            continue
        result.seconds = sum(float(read_entry(entry)["seconds"]) for entry in plan.entries.values())
    return results


def prepare_asset_sources(sources: Iterable[str], progress: bool = False) -> None:
    """:func:`prepare_folder` for every distinct PartNet-Mobility folder among the asset sources
    ``sources`` ("procedural" and generated libraries carry their own collision boxes and need
    nothing): what worker processes about to load these objects would otherwise each
    decompose, done once here."""
    from wpbench.assets.library import is_generated_library

    folders = {Path(source).expanduser().resolve() for source in sources if source != "procedural"}
    folders = {folder for folder in folders if not is_generated_library(folder)}
    for folder in sorted(folders):
        prepare_folder(folder, progress=progress)


def _one_line(message: str, object_id: str) -> str:
    text = " ".join(message.split())
    return text if text.startswith(object_id) else f"{object_id}: {text}"
