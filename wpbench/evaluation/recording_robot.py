"""The robot of a ``gripper`` or ``panda`` run as a recording draws it.

``robot_of(env)`` finds the robot the env built for its executor (``env.gripper``, a
wpbench.sim.gripper.FloatingGripper, or ``env.arm``, a wpbench.sim.panda_arm.PandaArm)
and returns a :class:`RobotView`: its links, each link's visual mesh in the link frame,
its TCP pose and whether it waits at its parking place far from the scene. An ``ideal``
env has neither: ``robot_of`` returns None.

Visual meshes come from the robot's URDF (``<visual>`` elements: mesh files loaded with
trimesh, boxes, cylinders, spheres), coloured by their materials; a link whose visuals
cannot be read falls back to its collision shapes (wpbench.sim.collision_mesh).
"""

from __future__ import annotations

import functools
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

PARKED_DISTANCE = 1.0          # m: a robot root this close to its parking place is parked
DEFAULT_RGBA = (200, 200, 200, 255)


@dataclass
class RobotView:
    """One robot of an env: ``links`` (SAPIEN articulation links) and, in the same order,
    ``names`` (their URDF link names) and ``meshes`` (link-frame meshes with vertex
    colours, None for a link with nothing to draw)."""

    kind: str                                   # the executor: "gripper" or "panda"
    links: list
    names: list[str]
    meshes: list[trimesh.Trimesh | None]
    tcp: Callable[[], np.ndarray]               # () -> (4, 4) world pose of the tool centre point
    park_position: np.ndarray                   # (3,) where the robot's root waits between stages

    def parked(self) -> bool:
        """The robot waits at its parking place (it takes no part in the scene)."""
        root = np.asarray(self.links[0].entity_pose.p, dtype=np.float64)
        return bool(np.linalg.norm(root - self.park_position) < PARKED_DISTANCE)


def robot_of(env) -> RobotView | None:
    """The env's robot (``gripper`` or ``panda`` executor), or None (``ideal``)."""
    gripper = getattr(env, "gripper", None)
    if gripper is not None:
        from wpbench.sim.gripper import PARK_POSITION, _hand_urdf

        return _view("gripper", gripper, _hand_urdf(), PARK_POSITION)
    arm = getattr(env, "arm", None)
    if arm is not None:
        from wpbench.sim.arm_planner import panda_files
        from wpbench.sim.panda_arm import PARK_POSITION

        return _view("panda", arm, panda_files()[0], PARK_POSITION)
    return None


def _view(kind: str, robot, urdf: Path, park_position) -> RobotView:
    from wpbench.sim.collision_mesh import body_mesh

    visuals = urdf_visual_meshes(str(urdf))
    names, meshes = [], []
    for link in robot.links:
        name = urdf_link_name(link.name, visuals.keys())
        mesh = visuals.get(name) if name is not None else None
        if mesh is None:
            mesh = body_mesh(link)
            if mesh is not None:
                mesh = mesh.copy()
                mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=DEFAULT_RGBA)
        names.append(name or _safe(link.name))
        meshes.append(mesh if mesh is not None and len(mesh.faces) else None)
    return RobotView(kind, list(robot.links), names, meshes, robot.tcp_pose,
                     np.asarray(park_position, dtype=np.float64))


def urdf_link_name(sapien_name: str, urdf_names) -> str | None:
    """The URDF link a SAPIEN link stands for: ManiSkill names links ``scene-<k>-<robot>_<urdf link>``."""
    matches = [n for n in urdf_names if sapien_name == n or sapien_name.endswith("_" + n)]
    return max(matches, key=len) if matches else None


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_\-]", "_", name) or "link"


@functools.lru_cache(maxsize=8)
def urdf_visual_meshes(urdf: str) -> dict[str, trimesh.Trimesh]:
    """URDF link name -> its visuals merged into one mesh in the link frame, with vertex
    colours. Links without visuals, or whose visuals cannot be loaded, are left out."""
    path = Path(urdf)
    root = ET.parse(path).getroot()
    materials = {m.get("name"): _rgba(m.find("color")) for m in root.findall("material")}
    out = {}
    for link in root.findall("link"):
        parts = []
        try:
            for visual in link.findall("visual"):
                mesh = _visual_mesh(visual, path.parent, materials)
                if mesh is not None:
                    parts.append(mesh)
        except (OSError, ValueError):
            continue   # the collision shapes stand in for this link
        if parts:
            out[link.get("name")] = trimesh.util.concatenate(parts) if len(parts) > 1 else parts[0]
    return out


def _visual_mesh(visual, folder: Path, materials: dict) -> trimesh.Trimesh | None:
    geometry = visual.find("geometry")
    if geometry is None:
        return None
    material = visual.find("material")
    rgba = None
    if material is not None:
        rgba = _rgba(material.find("color")) or materials.get(material.get("name"))
    shape = geometry[0] if len(geometry) else None
    if shape is None:
        return None
    if shape.tag == "mesh":
        mesh = _load_mesh(_mesh_path(shape.get("filename", ""), folder), rgba)
        scale = shape.get("scale")
        if scale:
            mesh.apply_scale(np.array([float(v) for v in scale.split()]))
    elif shape.tag == "box":
        mesh = trimesh.creation.box(extents=[float(v) for v in shape.get("size").split()])
    elif shape.tag == "cylinder":
        mesh = trimesh.creation.cylinder(radius=float(shape.get("radius")), height=float(shape.get("length")))
    elif shape.tag == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=float(shape.get("radius")))
    else:
        return None
    if shape.tag != "mesh":
        mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=rgba or DEFAULT_RGBA)
    mesh.apply_transform(_origin(visual.find("origin")))
    return mesh


def _mesh_path(filename: str, folder: Path) -> Path:
    if filename.startswith("package://"):
        filename = filename[len("package://"):]
    path = Path(filename)
    return path if path.is_absolute() else folder / path


def _load_mesh(path: Path, rgba) -> trimesh.Trimesh:
    """A mesh file as one mesh (the file's scene graph applied), each part coloured by its
    material (``rgba`` from the URDF overrides), vertices merged part by part."""
    scene = trimesh.load(str(path), force="scene")
    parts = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        part = scene.geometry[name]
        if not isinstance(part, trimesh.Trimesh) or len(part.faces) == 0:
            continue
        color = rgba or _part_color(part)
        part = trimesh.Trimesh(np.asarray(part.vertices), np.asarray(part.faces), process=False)
        part.apply_transform(transform)
        part.merge_vertices()
        part.visual = trimesh.visual.ColorVisuals(part, vertex_colors=color)
        parts.append(part)
    if not parts:
        raise ValueError(f"{path} holds no triangles")
    return trimesh.util.concatenate(parts) if len(parts) > 1 else parts[0]


def _part_color(part: trimesh.Trimesh) -> tuple[int, ...]:
    visual = part.visual
    material = getattr(visual, "material", None)
    if material is not None:
        try:
            return tuple(int(c) for c in np.asarray(material.main_color).reshape(-1)[:4])
        except (AttributeError, ValueError, TypeError):
            pass
    if getattr(visual, "kind", None) in ("vertex", "face"):
        return tuple(int(c) for c in np.asarray(visual.main_color).reshape(-1)[:4])
    return DEFAULT_RGBA


def _rgba(color) -> tuple[int, ...] | None:
    if color is None or not color.get("rgba"):
        return None
    values = np.clip([float(v) for v in color.get("rgba").split()], 0.0, 1.0)
    return tuple(int(round(255 * v)) for v in values)


def _origin(origin) -> np.ndarray:
    """URDF ``<origin xyz rpy>`` -> (4, 4); rpy are fixed-axis roll, pitch, yaw."""
    T = np.eye(4)
    if origin is None:
        return T
    xyz = [float(v) for v in origin.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in origin.get("rpy", "0 0 0").split()]
    T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    T[:3, 3] = xyz
    return T
