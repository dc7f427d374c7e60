"""Write an articulated object in PartNet-Mobility's on-disk layout.

A category module describes its object as :class:`ArticulatedModel`: links made of
primitive parts (boxes and cylinders) placed in the *body frame at q = 0*, and joints
whose origins are also given in the body frame. This module turns that description
into the files a PartNet-Mobility loader expects::

    <folder>/mobility.urdf         links base, link_0 (body), link_1.. ; joints joint_k
    <folder>/semantics.txt         "link_k hinge door" / "link_k slider drawer" / "link_0 heavy ..."
    <folder>/textured_objs/*.obj   one visual mesh per (link, colour), one mesh per collision piece

Every collision part is its own OBJ file, so SAPIEN's URDF loader (which takes the
convex hull of each collision file) keeps walls, shelves and doors as separate convex
pieces and cavities stay hollow. Mesh vertices are written in their link's frame, so
the URDF needs no per-mesh origins. Nothing here reads a clock or a global random
state: the same model gives byte-identical files.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

RGBA = tuple[float, float, float, float]
Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in the body frame at q = 0.

    ``center`` and ``size`` (full edge lengths, not half) in metres. ``collide`` adds
    it to the collision list; ``visible`` to the visual meshes.
    """

    center: Vec3
    size: Vec3
    rgba: RGBA
    collide: bool = True
    visible: bool = True

    def bounds(self) -> np.ndarray:
        """(2, 3): low and high corners."""
        c, h = np.asarray(self.center, float), np.asarray(self.size, float) / 2
        return np.stack([c - h, c + h])

    def mesh(self) -> trimesh.Trimesh:
        return trimesh.creation.box(extents=self.size, transform=_translation(self.center))


@dataclass(frozen=True)
class Cylinder:
    """A cylinder in the body frame at q = 0, its axis along ``axis`` ("x", "y" or "z")."""

    center: Vec3
    radius: float
    length: float
    axis: Literal["x", "y", "z"]
    rgba: RGBA
    collide: bool = True
    visible: bool = True
    sections: int = 20

    def bounds(self) -> np.ndarray:
        """(2, 3): low and high corners of the cylinder's bounding box."""
        half = np.full(3, self.radius)
        half["xyz".index(self.axis)] = self.length / 2
        c = np.asarray(self.center, float)
        return np.stack([c - half, c + half])

    def mesh(self) -> trimesh.Trimesh:
        # trimesh makes a z-aligned cylinder; rotate z onto the requested axis.
        rotations = {
            "z": np.eye(4),
            "x": trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]),
            "y": trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]),
        }
        transform = _translation(self.center) @ rotations[self.axis]
        return trimesh.creation.cylinder(
            radius=self.radius, height=self.length, sections=self.sections, transform=transform
        )


Part = Box | Cylinder


@dataclass
class LinkModel:
    """One rigid link: its parts and, for moving links, a mass in kg.

    ``mass=None`` lets the simulator derive mass from the collision volume (used for
    the fixed body, whose mass never matters).
    """

    name: str
    parts: list[Part] = field(default_factory=list)
    mass: float | None = None


@dataclass(frozen=True)
class JointModel:
    """A joint from ``parent`` to ``child``; ``origin`` is in the body frame at q = 0.

    The child link's frame equals the joint frame at q = 0 (no rotation), so a part at
    body-frame point p sits at ``p - origin`` in the child link. Increasing q opens.
    """

    name: str
    kind: Literal["fixed", "revolute", "prismatic"]
    parent: str
    child: str
    origin: Vec3 = (0.0, 0.0, 0.0)
    axis: Vec3 = (1.0, 0.0, 0.0)
    lower: float = 0.0
    upper: float = 0.0
    semantic: str = ""  # e.g. "hinge door", "slider drawer"; empty for the fixed body joint


@dataclass
class ArticulatedModel:
    """A whole object: ``links[0]`` is the body (``link_0``), the rest move."""

    name: str
    links: list[LinkModel]
    joints: list[JointModel]
    body_semantic: str  # e.g. "oven_body", written as "link_0 heavy oven_body"

    def link(self, name: str) -> LinkModel:
        for link in self.links:
            if link.name == name:
                return link
        raise KeyError(f"no link {name!r}; links are {[l.name for l in self.links]}")

    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned bounds of every part of the closed object, body frame."""
        all_bounds = np.stack([p.bounds() for l in self.links for p in l.parts])
        return np.stack([all_bounds[:, 0].min(axis=0), all_bounds[:, 1].max(axis=0)])


def _translation(offset) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = offset
    return t


def _fmt(values) -> str:
    """Floats as short fixed strings so URDF text never depends on repr quirks."""
    return " ".join(f"{float(v):.6g}" for v in values)


def _write_obj(mesh: trimesh.Trimesh, path: Path) -> None:
    text = trimesh.exchange.obj.export_obj(
        mesh, include_normals=False, include_color=False, include_texture=False, header=None, digits=6
    )
    path.write_text(text)


def _box_inertia(parts: list[Part], mass: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre of mass (3,) and inertia tensor (3, 3) about it, in the same frame as the parts.

    Mass is spread over the collision parts in proportion to their bounding-box volume
    (cylinders are treated as their bounding boxes: close enough for handles).
    """
    boxes = [p.bounds() for p in parts if p.collide]
    if not boxes:
        raise ValueError("a moving link needs at least one collision part to carry its mass")
    sizes = np.array([b[1] - b[0] for b in boxes])
    centres = np.array([(b[0] + b[1]) / 2 for b in boxes])
    volumes = np.prod(sizes, axis=1)
    masses = mass * volumes / volumes.sum()
    com = (masses[:, None] * centres).sum(axis=0) / mass
    inertia = np.zeros((3, 3))
    for m, s, c in zip(masses, sizes, centres):
        own = m / 12.0 * np.diag([s[1] ** 2 + s[2] ** 2, s[0] ** 2 + s[2] ** 2, s[0] ** 2 + s[1] ** 2])
        d = c - com
        inertia += own + m * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return com, inertia


def write_model(model: ArticulatedModel, folder: Path) -> Path:
    """Write ``mobility.urdf``, ``semantics.txt`` and meshes into ``folder``; return the URDF path."""
    folder = Path(folder)
    mesh_dir = folder / "textured_objs"
    mesh_dir.mkdir(parents=True, exist_ok=True)
    origin_of = {j.child: np.asarray(j.origin, float) for j in model.joints}

    lines = ['<?xml version="1.0" ?>', f'<robot name="{model.name}">', '\t<link name="base"/>']
    for link in model.links:
        offset = origin_of.get(link.name, np.zeros(3))
        lines.append(f'\t<link name="{link.name}">')
        if link.mass is not None:
            com, inertia = _box_inertia(link.parts, link.mass)
            lines += [
                "\t\t<inertial>",
                f'\t\t\t<origin xyz="{_fmt(com - offset)}"/>',
                f'\t\t\t<mass value="{link.mass:.6g}"/>',
                '\t\t\t<inertia ixx="{:.6g}" ixy="{:.6g}" ixz="{:.6g}" iyy="{:.6g}" iyz="{:.6g}" izz="{:.6g}"/>'.format(
                    inertia[0, 0], inertia[0, 1], inertia[0, 2], inertia[1, 1], inertia[1, 2], inertia[2, 2]
                ),
                "\t\t</inertial>",
            ]
        # Visual: one merged mesh per colour keeps the file count small.
        colours: dict[RGBA, list[trimesh.Trimesh]] = {}
        for part in link.parts:
            if part.visible:
                colours.setdefault(part.rgba, []).append(part.mesh())
        for k, (rgba, meshes) in enumerate(colours.items()):
            merged = trimesh.util.concatenate(meshes)
            merged.apply_translation(-offset)
            name = f"{link.name}-visual-{k}.obj"
            _write_obj(merged, mesh_dir / name)
            lines += [
                f'\t\t<visual name="{link.name}-visual-{k}">',
                f'\t\t\t<geometry><mesh filename="textured_objs/{name}"/></geometry>',
                f'\t\t\t<material name="{link.name}-material-{k}"><color rgba="{_fmt(rgba)}"/></material>',
                "\t\t</visual>",
            ]
        # Collision: one file per convex piece (the loader takes each file's convex hull).
        pieces = [p for p in link.parts if p.collide]
        for k, part in enumerate(pieces):
            mesh = part.mesh()
            mesh.apply_translation(-offset)
            name = f"{link.name}-collision-{k:02d}.obj"
            _write_obj(mesh, mesh_dir / name)
            lines += [
                f'\t\t<collision name="{link.name}-collision-{k:02d}">',
                f'\t\t\t<geometry><mesh filename="textured_objs/{name}"/></geometry>',
                "\t\t</collision>",
            ]
        lines.append("\t</link>")
    for joint in model.joints:
        lines += [
            f'\t<joint name="{joint.name}" type="{joint.kind}">',
            f'\t\t<origin xyz="{_fmt(joint.origin)}"/>',
        ]
        if joint.kind != "fixed":
            lines.append(f'\t\t<axis xyz="{_fmt(joint.axis)}"/>')
        lines += [f'\t\t<child link="{joint.child}"/>', f'\t\t<parent link="{joint.parent}"/>']
        if joint.kind != "fixed":
            lines.append(
                f'\t\t<limit lower="{joint.lower:.10g}" upper="{joint.upper:.10g}" effort="100" velocity="3"/>'
            )
        lines.append("\t</joint>")
    lines.append("</robot>")
    urdf = folder / "mobility.urdf"
    urdf.write_text("\n".join(lines) + "\n")

    semantics = [f"{j.child} {j.semantic}" for j in model.joints if j.semantic]
    semantics.append(f"{model.links[0].name} heavy {model.body_semantic}")
    (folder / "semantics.txt").write_text("\n".join(semantics) + "\n")
    return urdf
