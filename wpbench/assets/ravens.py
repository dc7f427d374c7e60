"""The Ravens objects (block, ell, disk, slimdisk, bowl), rebuilt to Ravens' dimensions.

TAX-Pose and WeightedPose take their free-floating objects from Ravens
(google-research/ravens). Ravens ships them as URDFs that pybullet loads; wpbench
rebuilds them as trimesh meshes so the simulator and the point-cloud sampler share
one description. Dimensions, read from Ravens' asset files:

- block: ``block/block.urdf``, a 0.04 m cube, 0.1 kg, colour rgba (1, 0.3412, 0.3490)
  (Ravens' "red", i.e. (255, 87, 89) / 255).
- ell: ``insertion/ell.urdf``, two 0.04 m tall boxes, 0.08 x 0.03 centred at
  (0.025, 0, 0) and 0.03 x 0.08 centred at (0, 0.025, 0); 0.1 kg, red.
- disk: ``hanoi/disk0.urdf`` + ``disk0.obj`` (mm, scale 0.001): a ring of outer
  radius 0.030 m, hole radius 0.015 m, height 0.010 m; 0.1 kg, red.
- slimdisk: ``hanoi/slimdisk.urdf`` = ``disk3.obj`` scaled (0.001, 0.001, 0.0005):
  outer radius 0.045 m, hole radius 0.015 m, height 0.005 m; 0.1 kg, green.
- bowl: ``bowl/bowl.urdf``, 0.1 kg, green rgba (0.349, 0.663, 0.310); its mesh is not
  in the stored sources, so the footprint is Ravens' ``bowl_size`` (0.12 m across,
  from its tasks) and the height (0.045 m), wall and floor thickness are our estimate.

Object frames follow Ravens (the ell's origin is where its arms cross); z is up and
the object rests on z = -rest_half_height. ``scale_range`` is the per-episode uniform
scale (TAX-Pose draws the block at x2 to x4, i.e. 8 to 16 cm).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Literal

import numpy as np
import trimesh

RAVENS_RED = (1.0, 0.3412, 0.3490, 1.0)
RAVENS_GREEN = (0.34901961, 0.6627451, 0.30980392, 1.0)

SymmetryKind = Literal["cube", "cylinder", "axial", "ell", "none"]


@dataclass(frozen=True)
class RavensObject:
    """One Ravens object at scale 1 (metres), with methods to scale it.

    Attributes:
        name: "block", "ell", "disk", "slimdisk" or "bowl".
        mass: kg (Ravens gives 0.1 kg for all of them; kept whatever the scale).
        rgba: colour in [0, 1].
        scale_range: (low, high) uniform per-episode scale.
        rest_half_height: half the height at scale 1; resting on a floor at height h,
            the object's origin is at h + rest_half_height * scale.
        symmetry_kind: which symmetry group (see :attr:`symmetry`).
    """

    name: str
    mass: float
    rgba: tuple[float, float, float, float]
    scale_range: tuple[float, float]
    rest_half_height: float
    symmetry_kind: SymmetryKind
    _visual: Callable[[], trimesh.Trimesh]
    _collision: Callable[[], list[trimesh.Trimesh]]

    def visual_mesh(self, scale: float = 1.0) -> trimesh.Trimesh:
        """Closed surface of the object, scaled about its origin."""
        _check_scale(scale)
        mesh = self._visual().copy()
        mesh.apply_scale(scale)
        return mesh

    def collision_parts(self, scale: float = 1.0) -> list[trimesh.Trimesh]:
        """Convex pieces whose union is the object (concave objects: several pieces)."""
        _check_scale(scale)
        parts = []
        for part in self._collision():
            part = part.copy()
            part.apply_scale(scale)
            parts.append(part)
        return parts

    def half_height(self, scale: float = 1.0) -> float:
        return self.rest_half_height * scale

    @property
    def symmetry(self):
        """The object's rotational symmetry group (``wpbench.geometry.symmetry.Symmetry``)."""
        from wpbench.geometry.symmetry import Symmetry  # torch is heavy: import on use

        if self.symmetry_kind == "cube":
            return Symmetry.cube()
        if self.symmetry_kind == "cylinder":  # a ring: any turn about z, and upside down
            return Symmetry.cylinder((0.0, 0.0, 1.0))
        if self.symmetry_kind == "axial":  # a bowl: any turn about z, never upside down
            return Symmetry.axial((0.0, 0.0, 1.0))
        if self.symmetry_kind == "ell":
            # A half turn about the diagonal (1, 1, 0)/sqrt(2) swaps the two arms.
            half_turn = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
            return Symmetry.from_discrete([half_turn])
        return Symmetry.none()


def _check_scale(scale: float) -> None:
    if not np.isfinite(scale) or scale <= 0:
        raise ValueError(f"scale must be a positive number, got {scale}")


def _box(low, high) -> trimesh.Trimesh:
    low, high = np.asarray(low, float), np.asarray(high, float)
    t = np.eye(4)
    t[:3, 3] = (low + high) / 2
    return trimesh.creation.box(extents=high - low, transform=t)


def _ring_profile(r_in: float, r_out: float, h: float) -> np.ndarray:
    return np.array([[r_in, -h / 2], [r_out, -h / 2], [r_out, h / 2], [r_in, h / 2], [r_in, -h / 2]])


def _revolve(profile: np.ndarray, sections: int = 48) -> trimesh.Trimesh:
    """Revolve a closed (r, z) polygon about z into a closed surface."""
    mesh = trimesh.creation.revolve(profile, sections=sections)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def _ring_sectors(r_in: float, r_out: float, z0: float, z1: float, pieces: int) -> list[trimesh.Trimesh]:
    """Convex pieces of a ring: each the hull of one angular sector's corner points.

    A sector's inner arc is concave, so its hull fills the inner chord: with 12 pieces
    the hole is narrowed by at most r_in * (1 - cos(15 deg)), 3.4% of its radius.
    """
    out = []
    for k in range(pieces):
        angles = np.linspace(2 * np.pi * k / pieces, 2 * np.pi * (k + 1) / pieces, 4)
        pts = []
        for r in (r_in, r_out):
            for a in angles:
                for z in (z0, z1):
                    pts.append([r * np.cos(a), r * np.sin(a), z])
        out.append(trimesh.convex.convex_hull(np.array(pts)))
    return out


# --- block -------------------------------------------------------------------
BLOCK_SIDE = 0.04


def _block_visual() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=[BLOCK_SIDE] * 3)


# --- ell ---------------------------------------------------------------------
ELL_ARM_LONG, ELL_ARM_WIDTH, ELL_HEIGHT = 0.08, 0.03, 0.04


def _ell_pieces() -> list[trimesh.Trimesh]:
    """Two convex collision pieces. Ravens overlaps its two boxes; here the second arm
    stops where the first starts, so the pieces tile the L (same union, volumes add up)."""
    w, h = ELL_ARM_WIDTH / 2, ELL_HEIGHT / 2
    arm_x = _box((-w, -w, -h), (0.025 + ELL_ARM_LONG / 2, w, h))
    arm_y = _box((-w, w, -h), (w, 0.025 + ELL_ARM_LONG / 2, h))
    return [arm_x, arm_y]


def _ell_visual() -> trimesh.Trimesh:
    """Corner square plus two equal arms: a surface as symmetric as the L itself."""
    w, h, end = ELL_ARM_WIDTH / 2, ELL_HEIGHT / 2, 0.025 + ELL_ARM_LONG / 2
    return trimesh.util.concatenate([
        _box((-w, -w, -h), (w, w, h)),
        _box((w, -w, -h), (end, w, h)),
        _box((-w, w, -h), (w, end, h)),
    ])


# --- disks ---------------------------------------------------------------------
DISK = dict(r_in=0.015, r_out=0.030, h=0.010)
SLIMDISK = dict(r_in=0.015, r_out=0.045, h=0.005)

# --- bowl --------------------------------------------------------------------
BOWL_RADIUS, BOWL_HEIGHT, BOWL_WALL, BOWL_FLOOR, BOWL_BASE_RADIUS = 0.06, 0.045, 0.006, 0.006, 0.035


def _bowl_radius_at(z: float) -> float:
    """Outer radius of the flared wall at height z in [0, BOWL_HEIGHT] (from its base)."""
    return BOWL_BASE_RADIUS + (BOWL_RADIUS - BOWL_BASE_RADIUS) * (z / BOWL_HEIGHT) ** 0.7


def _bowl_visual() -> trimesh.Trimesh:
    zs = np.linspace(0.0, BOWL_HEIGHT, 10)
    outer = [[_bowl_radius_at(z), z] for z in zs]
    inner = [[_bowl_radius_at(z) - BOWL_WALL, z] for z in zs[::-1] if z >= BOWL_FLOOR]
    profile = np.array([[0.0, 0.0]] + outer + inner + [[0.0, BOWL_FLOOR], [0.0, 0.0]])
    profile[:, 1] -= BOWL_HEIGHT / 2
    return _revolve(profile)


def _bowl_pieces() -> list[trimesh.Trimesh]:
    z0 = -BOWL_HEIGHT / 2
    floor = trimesh.creation.cylinder(radius=BOWL_BASE_RADIUS, height=BOWL_FLOOR, sections=24)
    floor.apply_translation([0, 0, z0 + BOWL_FLOOR / 2])
    pieces = [floor]
    # Wall: 12 sectors x 2 height bands, each the hull of its corner points.
    bands = np.linspace(0.0, BOWL_HEIGHT, 3)
    for lo, hi in zip(bands[:-1], bands[1:]):
        for k in range(12):
            angles = np.linspace(2 * np.pi * k / 12, 2 * np.pi * (k + 1) / 12, 4)
            pts = []
            for z in (lo, hi):
                r_out = _bowl_radius_at(z)
                for r in (r_out - BOWL_WALL, r_out):
                    for a in angles:
                        pts.append([r * np.cos(a), r * np.sin(a), z0 + z])
            pieces.append(trimesh.convex.convex_hull(np.array(pts)))
    return pieces


def _make_objects() -> dict[str, RavensObject]:
    def ring_visual(d):
        return lambda: _revolve(_ring_profile(d["r_in"], d["r_out"], d["h"]))

    def ring_pieces(d):
        return lambda: _ring_sectors(d["r_in"], d["r_out"], -d["h"] / 2, d["h"] / 2, 12)

    return {
        "block": RavensObject("block", 0.1, RAVENS_RED, (2.0, 4.0), BLOCK_SIDE / 2, "cube",
                              _block_visual, lambda: [_block_visual()]),
        "ell": RavensObject("ell", 0.1, RAVENS_RED, (1.5, 2.5), ELL_HEIGHT / 2, "ell",
                            _ell_visual, _ell_pieces),
        "disk": RavensObject("disk", 0.1, RAVENS_RED, (2.0, 3.0), DISK["h"] / 2, "cylinder",
                             ring_visual(DISK), ring_pieces(DISK)),
        "slimdisk": RavensObject("slimdisk", 0.1, RAVENS_GREEN, (1.5, 2.5), SLIMDISK["h"] / 2, "cylinder",
                                 ring_visual(SLIMDISK), ring_pieces(SLIMDISK)),
        "bowl": RavensObject("bowl", 0.1, RAVENS_GREEN, (1.0, 1.5), BOWL_HEIGHT / 2, "axial",
                             _bowl_visual, _bowl_pieces),
    }


RAVENS_OBJECTS: dict[str, RavensObject] = _make_objects()


def get_ravens_object(name: str) -> RavensObject:
    """The Ravens object called ``name``; ValueError listing the valid names otherwise."""
    try:
        return RAVENS_OBJECTS[name]
    except KeyError:
        raise ValueError(f"unknown Ravens object {name!r}; valid names: {', '.join(RAVENS_OBJECTS)}") from None
