"""Hollow collision geometry for PartNet-Mobility objects, computed once and cached.

SAPIEN turns each ``<collision>`` mesh of a URDF into *one* convex hull unless
the loader's ``load_multiple_collisions_from_file`` flag is set; the hull of an
oven body fills its cavity, so nothing could ever be put inside. This module
writes a *derived URDF* in which every ``<collision>`` element is a single
convex piece stored in its own OBJ file, so the cavity stays hollow whatever
flag the caller's loader uses. The pieces come from

* the dataset's own convex decomposition (``mobility_cvx.urdf`` and its
  ``cvx_objs/<link>.obj`` files, one ``o`` group per piece) when present, or
* CoACD run once per link on the link's collision meshes otherwise, each link in
  a worker process of its own, several at once (``wpbench.assets.decompose``).

A link whose decomposition gives nothing usable (a flat handle) or crashes gets a
fallback (``wpbench.assets.collision_fallback``: its convex hull, a thin box, or no
collision); :attr:`DerivedCollision.fallbacks` says which links and why.

Visual meshes stay where they are: the derived URDF points at them by
absolute path, so the (read-only) dataset folder is never modified or copied.

Cache layout (``cache_dir``, outside the dataset)::

    cache_dir/
        pieces/<link>-<fingerprint>/piece_000.obj ...   # one directory per link
        pieces/<link>-<fingerprint>/timing.json          # seconds, source, fallback of that link
        mobility_wpbench-<fingerprint>.urdf              # the derived URDF

Every directory and file is written to a temporary name and renamed into
place, so an interrupted run leaves no half-written entry and two processes
preparing the same object at once end with one complete entry; the fingerprint
(hash of the source meshes, transforms and CoACD parameters) makes a changed
source or parameter set produce a fresh entry instead of reusing a stale one.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from wpbench.assets.collision_fallback import fallback_pieces
from wpbench.assets.decompose import (
    CoacdConfig,
    LinkJob,
    convex_pieces_from_vertices,
    entry_is_complete,
    entry_piece_files,
    read_entry,
    run_jobs,
    save_mesh,
    write_entry,
)

DERIVED_URDF_PREFIX = "mobility_wpbench"

__all__ = ["CoacdConfig", "CollisionBuildError", "CollisionPlan", "DerivedCollision", "build_hollow_collision_urdf",
           "plan_collision", "finish_collision"]


class CollisionBuildError(ValueError):
    """The collision geometry of an object could not be built (bad mesh, bad URDF)."""


@dataclass(frozen=True)
class DerivedCollision:
    """Result of :func:`build_hollow_collision_urdf`.

    urdf: derived URDF (absolute visual paths, one convex piece per collision).
    source: "dataset-cvx" (mobility_cvx.urdf pieces) or "coacd".
    coacd_seconds: decomposition time per link measured when the pieces were first
        computed (read back from the cache on later calls); empty for "dataset-cvx".
    computed_now: links whose pieces were computed in this call (cache misses).
    fallbacks: {link: "thin box: <why>"} for links that got a fallback instead of
        decomposed pieces (see ``wpbench.assets.collision_fallback``).
    links_without_collision: links left with no collision piece at all.
    """

    urdf: Path
    source: str
    coacd_seconds: dict[str, float]
    computed_now: tuple[str, ...]
    fallbacks: dict[str, str] = field(default_factory=dict)
    links_without_collision: tuple[str, ...] = ()


# --------------------------------------------------------------------------- URDF helpers


def parse_urdf(path: Path) -> ET.ElementTree:
    """Parse a URDF, turning XML errors into a :class:`CollisionBuildError` that says what to do."""
    try:
        return ET.parse(path)
    except ET.ParseError as err:
        raise CollisionBuildError(
            f"{path} is not valid XML ({err}); restore the file from the PartNet-Mobility download."
        ) from err
    except OSError as err:
        raise CollisionBuildError(f"cannot read {path} ({err}); check that the file exists and is readable.") from err


def origin_matrix(element: ET.Element | None) -> np.ndarray:
    """(4, 4) transform of a URDF ``<origin xyz rpy>`` element (identity when absent).

    URDF rpy is fixed-axis roll (x), pitch (y), yaw (z): R = Rz(yaw) Ry(pitch) Rx(roll).
    """
    T = np.eye(4)
    if element is None:
        return T
    xyz = [float(v) for v in element.get("xyz", "0 0 0").split()]
    roll, pitch, yaw = [float(v) for v in element.get("rpy", "0 0 0").split()]
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    T[:3, :3] = Rz @ Ry @ Rx
    T[:3, 3] = xyz
    return T


def _mesh_scale(mesh_el: ET.Element) -> np.ndarray:
    return np.array([float(v) for v in mesh_el.get("scale", "1 1 1").split()])


def load_obj_mesh(path: Path) -> trimesh.Trimesh:
    """Load an OBJ (all groups merged, materials ignored) as one triangle mesh."""
    if not path.is_file():
        raise CollisionBuildError(f"mesh {path} is missing; restore it from the PartNet-Mobility download.")
    try:
        loaded = trimesh.load(path, force="mesh", process=False, skip_materials=True)
    except Exception as err:  # trimesh raises many types for broken files
        raise CollisionBuildError(f"mesh {path} cannot be read ({err}); restore it from the download.") from err
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise CollisionBuildError(f"mesh {path} has no triangles; restore it from the download.")
    return loaded


def link_collision_mesh(link: ET.Element, urdf_dir: Path) -> trimesh.Trimesh | None:
    """All ``<collision>`` meshes of a link, in the link frame, merged into one mesh (None if none)."""
    parts = []
    for collision in link.findall("collision"):
        mesh_el = collision.find("geometry/mesh")
        if mesh_el is None:
            continue
        mesh = load_obj_mesh(urdf_dir / mesh_el.get("filename", ""))
        mesh = mesh.copy()
        mesh.apply_scale(_mesh_scale(mesh_el))
        mesh.apply_transform(origin_matrix(collision.find("origin")))
        parts.append(mesh)
    if not parts:
        return None
    return trimesh.util.concatenate(parts)


def split_obj_groups(path: Path) -> list[np.ndarray]:
    """Vertices (K_i, 3) of every ``o``/``g`` group of an OBJ file (convex pieces of a decomposition).

    OBJ face indices are global across groups, so vertices are collected per
    group from the faces that the group owns.
    """
    if not path.is_file():
        raise CollisionBuildError(f"convex mesh {path} is missing; restore it from the download.")
    vertices: list[list[float]] = []
    groups: list[set[int]] = [set()]
    for line in path.read_text(errors="replace").splitlines():
        if line.startswith("v "):
            vertices.append([float(v) for v in line.split()[1:4]])
        elif line.startswith(("o ", "g ")):
            if groups[-1]:
                groups.append(set())
        elif line.startswith("f "):
            for token in line.split()[1:]:
                index = int(token.split("/")[0])
                groups[-1].add(index - 1 if index > 0 else len(vertices) + index)
    all_vertices = np.asarray(vertices, dtype=np.float64)
    return [all_vertices[sorted(g)] for g in groups if len(g) >= 4]


# --------------------------------------------------------------------------- cache helpers


def _fingerprint(*chunks: bytes) -> str:
    h = hashlib.sha256()
    for chunk in chunks:
        h.update(hashlib.sha256(chunk).digest())
    return h.hexdigest()[:12]


def write_text_atomically(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file of this process's own in the same
    directory and a rename, so a reader (another worker) never sees a half-written file and
    processes writing the same file at once do not collide."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


# --------------------------------------------------------------------------- visual meshes


def _visual_with_existing_textures(obj_path: Path, cache_dir: Path) -> Path:
    """``obj_path`` itself, or a cached copy whose .mtl drops texture maps that do not exist."""
    if obj_path.suffix.lower() != ".obj" or not obj_path.is_file():
        return obj_path
    mtl_names = [line.split(None, 1)[1].strip() for line in obj_path.read_text(errors="replace").splitlines()
                 if line.startswith("mtllib ") and len(line.split(None, 1)) == 2]
    broken = False
    cleaned: dict[str, str] = {}
    for name in mtl_names:
        mtl = obj_path.parent / name
        if not mtl.is_file():
            continue
        lines = []
        for line in mtl.read_text(errors="replace").splitlines():
            if line.strip().startswith("map_") and not (mtl.parent / line.split()[-1]).is_file():
                broken = True
                continue
            lines.append(line)
        cleaned[name] = "\n".join(lines) + "\n"
    if not broken:
        return obj_path
    key = _fingerprint(str(obj_path).encode(), obj_path.read_bytes(), *(t.encode() for t in cleaned.values()))
    target = cache_dir / key / obj_path.name
    if not target.is_file():
        for name, text in cleaned.items():
            write_text_atomically(target.parent / name, text)
        write_text_atomically(target, obj_path.read_text(errors="replace"))
    return target


def _visual_paths_into(root: ET.Element, source_dir: Path, cache_dir: Path) -> None:
    """Visual meshes: absolute paths into the dataset folder, which stays untouched; a mesh
    whose material names a texture image the folder lacks gets a cached copy without it
    (the renderer aborts on a missing texture file)."""
    for mesh_el in root.iter("mesh"):
        filename = mesh_el.get("filename", "")
        if not Path(filename).is_absolute():
            path = (source_dir / filename).resolve()
            mesh_el.set("filename", str(_visual_with_existing_textures(path, cache_dir / "visuals")))


@dataclass
class CollisionPlan:
    """What building one object's derived URDF needs: its source tree, the cache entry
    of each link with collisions, and the decompositions still to run (``jobs``).

    Made by :func:`plan_collision`; run the jobs (``wpbench.assets.decompose.run_jobs``,
    possibly together with other objects' jobs), then :func:`finish_collision`.
    """

    folder: Path
    cache_dir: Path
    source_urdf: Path
    tree: ET.ElementTree
    use_dataset_cvx: bool
    config: CoacdConfig
    entries: dict[str, Path]  # link name -> cache entry
    jobs: list[LinkJob]
    computed_now: list[str]
    scratch: Path | None = None  # holds the jobs' mesh files until finish_collision

    def cleanup(self) -> None:
        if self.scratch is not None:
            shutil.rmtree(self.scratch, ignore_errors=True)
            self.scratch = None


def plan_collision(folder: Path, cache_dir: Path, coacd_config: CoacdConfig | None = None,
                   decomposer: str | None = None) -> CollisionPlan:
    """Read ``folder``'s URDF, find each link's cache entry, and list the decompositions
    missing from the cache (the dataset's own convex pieces are written at once).

    ``decomposer``: "module:function" run by the workers instead of CoACD.
    Raises CollisionBuildError with a message saying what to fix when the URDF or a mesh
    is unreadable.
    """
    folder = Path(folder).resolve()
    cache_dir = Path(cache_dir)
    config = coacd_config or CoacdConfig()
    cvx_urdf = folder / "mobility_cvx.urdf"
    use_dataset_cvx = cvx_urdf.is_file()
    source_urdf = cvx_urdf if use_dataset_cvx else folder / "mobility.urdf"
    tree = parse_urdf(source_urdf)
    root = tree.getroot()
    if root.tag != "robot":
        raise CollisionBuildError(f"{source_urdf} has root <{root.tag}>, expected <robot>; restore the file.")
    plan = CollisionPlan(folder=folder, cache_dir=cache_dir, source_urdf=source_urdf, tree=tree,
                         use_dataset_cvx=use_dataset_cvx, config=config, entries={}, jobs=[], computed_now=[])
    try:
        for link in root.findall("link"):
            name = link.get("name", "")
            collisions = [c for c in link.findall("collision") if c.find("geometry/mesh") is not None]
            if not link.findall("collision"):
                continue
            if use_dataset_cvx:
                files = [source_urdf.parent / c.find("geometry/mesh").get("filename", "") for c in collisions]
                origins = [origin_matrix(c.find("origin")) for c in collisions]
                key = _fingerprint(*(f.read_bytes() if f.is_file() else b"missing" for f in files),
                                   *(o.tobytes() for o in origins))
            else:
                files = [folder / c.find("geometry/mesh").get("filename", "") for c in collisions]
                key = _fingerprint(
                    ET.tostring(link), *(f.read_bytes() if f.is_file() else b"missing" for f in files),
                    json.dumps(asdict(config)).encode(),
                )
            entry = cache_dir / "pieces" / f"{name}-{key}"
            plan.entries[name] = entry
            if entry_is_complete(entry):
                continue
            plan.computed_now.append(name)
            if use_dataset_cvx:
                _write_dataset_cvx_entry(entry, name, files, origins, config)
                continue
            mesh = link_collision_mesh(link, folder)
            if mesh is None:
                write_entry(entry, [], {"link": name, "seconds": 0.0, "source": "fallback",
                                        "fallback": "no collision", "reason": "the link names no collision mesh",
                                        "coacd": asdict(config)})
                continue
            if plan.scratch is None:
                cache_dir.mkdir(parents=True, exist_ok=True)
                plan.scratch = Path(tempfile.mkdtemp(dir=cache_dir, prefix=".meshes-"))
            mesh_file = plan.scratch / f"{len(plan.jobs):03d}.npz"
            save_mesh(mesh, mesh_file)
            job = LinkJob(label=f"{folder.name}/{name}", link=name, mesh_file=mesh_file, entry=entry, config=config)
            if decomposer is not None:
                job = LinkJob(**{**job.__dict__, "decomposer": decomposer})
            plan.jobs.append(job)
    except BaseException:
        plan.cleanup()
        raise
    return plan


def _write_dataset_cvx_entry(entry: Path, name: str, files: list[Path], origins: list[np.ndarray],
                             config: CoacdConfig) -> None:
    pieces: list[trimesh.Trimesh] = []
    all_vertices = []
    for f, origin in zip(files, origins):
        groups = split_obj_groups(f)
        all_vertices += [g @ origin[:3, :3].T + origin[:3, 3] for g in groups]
        for piece in convex_pieces_from_vertices(groups):
            piece.apply_transform(origin)
            pieces.append(piece)
    info = {"link": name, "seconds": 0.0, "source": "dataset-cvx", "coacd": asdict(config)}
    if not pieces:
        vertices = np.concatenate(all_vertices) if all_vertices else np.zeros((0, 3))
        pieces, kind = fallback_pieces(vertices)
        info.update(source="fallback", fallback=kind, reason="the dataset's convex pieces have no volume")
    write_entry(entry, pieces, info)


def finish_collision(plan: CollisionPlan) -> DerivedCollision:
    """Write (or reuse) the derived URDF once every link of ``plan`` has its cache entry."""
    plan.cleanup()
    root = plan.tree.getroot()
    coacd_seconds: dict[str, float] = {}
    fallbacks: dict[str, str] = {}
    without: list[str] = []
    fingerprints: list[bytes] = [plan.source_urdf.read_bytes(), json.dumps(asdict(plan.config)).encode()]
    for link in root.findall("link"):
        name = link.get("name", "")
        if name not in plan.entries:
            continue
        entry = plan.entries[name]
        if not entry_is_complete(entry):
            raise CollisionBuildError(f"link {name!r} of {plan.folder} has no collision pieces yet; "
                                      "run its decomposition first (wpbench assets prepare).")
        info = read_entry(entry)
        if not plan.use_dataset_cvx:
            coacd_seconds[name] = float(info["seconds"])
        if info.get("source") == "fallback":
            fallbacks[name] = f"{info['fallback']}: {info['reason']}"
        fingerprints.append(entry.name.encode())
        # Replace the link's collisions by one element per convex piece (pieces are in the link frame).
        for c in link.findall("collision"):
            link.remove(c)
        files = entry_piece_files(entry)
        if not files:
            without.append(name)
        for piece_file in files:
            collision = ET.SubElement(link, "collision")
            ET.SubElement(ET.SubElement(collision, "geometry"), "mesh", filename=str(piece_file.resolve()))
    _visual_paths_into(root, plan.source_urdf.parent, plan.cache_dir)
    ET.indent(plan.tree)
    text = ET.tostring(root, encoding="unicode")
    urdf_path = plan.cache_dir / f"{DERIVED_URDF_PREFIX}-{_fingerprint(*fingerprints)}.urdf"
    if not urdf_path.is_file() or urdf_path.read_text() != text:
        write_text_atomically(urdf_path, text)
    return DerivedCollision(
        urdf=urdf_path,
        source="dataset-cvx" if plan.use_dataset_cvx else "coacd",
        coacd_seconds=coacd_seconds,
        computed_now=tuple(plan.computed_now),
        fallbacks=fallbacks,
        links_without_collision=tuple(without),
    )


def build_hollow_collision_urdf(
    folder: Path, cache_dir: Path, coacd_config: CoacdConfig | None = None, workers: int | None = None,
    progress: bool = False, decomposer: str | None = None,
) -> DerivedCollision:
    """Write (or reuse) the derived URDF of a PartNet-Mobility folder; see the module docstring.

    Missing decompositions run in up to ``workers`` worker processes (default: one per
    core), with a progress bar naming the links when ``progress``.
    Raises CollisionBuildError with a message saying what to fix when the URDF
    or a mesh is unreadable.
    """
    plan = plan_collision(folder, cache_dir, coacd_config, decomposer=decomposer)
    try:
        run_jobs(plan.jobs, workers=workers, progress=progress, desc=f"decomposing {Path(folder).name}")
    finally:
        plan.cleanup()
    return finish_collision(plan)
