"""Overlap and trimming of convex collision pieces, as pure geometry.

A convex piece is given by its vertices (K, 3); its hull is ``{x : A x <= b}`` with
unit outward face normals as rows of A. Two pieces overlap by the radius of the
largest ball inside both hulls (a linear program: maximise t with
``A x + t <= b`` for both hulls), so a 4 mm slab of overlap measures 2 mm and two
pieces that only touch measure 0. Trimming keeps the part of a piece on the far
side of one face plane of an obstacle, which is again convex.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, QhullError

# Pieces with less volume than this fraction of their volume before trimming are dropped.
MIN_KEPT_VOLUME_FRACTION = 0.02


def _check_vertices(vertices: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 4:
        raise ValueError(f"{name} must have shape (K>=4, 3), got {v.shape}")
    return v


def hull_halfspaces(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A (F, 3) unit outward normals, b (F,)) with the hull of ``vertices`` (K, 3) = {x : A x <= b}.

    Raises ValueError when the points span no volume.
    """
    v = _check_vertices(vertices, "vertices")
    try:
        hull = ConvexHull(v)
    except QhullError as err:
        raise ValueError(f"the {len(v)} vertices span no volume") from err
    normals, offsets = hull.equations[:, :3], hull.equations[:, 3]
    return normals, -offsets


def convex_volume(vertices: np.ndarray) -> float:
    """Volume of the hull of ``vertices`` (K, 3); 0 when they span no volume."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (K, 3), got {v.shape}")
    if len(v) < 4:
        return 0.0
    try:
        return float(ConvexHull(v).volume)
    except QhullError:
        return 0.0


def overlap_inradius(a: np.ndarray, b: np.ndarray) -> float:
    """Radius of the largest ball inside both hulls of ``a`` (K, 3) and ``b`` (L, 3); 0 when disjoint or touching."""
    A1, b1 = hull_halfspaces(a)
    A2, b2 = hull_halfspaces(b)
    A = np.vstack([A1, A2])
    rhs = np.concatenate([b1, b2])
    # Variables (x, y, z, t): maximise t subject to A p + t <= b, t >= 0.
    result = linprog(c=[0, 0, 0, -1], A_ub=np.hstack([A, np.ones((len(A), 1))]), b_ub=rhs,
                     bounds=[(None, None)] * 3 + [(0, None)], method="highs")
    return float(result.x[3]) if result.status == 0 else 0.0


def clip_convex(vertices: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray | None:
    """Vertices (M, 3) of the hull of ``vertices`` (K, 3) cut to ``{x : normal . x >= offset}``.

    None when less than a sliver of volume (:data:`MIN_KEPT_VOLUME_FRACTION`) is left.
    """
    v = _check_vertices(vertices, "vertices")
    n = np.asarray(normal, dtype=np.float64)
    if n.shape != (3,) or not np.linalg.norm(n) > 0:
        raise ValueError(f"normal must be a nonzero (3,) vector, got {normal!r}")
    n = n / np.linalg.norm(n)
    try:
        hull = ConvexHull(v)
    except QhullError:
        return None
    side = v @ n - offset
    kept = [v[side >= 0]]
    edges = {tuple(sorted((int(s[i]), int(s[(i + 1) % 3])))) for s in hull.simplices for i in range(3)}
    for i, j in edges:
        if side[i] * side[j] < 0:
            w = side[i] / (side[i] - side[j])
            kept.append((v[i] + w * (v[j] - v[i]))[None])
    points = np.concatenate(kept)
    if convex_volume(points) < MIN_KEPT_VOLUME_FRACTION * hull.volume:
        return None
    return points[ConvexHull(points).vertices]


def trim_away(piece: np.ndarray, obstacle: np.ndarray, gap: float = 0.0) -> np.ndarray | None:
    """``piece`` (K, 3) cut by the face plane of ``obstacle`` (L, 3) that keeps most of it, pushed
    out by ``gap``: the result does not overlap the obstacle. None when nothing worth keeping is left."""
    A, b = hull_halfspaces(obstacle)
    best, best_volume = None, -1.0
    for normal, offset in zip(A, b):
        clipped = clip_convex(piece, normal, offset + gap)
        volume = convex_volume(clipped) if clipped is not None else 0.0
        if volume > best_volume:
            best, best_volume = clipped, volume
    return best
