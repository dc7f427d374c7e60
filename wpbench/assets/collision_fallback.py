"""Collision pieces for a link whose convex decomposition gives nothing usable.

Real PartNet-Mobility objects are full of small links (a handle, a knob, a button)
whose meshes are flat slivers: CoACD returns only pieces without volume, or crashes
on them. Rather than refuse the whole object, such a link gets, in this order:

1. the convex hull of its mesh, when the hull has a thickness (a solid knob);
2. a thin box: the link's oriented bounding box with its thinnest side grown to
   :data:`MIN_THICKNESS_FRACTION` of its largest side (a flat handle);
3. no collision at all, when the mesh has no area (a line or a point cannot push
   anything).

Pure functions on vertex arrays; the caller records which fallback a link got.
"""

from __future__ import annotations

import numpy as np
import trimesh

# A hull (or a box) thinner than this fraction of its largest side counts as flat.
MIN_THICKNESS_FRACTION = 0.02
# Sides shorter than this fraction of the largest one are zero (numerical noise).
ZERO_EXTENT_FRACTION = 1e-6

CONVEX_HULL = "convex hull"
THIN_BOX = "thin box"
NO_COLLISION = "no collision"


def principal_extents(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Oriented bounding box of points (N, 3) along their principal axes.

    Returns (center (3,), axes (3, 3) with one unit axis per row, thinnest first,
    extents (3,) full side lengths in the same order).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) == 0:
        raise ValueError(f"vertices must have shape (N>0, 3), got {vertices.shape}")
    mean = vertices.mean(0)
    centered = vertices - mean
    _values, vectors = np.linalg.eigh(centered.T @ centered)  # ascending variance
    axes = vectors.T
    local = centered @ axes.T
    low, high = local.min(0), local.max(0)
    extents = high - low
    order = np.argsort(extents, kind="stable")
    axes, low, high, extents = axes[order], low[order], high[order], extents[order]
    center = mean + ((low + high) / 2) @ axes
    return center, axes, extents


def thin_box(vertices: np.ndarray) -> trimesh.Trimesh | None:
    """The oriented bounding box of ``vertices`` (N, 3), thinnest side grown to
    ``MIN_THICKNESS_FRACTION`` of the largest; None if the points span less than a plane."""
    center, axes, extents = principal_extents(vertices)
    largest = float(extents[2])
    if largest <= 0 or extents[1] <= ZERO_EXTENT_FRACTION * largest:
        return None
    sides = extents.copy()
    sides[0] = max(sides[0], MIN_THICKNESS_FRACTION * largest)
    transform = np.eye(4)
    transform[:3, :3] = axes.T
    transform[:3, 3] = center
    return trimesh.creation.box(extents=sides, transform=transform)


def solid_hull(vertices: np.ndarray) -> trimesh.Trimesh | None:
    """Convex hull of ``vertices`` (N, 3) if it is thicker than ``MIN_THICKNESS_FRACTION``
    of its largest side; None for a flat or degenerate point set."""
    _center, _axes, extents = principal_extents(vertices)
    if extents[2] <= 0 or extents[0] < MIN_THICKNESS_FRACTION * extents[2]:
        return None
    try:
        hull = trimesh.convex.convex_hull(np.asarray(vertices, dtype=np.float64))
    except Exception:  # qhull refuses degenerate input with several exception types
        return None
    return hull if hull.volume > 0 else None


def fallback_pieces(vertices: np.ndarray) -> tuple[list[trimesh.Trimesh], str]:
    """Pieces standing in for a link whose decomposition failed, and which fallback it is.

    ``vertices`` (N, 3): the link's collision mesh vertices in the link frame (N may be 0).
    Returns ([hull], CONVEX_HULL), ([box], THIN_BOX) or ([], NO_COLLISION).
    """
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    if len(vertices) == 0:
        return [], NO_COLLISION
    hull = solid_hull(vertices)
    if hull is not None:
        return [hull], CONVEX_HULL
    box = thin_box(vertices)
    if box is not None:
        return [box], THIN_BOX
    return [], NO_COLLISION
