"""Clear the target's path: collision pieces that overlap the door, or block its swing, are decomposition defects.

A convex decomposition of a real object often leaves pieces where there is no
material: a piece of the body (or of another door) that reaches into the closed
door, or that fills the gap around the hinge. Physics then holds the door back, or
drags the other door along, and even the true pose cannot open it. At load time:

1. *trim*: every piece of a link that does not move with the target and overlaps a
   piece of the target (or of a link riding on it: a handle) by more than
   :data:`OVERLAP_TOLERANCE_M` in the closed state is cut by the target piece's face
   plane that keeps most of it (``wpbench.assets.convex_overlap.trim_away``); a piece
   with nothing left is dropped. Links joined by a joint never collide in physics (the
   door and the body it hangs on), so their overlaps are left alone;
2. *settle*: everything is held closed in physics for a moment; a link outside the
   target's group that moves anyway is pushed by a neighbour it overlaps (a knob sunk
   into the body's panel spins up, and in an episode that reads as a blow-up). All its
   pieces are dropped when the cavity survives without them (a knob's collision cannot
   matter to the task); ``restless`` records them with their peak speed;
3. *probe*: the door is driven open in physics (``wpbench.assets.reach.probe_opening``);
4. *drop*: when it stops short, the pieces pressed against it at the stop are tried,
   strongest contact first: a piece is dropped only when the cavity survives without
   it (the caller's ``cavity_survives``), since a piece the cavity needs is real
   geometry (a side wall the handle meets), not a defect. Then probe again, at most
   :data:`MAX_DROPPED_PIECES` times.

The result is a new URDF beside the derived one, whose collisions are the cleared
pieces (trimmed pieces as OBJ files of their own, in the link frame), and a record of
what changed. The dataset and the derived URDF are never modified.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from wpbench.assets.collision import write_text_atomically
from wpbench.assets.convex_overlap import overlap_inradius, trim_away
from wpbench.assets.reach import OpeningProbe, probe_opening, restless_links

# Overlap (inscribed-ball radius, metres) above which two pieces interpenetrate rather than touch.
OVERLAP_TOLERANCE_M = 0.0005
# Clearance left between a trimmed piece and the target piece it was cut against (metres).
TRIM_GAP_M = 0.001
# Most blocking pieces dropped before the door counts as blocked by real geometry.
MAX_DROPPED_PIECES = 4
# Most times the object is settled at rest (each round drops the parts that still moved).
SETTLE_ROUNDS = 4
CLEARED_URDF_TAG = "cleared"


@dataclass(frozen=True)
class PathClearing:
    """What :func:`clear_target_path` did.

    urdf: the URDF to use (the input one when nothing changed).
    trimmed / dropped: "link#piece" names of pieces cut back or removed (piece =
        index among the link's collision pieces in the input URDF).
    restless: {link: peak joint speed at rest} of the links whose pieces were dropped
        because they moved while held still.
    probe: the last opening probe (on ``urdf``).
    """

    urdf: Path
    probe: OpeningProbe
    trimmed: list[str] = field(default_factory=list)
    dropped: list[str] = field(default_factory=list)
    restless: dict[str, float] = field(default_factory=dict)

    @property
    def changed(self) -> bool:
        return bool(self.trimmed or self.dropped)


def moving_group(articulation, target_link: str) -> set[str]:
    """The target link and every link below it in the tree (they ride on the door)."""
    children: dict[str, list[str]] = {}
    for joint in articulation.get_joints():
        if joint.parent_link is not None:
            children.setdefault(joint.parent_link.name, []).append(joint.child_link.name)
    group, todo = set(), [target_link]
    while todo:
        name = todo.pop()
        group.add(name)
        todo += children.get(name, [])
    return group


def _aabb_overlap(a: np.ndarray, b: np.ndarray, pad: float) -> bool:
    return bool(np.all(a.min(0) <= b.max(0) + pad) and np.all(b.min(0) <= a.max(0) + pad))


def jointed_pairs(articulation) -> set[frozenset[str]]:
    """Links joined by a joint: physics never lets such a pair collide (a door and its body)."""
    return {frozenset((j.parent_link.name, j.child_link.name)) for j in articulation.get_joints()
            if j.parent_link is not None}


def trim_overlaps(pieces: dict[str, list[np.ndarray | None]], moving: set[str],
                  never_collide: set[frozenset[str]] = frozenset(),
                  tolerance: float = OVERLAP_TOLERANCE_M, gap: float = TRIM_GAP_M) -> list[str]:
    """Cut, in place, every piece of a link outside ``moving`` that overlaps a piece of a link in it.

    pieces: {link: [body-frame vertices (K, 3), or None for a dropped piece]}. A piece cut
    to nothing becomes None. never_collide: link pairs physics ignores (left as they are).
    Returns the "link#piece" names changed.
    """
    obstacles = [(name, p) for name in moving for p in pieces.get(name, []) if p is not None]
    changed = []
    for name, link_pieces in pieces.items():
        if name in moving:
            continue
        for i, piece in enumerate(link_pieces):
            touched = False
            for obstacle_link, obstacle in obstacles:
                if piece is None:
                    break
                if frozenset((name, obstacle_link)) in never_collide:
                    continue
                if _aabb_overlap(piece, obstacle, 0.0) and overlap_inradius(piece, obstacle) > tolerance:
                    piece = trim_away(piece, obstacle, gap)
                    touched = True
            if touched:
                link_pieces[i] = piece
                changed.append(f"{name}#{i}")
    return changed


def write_cleared_urdf(urdf: Path, pieces: dict[str, list[np.ndarray | None]], changed: set[str],
                       link_frames: dict[str, tuple[np.ndarray, float]]) -> Path:
    """A copy of ``urdf`` whose changed pieces are replaced (trimmed: a new OBJ, dropped: removed).

    link_frames: {link: (4x4 body-from-piece transform, scale)} to bring body-frame
    vertices back into the piece files' frame. The file is named after its content, so
    the same clearing of the same URDF gives the same path. Safe when several processes
    (a run's workers) clear the same object at once: every file is written under a name of
    its own and renamed into place, piece files before the URDF that names them, so a
    reader never sees a half-written file and concurrent writers leave identical files.
    """
    tree = ET.parse(urdf)
    digest = hashlib.sha256(urdf.read_bytes())
    for key in sorted(changed):
        link, index = key.split("#")
        vertices = pieces[link][int(index)]
        digest.update(key.encode() + (b"none" if vertices is None else np.round(vertices, 7).tobytes()))
    tag = digest.hexdigest()[:12]
    folder = urdf.parent / f"{CLEARED_URDF_TAG}-{tag}"
    out = urdf.parent / f"{urdf.stem}-{CLEARED_URDF_TAG}-{tag}.urdf"
    if out.is_file():
        return out
    for link_el in tree.getroot().findall("link"):
        name = link_el.get("name", "")
        collisions = link_el.findall("collision")
        for i in sorted((int(k.split("#")[1]) for k in changed if k.split("#")[0] == name), reverse=True):
            vertices = pieces[name][i]
            if vertices is None:
                link_el.remove(collisions[i])
                continue
            T, scale = link_frames[name]
            local = (vertices - T[:3, 3]) @ T[:3, :3] / scale
            piece_file = folder / f"{name}-{i:03d}.obj"
            write_text_atomically(piece_file, trimesh.convex.convex_hull(local).export(file_type="obj"))
            collisions[i].find("geometry/mesh").set("filename", str(piece_file.resolve()))
    ET.indent(tree)
    write_text_atomically(out, ET.tostring(tree.getroot(), encoding="unicode"))
    return out


def clear_target_path(
    urdf: Path,
    scale: float,
    closed_values: dict[str, float],
    target_joint: str,
    closed_q: float,
    open_q: float,
    cavity_survives: Callable[[dict[str, list[np.ndarray]]], bool] | None,
    load: Callable[[Path, float], tuple[object, object]],
    repair: bool = True,
) -> PathClearing:
    """Trim overlaps, probe the opening, drop blockers the cavity can spare; see the module docstring.

    closed_values: every movable joint's closed value (the target's is ``closed_q``).
    cavity_survives: given {link: body-frame pieces (K, 3)} of the closed object, whether
        its cavity is still there; None never drops a piece (only trims).
    load: (urdf, scale) -> (scene, articulation), e.g. ``partnet.load_collision_articulation``.
    repair: False only probes (the check without the fix).
    """
    from wpbench.assets.partnet import link_pieces

    scene, articulation = load(urdf, scale)
    links = {link.name: link for link in articulation.get_links()}
    joint_names = [j.name for j in articulation.get_active_joints()]
    target = next(j for j in articulation.get_active_joints() if j.name == target_joint).child_link.name
    moving = moving_group(articulation, target)
    closed = {**closed_values, target_joint: closed_q}
    articulation.set_qpos(np.array([closed.get(n, 0.0) for n in joint_names], dtype=np.float32))
    pieces: dict[str, list[np.ndarray | None]] = {name: list(link_pieces(link)) for name, link in links.items()}
    frames = {}
    for name, link in links.items():
        shapes = link.get_collision_shapes()
        if shapes:
            pose = (link.entity_pose * shapes[0].get_local_pose()).to_transformation_matrix()
            frames[name] = (pose, float(np.asarray(shapes[0].get_scale())[0]))
    trimmed = trim_overlaps(pieces, moving, jointed_pairs(articulation)) if repair else []
    dropped: list[str] = []
    current = urdf
    restless: dict[str, float] = {}
    for _ in range(SETTLE_ROUNDS if repair else 0):
        # A part freed of its neighbour may let the next one move: settle again until all is still.
        if trimmed or dropped:
            current = write_cleared_urdf(urdf, pieces, set(trimmed) | set(dropped), frames)
        scene, articulation = load(current, scale)
        found = False
        for link, speed in sorted(restless_links(articulation, closed, moving).items()):
            alive = [i for i, p in enumerate(pieces.get(link, [])) if p is not None]
            trial = {name: [p for p in ps if p is not None] for name, ps in pieces.items() if name != link}
            if alive and (cavity_survives is None or cavity_survives(trial)):
                for i in alive:
                    pieces[link][i] = None
                    dropped.append(f"{link}#{i}")
                restless[link] = round(speed, 2)
                found = True
        if not found:
            break
    settled = len(dropped)   # pieces of restless links; the probe's drops count from here
    while True:
        changed = set(trimmed) | set(dropped)
        if changed:
            current = write_cleared_urdf(urdf, pieces, changed, frames)
        scene, articulation = load(current, scale)
        probe = probe_opening(articulation, target_joint, closed, closed_q, open_q, moving_links=moving)
        if probe.full or not repair or cavity_survives is None or len(dropped) - settled >= MAX_DROPPED_PIECES:
            break
        spared = None
        for blocker in probe.blockers:
            # Piece indices of the probe refer to the current URDF: map back to the input's numbering.
            alive = [i for i, p in enumerate(pieces.get(blocker.link, [])) if p is not None]
            if blocker.link in moving or not 0 <= blocker.piece < len(alive):
                continue
            index = alive[blocker.piece]
            trial = {name: [p for j, p in enumerate(ps) if p is not None and not (name == blocker.link and j == index)]
                     for name, ps in pieces.items()}
            if cavity_survives(trial):
                spared = (blocker.link, index)
                break
        if spared is None:
            break
        pieces[spared[0]][spared[1]] = None
        dropped.append(f"{spared[0]}#{spared[1]}")
    del scene, articulation
    return PathClearing(current, probe, trimmed, dropped, restless)
