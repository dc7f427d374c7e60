"""Load real PartNet-Mobility objects as :class:`FurnitureAsset` (no hand annotation).

A PartNet-Mobility folder holds ``mobility.urdf``, ``semantics.txt`` (one line
per link: ``link_name joint_kind label``, e.g. ``link_0 hinge door``),
``meta.json`` (``model_cat``, the category) and the meshes. This module:

1. picks the *target*: among links whose semantics say ``hinge`` + a label
   containing ``door`` (revolute joint with finite limits), the largest door,
   sized by the area of the two largest sides of its closed bounding box; if
   there is no door, the largest ``slider`` + ``drawer`` link the same way.
   Knobs, buttons, handles and lids are never targets; every other movable
   link stays part of the anchor, held at its closed value
   (``extra["closed_qpos_by_joint"]``);
2. decides which joint limit is *closed* from geometry, not convention: the
   closed door or drawer lies inside the rest of the object's bounding box,
   the open one sticks out (PartNet-Mobility is usually closed at the lower
   limit, but nothing guarantees it);
3. builds hollow collision geometry (``wpbench.assets.collision``: the
   dataset's convex pieces or CoACD, cached outside the dataset); a small link
   whose decomposition fails gets a fallback (its convex hull, a thin box, or no
   collision), recorded in ``extra["collision_fallbacks"]``; the object is
   refused only when the target part or the cavity cannot be built;
4. scales the object to a realistic size for its category
   (:data:`CATEGORY_TYPICAL_SIZE_M`, the largest side of the closed object),
   unless the caller overrides the loader scale;
5. measures everything from the articulation as SAPIEN loads it (so the body
   frame is exactly the root link frame a task gets): bounds, the door's
   outward normal ``front``, and the cavity behind the door
   (``wpbench.assets.cavity``; for a drawer, the open drawer's inner volume).

Errors are :class:`PartNetLoadError` with a message that says what is wrong
and what to do; :func:`load_partnet_folder` collects them per folder so one
bad object never stops the others.
"""

from __future__ import annotations

import json
import logging
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wpbench.assets.cavity import CavityConfig, door_cavity, drawer_inner_volume
from wpbench.assets.collision import CoacdConfig, CollisionBuildError, build_hollow_collision_urdf
from wpbench.assets.collision_fallback import CONVEX_HULL
from wpbench.assets.clear_path import clear_target_path
from wpbench.assets.reach import BACK_OFF, OpeningProbe
from wpbench.assets.spec import FurnitureAsset

# Typical largest side (metres) of the closed object, per wpbench category.
# Ballpark real appliance/furniture sizes; the loader scale is this divided by
# the largest side of the object as the dataset stores it.
CATEGORY_TYPICAL_SIZE_M: dict[str, float] = {
    "microwave": 0.50,
    "oven": 0.90,
    "dishwasher": 0.85,
    "fridge": 1.75,
    "storage": 1.00,
    "safe": 0.50,
    "washing_machine": 0.85,
    "table": 1.00,
    "box": 0.40,
    "trashcan": 0.60,
}
# Size used when the category is not in the table (a counter-height cabinet).
DEFAULT_TYPICAL_SIZE_M = 0.80

# PartNet-Mobility ``model_cat`` / body labels -> wpbench category names.
_CATEGORY_ALIASES: dict[str, str] = {
    "refrigerator": "fridge",
    "storagefurniture": "storage",
    "furniture": "storage",
    "washingmachine": "washing_machine",
    "trashcan": "trashcan",
}

MIN_REGION_HALF_EXTENT_M = 0.02  # a region must hold at least a 4 cm object
# A collision piece may be dropped from a door's path only if the cavity keeps this fraction of its volume.
CAVITY_KEEP_FRACTION = 0.8
MAX_NAMED_BLOCKERS = 2  # blocking pieces named in a message

log = logging.getLogger(__name__)
_DOOR_MIN_RANGE_RAD = 0.3  # hinges that barely move (latches) are not doors


class PartNetLoadError(ValueError):
    """A PartNet-Mobility folder cannot be turned into a FurnitureAsset; the message says how to fix it."""


@dataclass(frozen=True)
class PartNetLoadConfig:
    """Knobs of the loader that users may tune (defaults suit the shipped objects)."""

    coacd: CoacdConfig = CoacdConfig()
    cavity: CavityConfig = CavityConfig()
    # Measure in physics how far the target really opens (see wpbench.assets.reach).
    probe_reach: bool = True
    # Trim collision pieces overlapping the target and drop those blocking it that the cavity can spare
    # (wpbench.assets.clear_path); False only measures (the check without the fix).
    clear_path: bool = True
    # Refuse targets that physics lets open less than this fraction of their range.
    min_reach_fraction: float = 0.5
    # Decomposition worker processes (None: one per core) and whether to show their progress bar.
    workers: int | None = None
    progress: bool = False
    # "module:function" that decomposes a link instead of CoACD (see wpbench.assets.decompose).
    decomposer: str | None = None


@dataclass(frozen=True)
class _Movable:
    """A movable link as the URDF and semantics.txt describe it."""

    link: str
    joint: str
    urdf_type: str  # "revolute", "prismatic", "continuous"
    semantic_kind: str  # "hinge", "slider", ...
    label: str  # "door", "rotation_door", "drawer", "knob", ...
    lower: float
    upper: float

    @property
    def is_door(self) -> bool:
        return (self.semantic_kind == "hinge" and "door" in self.label and self.urdf_type == "revolute"
                and np.isfinite(self.lower) and np.isfinite(self.upper)
                and self.upper - self.lower > _DOOR_MIN_RANGE_RAD)

    @property
    def is_drawer(self) -> bool:
        return (self.semantic_kind == "slider" and "drawer" in self.label and self.urdf_type == "prismatic"
                and self.upper > self.lower)


# --------------------------------------------------------------------------- category and scale


def normalise_category(raw: str) -> str:
    """PartNet-Mobility category name ("Refrigerator", "StorageFurniture") -> wpbench name ("fridge", "storage")."""
    key = raw.strip().lower().replace(" ", "").replace("_", "")
    return _CATEGORY_ALIASES.get(key, raw.strip().lower().replace(" ", "_"))


def typical_size(category: str) -> float:
    """Typical largest side (m) of a closed object of ``category`` (wpbench or PartNet name)."""
    return CATEGORY_TYPICAL_SIZE_M.get(normalise_category(category), DEFAULT_TYPICAL_SIZE_M)


def category_scale(category: str, largest_side_unscaled: float) -> float:
    """Loader scale that makes an object whose largest side is ``largest_side_unscaled`` typical-sized."""
    if not largest_side_unscaled > 0:
        raise PartNetLoadError(f"object has no extent (largest side {largest_side_unscaled}); its meshes are empty.")
    return typical_size(category) / largest_side_unscaled


def _resolve_scale_override(
    override: dict[str, float] | float | None, object_id: str, category: str, raw_category: str
) -> float | None:
    """A float applies to every object; a dict is looked up by object id, then category (wpbench, then raw)."""
    if override is None:
        return None
    if isinstance(override, (int, float)):
        value = float(override)
    else:
        for key in (object_id, category, raw_category):
            if key in override:
                value = float(override[key])
                break
        else:
            return None
    if not value > 0:
        raise PartNetLoadError(f"scale override {value} for {object_id} must be a positive number.")
    return value


def default_cache_dir(object_id: str) -> Path:
    """``$WPBENCH_CACHE/partnet/<id>`` or ``~/.cache/wpbench/partnet/<id>``."""
    base = os.environ.get("WPBENCH_CACHE")
    return (Path(base) if base else Path.home() / ".cache" / "wpbench") / "partnet" / object_id


# --------------------------------------------------------------------------- reading the folder


def _read_category(folder: Path, semantics: list[tuple[str, str, str]]) -> str:
    meta = folder / "meta.json"
    if meta.is_file():
        try:
            raw = json.loads(meta.read_text()).get("model_cat")
        except json.JSONDecodeError as err:
            raise PartNetLoadError(f"{meta} is not valid JSON ({err}); restore it or delete it.") from err
        if raw:
            return str(raw)
    # No meta.json: the static body's label ("microwave_body") names the category.
    for _link, kind, label in semantics:
        if kind in ("heavy", "static", "free") and label.endswith("_body"):
            return label[: -len("_body")]
    return "unknown"


def _read_semantics(folder: Path) -> list[tuple[str, str, str]]:
    path = folder / "semantics.txt"
    if not path.is_file():
        raise PartNetLoadError(
            f"{folder.name}: semantics.txt is missing; it names the door/drawer links. "
            "Restore it from the PartNet-Mobility download."
        )
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        parts = line.split(maxsplit=2)
        if len(parts) != 3:
            raise PartNetLoadError(
                f"{path} line {number} {line!r} is not 'link_name joint_kind label'; fix or restore the file."
            )
        rows.append((parts[0], parts[1], parts[2].strip()))
    return rows


def _read_movables(folder: Path, semantics: list[tuple[str, str, str]]) -> list[_Movable]:
    urdf = folder / "mobility.urdf"
    if not urdf.is_file():
        raise PartNetLoadError(f"{folder.name}: mobility.urdf is missing; restore it from the download.")
    try:
        root = ET.parse(urdf).getroot()
    except ET.ParseError as err:
        raise PartNetLoadError(f"{urdf} is not valid XML ({err}); restore it from the download.") from err
    joints_by_child = {}
    for joint in root.findall("joint"):
        child = joint.find("child")
        if child is not None:
            joints_by_child[child.get("link")] = joint
    movables = []
    for link, kind, label in semantics:
        joint = joints_by_child.get(link)
        if joint is None or joint.get("type") in (None, "fixed"):
            continue
        limit = joint.find("limit")
        lower = float(limit.get("lower", "-inf")) if limit is not None else -np.inf
        upper = float(limit.get("upper", "inf")) if limit is not None else np.inf
        movables.append(_Movable(link, joint.get("name", ""), joint.get("type", ""), kind, label, lower, upper))
    return movables


# --------------------------------------------------------------------------- SAPIEN side


def load_collision_articulation(urdf: Path, scale: float):
    """Load ``urdf`` into a physics-only SAPIEN scene (visuals dropped: no renderer needed),
    built with SAPIEN's own PhysX defaults whatever an env in this process has set
    (``wpbench.assets.physx_defaults``), so the load-time checks give the same answer in
    any process.

    Returns (scene, articulation); keep the scene alive while using the articulation.
    """
    import sapien

    from wpbench.assets.physx_defaults import sapien_physx_defaults

    with sapien_physx_defaults():
        scene = sapien.Scene([sapien.physx.PhysxCpuSystem()])
        loader = scene.create_urdf_loader()
        loader.scale = scale
        loader.fix_root_link = True
        articulation_builders, _actors, _cameras = loader.parse(str(urdf))
        if len(articulation_builders) != 1:
            raise PartNetLoadError(f"{urdf} holds {len(articulation_builders)} articulations, expected one.")
        for link_builder in articulation_builders[0].link_builders:
            link_builder.visual_records = []  # visual meshes need a render system we do not create
        articulation = articulation_builders[0].build(fix_root_link=True)
    articulation.set_root_pose(sapien.Pose())
    return scene, articulation


def link_pieces(link) -> list[np.ndarray]:
    """Body-frame vertices (K_i, 3) of each convex collision piece of a SAPIEN link at its current pose."""
    pieces = []
    for shape in link.get_collision_shapes():
        vertices = np.asarray(shape.get_vertices(), dtype=np.float64) * np.asarray(shape.get_scale())
        T = (link.entity_pose * shape.get_local_pose()).to_transformation_matrix()
        pieces.append(vertices @ T[:3, :3].T + T[:3, 3])
    return pieces


class _Posed:
    """Sets joint values by name on a loaded articulation and reads link geometry."""

    def __init__(self, articulation):
        self.articulation = articulation
        self.joints = [j.name for j in articulation.get_active_joints()]
        self.links = {link.name: link for link in articulation.get_links()}

    def set(self, values: dict[str, float]) -> None:
        qpos = np.array([values.get(name, 0.0) for name in self.joints], dtype=np.float32)
        self.articulation.set_qpos(qpos)

    def pieces(self, link_names) -> list[np.ndarray]:
        return [p for name in link_names for p in link_pieces(self.links[name])]

    def points(self, link_names) -> np.ndarray:
        pieces = self.pieces(link_names)
        return np.concatenate(pieces) if pieces else np.zeros((0, 3))


def _rest_value(m: _Movable) -> float:
    """Joint value used before the closed end is known: the lower limit, or 0 when unlimited."""
    return m.lower if np.isfinite(m.lower) else 0.0


def _closed_end(posed: _Posed, m: _Movable, base: dict[str, float], others: list[str]) -> tuple[float, float]:
    """(closed, open) limits of a door/drawer: closed is the end where it lies inside the rest's bounds."""
    rest = posed.points(others)
    low, high = rest.min(0), rest.max(0)
    pad = 0.02 * float(np.linalg.norm(high - low))
    fractions = []
    for value in (m.lower, m.upper):
        posed.set({**base, m.joint: value})
        pts = posed.points([m.link])
        fractions.append(float(np.mean(np.all((pts >= low - pad) & (pts <= high + pad), axis=1))))
    posed.set(base)
    # Ties (both ends inside) fall back on the dataset's convention: closed at the lower limit.
    return (m.upper, m.lower) if fractions[1] > fractions[0] + 1e-6 else (m.lower, m.upper)


def _closed_area(pts: np.ndarray) -> float:
    sides = np.sort(pts.max(0) - pts.min(0))
    return float(sides[1] * sides[2])


# --------------------------------------------------------------------------- public API


@dataclass(frozen=True)
class ObjectDescription:
    """What a folder's text files say: its movable links, its category, and the
    door/drawer links that may be the target (largest first is chosen later)."""

    movables: list[_Movable]
    candidates: list[_Movable]
    raw_category: str
    category: str


def describe_object(folder: Path, target_link: str | None = None) -> ObjectDescription:
    """Read ``folder``'s semantics.txt, mobility.urdf and meta.json (no meshes, no physics).

    Raises PartNetLoadError when the folder is not a usable object (missing files, no
    door or drawer), with a one-line message saying what to do.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise PartNetLoadError(f"{folder} is not a directory; pass a PartNet-Mobility object folder.")
    object_id = folder.name
    semantics = _read_semantics(folder)
    movables = _read_movables(folder, semantics)
    raw_category = _read_category(folder, semantics)
    candidates = [m for m in movables if m.is_door] or [m for m in movables if m.is_drawer]
    if target_link is not None:
        candidates = [m for m in movables if m.link == target_link and (m.is_door or m.is_drawer)]
        if not candidates:
            raise PartNetLoadError(
                f"{object_id}: link {target_link!r} is not a door or drawer; choose one of "
                f"{[m.link for m in movables if m.is_door or m.is_drawer]}."
            )
    if not candidates:
        raise PartNetLoadError(
            f"{object_id}: semantics.txt names no door ('hinge ...door' on a limited revolute joint) and no "
            f"drawer ('slider drawer' on a prismatic joint); movable links are "
            f"{[(m.link, m.semantic_kind, m.label) for m in movables]}. Use an object with a door or drawer."
        )
    return ObjectDescription(movables, candidates, raw_category, normalise_category(raw_category))


def load_partnet_object(
    folder: Path,
    cache_dir: Path | None = None,
    scale: dict[str, float] | float | None = None,
    target_link: str | None = None,
    config: PartNetLoadConfig = PartNetLoadConfig(),
) -> FurnitureAsset:
    """One PartNet-Mobility folder -> FurnitureAsset (see the module docstring for the rules).

    Args:
        folder: the object's folder (``<root>/<id>`` with ``mobility.urdf``, ``semantics.txt``).
        cache_dir: where the collision pieces and derived URDF go (this object's own
            directory); default :func:`default_cache_dir`.
        scale: loader scale (a float), or a dict looked up by object id then category
            (as in :func:`load_partnet_folder`); default from the category size table.
        target_link: force this door/drawer link as the target instead of the largest door.
        config: CoACD and cavity-search parameters.

    Raises:
        PartNetLoadError: the folder is incomplete or has no usable door/drawer/cavity.
    """
    folder = Path(folder)
    object_id = folder.name
    described = describe_object(folder, target_link)
    movables, candidates = described.movables, described.candidates
    raw_category, category = described.raw_category, described.category

    try:
        derived = build_hollow_collision_urdf(folder, cache_dir or default_cache_dir(object_id), config.coacd,
                                              workers=config.workers, progress=config.progress,
                                              decomposer=config.decomposer)
    except CollisionBuildError as err:
        raise PartNetLoadError(f"{object_id}: {err}") from err
    buildable = [m for m in candidates if m.link not in derived.links_without_collision]
    if not buildable:
        links = [m.link for m in candidates]
        raise PartNetLoadError(
            f"{object_id}: the door/drawer link(s) {links} have no collision geometry "
            f"({'; '.join(derived.fallbacks.get(link, 'no mesh') for link in links)}); the target part cannot be "
            "built: restore its meshes from the download or pick another object."
        )
    candidates = buildable

    # Pass 1 at scale 1: which end of each door/drawer is closed, and how big the object is.
    scene, articulation = load_collision_articulation(derived.urdf, 1.0)
    posed = _Posed(articulation)
    base = {m.joint: _rest_value(m) for m in movables}
    all_links = [name for name, link in posed.links.items() if link.get_collision_shapes()]
    if not [n for n in all_links if n not in {m.link for m in candidates}]:
        raise PartNetLoadError(
            f"{object_id}: only the door/drawer links have collision geometry, the body has none (its meshes "
            "are missing or empty), so there is no cavity; restore the body's meshes from the download."
        )
    ends = {}
    for m in movables:
        if m.is_door or m.is_drawer:
            ends[m.joint] = _closed_end(posed, m, base, [n for n in all_links if n != m.link])
    closed_values = {**base, **{joint: closed for joint, (closed, _open) in ends.items()}}
    posed.set(closed_values)
    unscaled = posed.points(all_links)
    largest_side = float(np.max(unscaled.max(0) - unscaled.min(0)))
    override = _resolve_scale_override(scale, object_id, category, raw_category)
    final_scale = override if override is not None else category_scale(category, largest_side)
    del articulation, scene

    # Pass 2 at the final scale: every number in the asset comes from this articulation.
    scene, articulation = load_collision_articulation(derived.urdf, final_scale)
    posed = _Posed(articulation)
    limits = {j.name: j.get_limits()[0] for j in articulation.get_active_joints()}
    # Prismatic limits scale with the object; revolute ones do not (SAPIEN scales them on load).
    closed_values = {
        m.joint: (closed_values[m.joint] * final_scale if m.urdf_type == "prismatic" else closed_values[m.joint])
        for m in movables
    }
    posed.set(closed_values)
    target = max(candidates, key=lambda m: (_closed_area(posed.points([m.link])), m.link))
    lower, upper = (float(v) for v in limits[target.joint])
    closed_q = lower if np.isclose(closed_values[target.joint], lower, atol=1e-5) else upper
    open_q = upper if closed_q == lower else lower
    anchor_links = [n for n in all_links if n != target.link]
    closed_points = posed.points(all_links)
    bounds_low, bounds_high = closed_points.min(0), closed_points.max(0)

    # front: the horizontal direction the target moves in when it starts to open.
    door_closed = posed.points([target.link])
    posed.set({**closed_values, target.joint: closed_q + 0.05 * (open_q - closed_q)})
    displacement = (posed.points([target.link]) - door_closed).mean(0)
    horizontal = np.array([displacement[0], displacement[1], 0.0])
    if np.linalg.norm(horizontal) < 1e-3 * np.linalg.norm(displacement) or np.linalg.norm(displacement) == 0:
        raise PartNetLoadError(
            f"{object_id}: {target.link} opens vertically (a lid?), so it has no horizontal front; "
            "pass target_link= for a door or drawer that opens sideways."
        )
    front = horizontal / np.linalg.norm(horizontal)
    if target.is_door:
        # The mean displacement leans sideways by the door's thickness; the door plane's
        # normal (least-variance direction of the closed door) is the exact outward normal.
        centered = door_closed - door_closed.mean(0)
        normal = np.linalg.eigh(centered.T @ centered)[1][:, 0]
        normal = np.array([normal[0], normal[1], 0.0])
        if np.linalg.norm(normal) > 0.5 and abs(normal @ front) / np.linalg.norm(normal) > 0.7:
            normal /= np.linalg.norm(normal)
            front = normal if normal @ front > 0 else -normal

    def find_region(pose_of):
        """The cavity behind the target of the articulation ``pose_of`` (a _Posed)."""
        if target.is_door:
            pose_of.set(closed_values)
            return door_cavity(pose_of.pieces(anchor_links), pose_of.pieces([target.link]),
                               bounds_low, bounds_high, config.cavity), "closed"
        pose_of.set({**closed_values, target.joint: open_q})
        return drawer_inner_volume(pose_of.pieces([target.link]), config.cavity), "open"

    region, region_state = find_region(posed)
    _check_region(object_id, target, region, derived, anchor_links, door_closed, front)

    reachable = open_q
    clearing = None
    if config.probe_reach:
        def cavity_survives(pieces_by_link: dict[str, list[np.ndarray]]) -> bool:
            anchor = [p for name in anchor_links for p in pieces_by_link.get(name, [])]
            found = door_cavity(anchor, [p for p in pieces_by_link.get(target.link, [])], bounds_low, bounds_high,
                                config.cavity)
            return (found is not None and min(found.half_extents) >= MIN_REGION_HALF_EXTENT_M
                    and np.prod(found.half_extents) >= CAVITY_KEEP_FRACTION * np.prod(region.half_extents))

        clearing = clear_target_path(
            derived.urdf, final_scale, closed_values, target.joint, closed_q, open_q,
            cavity_survives if target.is_door else None, load_collision_articulation, repair=config.clear_path)
        if clearing.changed:
            del articulation, scene
            scene, articulation = load_collision_articulation(clearing.urdf, final_scale)
            posed = _Posed(articulation)
            region, region_state = find_region(posed)
            _check_region(object_id, target, region, derived, anchor_links, door_closed, front)
        probe = clearing.probe
        reachable = open_q if probe.full else probe.reached - BACK_OFF * (open_q - closed_q)
        if (reachable - closed_q) / (open_q - closed_q) < config.min_reach_fraction:
            raise PartNetLoadError(
                f"{object_id}: {target.link} opens only to q={probe.reached:.3f} of its limit {open_q:.3f} in "
                f"physics, {describe_blockers(probe)} ({'pieces the cavity needs are never removed' if config.clear_path else 'clear_path is off'}); pick another target_link or "
                f"rebuild its collision (delete {derived.urdf.parent})."
            )
        if not probe.full:
            log.warning("%s: %s opens %.0f%% of its range (to q=%.3f of %.3f): %s; the goal is lowered to q=%.3f",
                        object_id, target.link, 100 * (probe.reached - closed_q) / (open_q - closed_q),
                        probe.reached, open_q, describe_blockers(probe), reachable)
    posed.set(closed_values)
    del articulation, scene
    return FurnitureAsset(
        object_id=object_id,
        category=category,
        urdf=clearing.urdf if clearing is not None else derived.urdf,
        scale=float(final_scale),
        target_link=target.link,
        target_joint=target.joint,
        joint_type="revolute" if target.is_door else "prismatic",
        closed_qpos=float(closed_q) + 0.0,  # + 0.0 turns a "-0.0" limit into 0.0
        open_qpos=float(reachable),
        in_region=region,
        bounds_low=tuple(float(v) for v in bounds_low),
        bounds_high=tuple(float(v) for v in bounds_high),
        front=tuple(float(v) + 0.0 for v in front),
        source="partnet-mobility",
        split=None,
        extra={
            "dataset_folder": str(folder.resolve()),
            "raw_category": raw_category,
            "scale_source": "override" if override is not None else "category table",
            "closed_qpos_by_joint": {k: float(v) for k, v in closed_values.items()},
            "collision_source": derived.source,
            "coacd_seconds": derived.coacd_seconds,
            "collision_fallbacks": dict(derived.fallbacks),
            "links_without_collision": list(derived.links_without_collision),
            "in_region_state": region_state,
            "open_qpos_limit": float(open_q),  # the URDF limit; open_qpos is what physics reaches
            "collision_trimmed": list(clearing.trimmed) if clearing is not None else [],
            "collision_dropped": list(clearing.dropped) if clearing is not None else [],
            "collision_restless": dict(clearing.restless) if clearing is not None else {},
            "reach_blocked_by": describe_blockers(clearing.probe) if clearing is not None and not clearing.probe.full else "",
            "target_label": target.label,
        },
    )


def describe_blockers(probe: OpeningProbe) -> str:
    """One phrase naming what holds the door at the stop, e.g. "held by link_2 piece 3 at (0.1, -0.3, 0.4)"."""
    if not probe.blockers:
        return "held by its own drive or joint friction (no contact)"
    parts = [f"{b.link} piece {b.piece} at ({', '.join(f'{v:.2f}' for v in b.position)})"
             for b in probe.blockers[:MAX_NAMED_BLOCKERS]]
    return "held by " + ", ".join(parts)


def _check_region(object_id, target, region, derived, anchor_links, door_closed, front) -> None:
    """Raise PartNetLoadError when ``region`` cannot hold an object or is not behind the door."""
    if region is None or min(region.half_extents) < MIN_REGION_HALF_EXTENT_M:
        size = None if region is None else [round(2 * h, 3) for h in region.half_extents]
        hulls = [link for link, why in derived.fallbacks.items() if link in anchor_links and why.startswith(CONVEX_HULL)]
        cause = (f"link(s) {hulls} stand in as their convex hull ({'; '.join(derived.fallbacks[h] for h in hulls)}), "
                 "which fills the cavity" if hulls else "the collision pieces may fill it")
        raise PartNetLoadError(
            f"{object_id}: found no free cavity behind {target.link} big enough for an object (size {size} m); "
            f"{cause}: delete the cache directory {derived.urdf.parent} and lower CoacdConfig.threshold, "
            "or pick another target_link."
        )
    if target.is_door:
        door_inner_face = float((door_closed @ front).min())
        if float(np.asarray(region.center) @ front) >= door_inner_face:
            raise PartNetLoadError(
                f"{object_id}: the free region found is not behind {target.link}; pass target_link= "
                "or check the object's geometry."
            )


def object_folders(root: Path) -> list[Path]:
    """The object folders under ``root`` (or ``root`` itself when it is one object), sorted by name."""
    if (root / "mobility.urdf").is_file() or (root / "semantics.txt").is_file():
        return [root]
    return sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))


def load_partnet_folder(
    root: Path,
    cache_dir: Path | None = None,
    scale_override: dict[str, float] | float | None = None,
    config: PartNetLoadConfig = PartNetLoadConfig(),
    only: set[str] | None = None,
) -> tuple[list[FurnitureAsset], dict[str, str]]:
    """Load every object folder under ``root`` (or ``root`` itself if it is one object);
    with ``only``, just the folders of those names.

    Args:
        root: a directory of PartNet-Mobility object folders, or one object folder.
        cache_dir: base cache directory; object ``<id>`` uses ``cache_dir/<id>``
            (default :func:`default_cache_dir`).
        scale_override: loader scale for every object (float), or per object id /
            category (dict; id wins over category); others use the category table.

    Returns:
        (assets that loaded, {folder name: reason} for those that could not).
    """
    root = Path(root)
    if not root.is_dir():
        raise PartNetLoadError(f"{root} is not a directory; pass the folder that holds PartNet-Mobility objects.")
    assets: list[FurnitureAsset] = []
    failures: dict[str, str] = {}
    for folder in object_folders(root):
        if only is not None and folder.name not in only:
            continue
        try:
            assets.append(
                load_partnet_object(
                    folder,
                    cache_dir=None if cache_dir is None else Path(cache_dir) / folder.name,
                    scale=scale_override,
                    config=config,
                )
            )
        except PartNetLoadError as err:
            failures[folder.name] = str(err)
        except Exception as err:  # one broken object must not stop the rest
            failures[folder.name] = (
                f"{folder.name}: unexpected {type(err).__name__}: {' '.join(str(err).split())}. Check that the "
                "folder is a complete PartNet-Mobility object (mobility.urdf, semantics.txt, meta.json, textured_objs/)."
            )
    return assets, failures

