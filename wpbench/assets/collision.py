"""Hollow collision geometry for PartNet-Mobility objects, computed once and cached.

SAPIEN turns each ``<collision>`` mesh of a URDF into *one* convex hull unless
the loader's ``load_multiple_collisions_from_file`` flag is set; the hull of an
oven body fills its cavity, so nothing could ever be put inside. This module
writes a *derived URDF* in which every ``<collision>`` element is a single
convex piece stored in its own OBJ file, so the cavity stays hollow whatever
flag the caller's loader uses. The pieces come from

* the dataset's own convex decomposition (``mobility_cvx.urdf`` and its
  ``cvx_objs/<link>.obj`` files, one ``o`` group per piece) when present, or
* CoACD run once per link on the link's collision meshes otherwise.

Visual meshes stay where they are: the derived URDF points at them by
absolute path, so the (read-only) dataset folder is never modified or copied.

Cache layout (``cache_dir``, outside the dataset)::

    cache_dir/
        pieces/<link>-<fingerprint>/piece_000.obj ...   # one directory per link
        pieces/<link>-<fingerprint>/timing.json          # CoACD seconds for that link
        mobility_wpbench-<fingerprint>.urdf              # the derived URDF

Every directory and file is written to a temporary name and renamed into
place, so an interrupted run leaves no half-written entry; the fingerprint
(hash of the source meshes, transforms and CoACD parameters) makes a changed
source or parameter set produce a fresh entry instead of reusing a stale one.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import trimesh

DERIVED_URDF_PREFIX = "mobility_wpbench"


class CollisionBuildError(ValueError):
    """The collision geometry of an object could not be built (bad mesh, bad URDF)."""


@dataclass(frozen=True)
class CoacdConfig:
    """CoACD parameters. Modest on purpose: a 2-core machine takes 35-60 s per body.

    threshold: concavity tolerance (fraction of the mesh size); 0.05-0.1 keeps
        thin walls as separate pieces while keeping the piece count low.
    max_convex_hull: cap on pieces per link (-1 = no cap).
    preprocess_resolution: voxel resolution of the manifold pre-pass.
    mcts_iterations / mcts_nodes: search effort per cut.
    seed: CoACD's random seed, for reproducible pieces.
    """

    threshold: float = 0.08
    max_convex_hull: int = 48
    preprocess_resolution: int = 50
    mcts_iterations: int = 100
    mcts_nodes: int = 15
    seed: int = 0


@dataclass(frozen=True)
class DerivedCollision:
    """Result of :func:`build_hollow_collision_urdf`.

    urdf: derived URDF (absolute visual paths, one convex piece per collision).
    source: "dataset-cvx" (mobility_cvx.urdf pieces) or "coacd".
    coacd_seconds: CoACD time per link measured when the pieces were first
        computed (read back from the cache on later calls); empty for "dataset-cvx".
    computed_now: links whose pieces were computed in this call (cache misses).
    """

    urdf: Path
    source: str
    coacd_seconds: dict[str, float]
    computed_now: tuple[str, ...]


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


def _write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file in the same directory and a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(tmp, path)


def _write_pieces_atomic(target_dir: Path, pieces: list[trimesh.Trimesh], info: dict) -> None:
    """Write convex pieces (and an info JSON) into ``target_dir`` all at once via a temporary directory."""
    target_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp_dir = Path(tempfile.mkdtemp(dir=target_dir.parent, prefix=f".{target_dir.name}.", suffix=".tmp"))
    try:
        for i, piece in enumerate(pieces):
            piece.export(tmp_dir / f"piece_{i:03d}.obj")
        (tmp_dir / "timing.json").write_text(json.dumps(info, indent=2) + "\n")
        try:
            os.rename(tmp_dir, target_dir)
        except OSError:
            # Another process finished the same entry first; its result is equivalent.
            if not (target_dir / "timing.json").is_file():
                raise
            shutil.rmtree(tmp_dir, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp_dir, ignore_errors=True)
        raise


def _piece_files(piece_dir: Path) -> list[Path]:
    return sorted(piece_dir.glob("piece_*.obj"))


def _convex_pieces_from_vertices(groups: list[np.ndarray]) -> list[trimesh.Trimesh]:
    pieces = []
    for vertices in groups:
        try:
            hull = trimesh.convex.convex_hull(vertices)
        except Exception:  # degenerate (flat) group: PhysX cannot use it either
            continue
        if hull.volume > 1e-12:
            pieces.append(hull)
    return pieces


def run_coacd(mesh: trimesh.Trimesh, config: CoacdConfig) -> list[trimesh.Trimesh]:
    """Convex pieces of ``mesh`` from CoACD (each piece a convex hull, link frame)."""
    import coacd  # heavy import; only needed on a cache miss

    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)),
        threshold=config.threshold,
        max_convex_hull=config.max_convex_hull,
        preprocess_resolution=config.preprocess_resolution,
        mcts_iterations=config.mcts_iterations,
        mcts_nodes=config.mcts_nodes,
        seed=config.seed,
    )
    return _convex_pieces_from_vertices([np.asarray(v) for v, _f in parts])


# --------------------------------------------------------------------------- main entry point


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
            _write_atomic(target.parent / name, text)
        _write_atomic(target, obj_path.read_text(errors="replace"))
    return target


def build_hollow_collision_urdf(
    folder: Path, cache_dir: Path, coacd_config: CoacdConfig | None = None
) -> DerivedCollision:
    """Write (or reuse) the derived URDF of a PartNet-Mobility folder; see the module docstring.

    Raises CollisionBuildError with a message saying what to fix when the URDF
    or a mesh is unreadable.
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
    # Collision meshes of the plain URDF feed CoACD; in the cvx case they are the cvx_objs files.
    coacd_seconds: dict[str, float] = {}
    computed_now: list[str] = []
    fingerprints: list[bytes] = [source_urdf.read_bytes(), json.dumps(asdict(config)).encode()]

    for link in root.findall("link"):
        name = link.get("name", "")
        collisions = link.findall("collision")
        if not collisions:
            continue
        if use_dataset_cvx:
            files = [source_urdf.parent / c.find("geometry/mesh").get("filename", "") for c in collisions
                     if c.find("geometry/mesh") is not None]
            origins = [origin_matrix(c.find("origin")) for c in collisions if c.find("geometry/mesh") is not None]
            key = _fingerprint(*(f.read_bytes() if f.is_file() else b"missing" for f in files),
                               *(o.tobytes() for o in origins))
        else:
            files = [folder / c.find("geometry/mesh").get("filename", "") for c in collisions
                     if c.find("geometry/mesh") is not None]
            key = _fingerprint(
                ET.tostring(link), *(f.read_bytes() if f.is_file() else b"missing" for f in files),
                json.dumps(asdict(config)).encode(),
            )
        piece_dir = cache_dir / "pieces" / f"{name}-{key}"
        if not (piece_dir / "timing.json").is_file():
            start = time.perf_counter()
            if use_dataset_cvx:
                pieces: list[trimesh.Trimesh] = []
                for f, origin in zip(files, origins):
                    for piece in _convex_pieces_from_vertices(split_obj_groups(f)):
                        piece.apply_transform(origin)
                        pieces.append(piece)
            else:
                mesh = link_collision_mesh(link, folder)
                pieces = run_coacd(mesh, config) if mesh is not None else []
            seconds = time.perf_counter() - start
            if not pieces:
                raise CollisionBuildError(
                    f"no usable convex piece for link {name!r} of {folder}; its collision meshes are degenerate."
                )
            _write_pieces_atomic(piece_dir, pieces, {"link": name, "seconds": seconds,
                                                     "source": "dataset-cvx" if use_dataset_cvx else "coacd",
                                                     "coacd": asdict(config), "pieces": len(pieces)})
            computed_now.append(name)
        info = json.loads((piece_dir / "timing.json").read_text())
        if not use_dataset_cvx:
            coacd_seconds[name] = float(info["seconds"])
        fingerprints.append(piece_dir.name.encode())
        # Replace the link's collisions by one element per convex piece (pieces are in the link frame).
        for c in collisions:
            link.remove(c)
        for piece_file in _piece_files(piece_dir):
            collision = ET.SubElement(link, "collision")
            ET.SubElement(ET.SubElement(collision, "geometry"), "mesh", filename=str(piece_file.resolve()))

    # Visual meshes: absolute paths into the dataset folder, which stays untouched; a mesh
    # whose material names a texture image the folder lacks gets a cached copy without it
    # (the renderer aborts on a missing texture file).
    for mesh_el in root.iter("mesh"):
        filename = mesh_el.get("filename", "")
        if not Path(filename).is_absolute():
            path = (source_urdf.parent / filename).resolve()
            mesh_el.set("filename", str(_visual_with_existing_textures(path, cache_dir / "visuals")))

    ET.indent(tree)
    text = ET.tostring(root, encoding="unicode")
    urdf_path = cache_dir / f"{DERIVED_URDF_PREFIX}-{_fingerprint(*fingerprints)}.urdf"
    if not urdf_path.is_file() or urdf_path.read_text() != text:
        _write_atomic(urdf_path, text)
    return DerivedCollision(
        urdf=urdf_path,
        source="dataset-cvx" if use_dataset_cvx else "coacd",
        coacd_seconds=coacd_seconds,
        computed_now=tuple(computed_now),
    )
