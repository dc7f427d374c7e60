"""Which surface points a pinhole camera would see: a point z-buffer.

The ``mesh`` observation samples the objects' surfaces; a depth camera sees only the
surface facing it, not the inside of a closed drawer or the back of a door. This
module keeps the samples a camera at ``eye`` looking at ``target`` would see, without
a renderer: every sample is projected into a ``resolution`` x ``resolution`` image,
each pixel keeps the nearest depth, and a sample is visible when it is no deeper than
its pixel's nearest depth plus a tolerance. The tolerance grows with the pixel's
footprint, since a surface seen at a slant spans that much depth within one pixel.
The image must be coarse enough that every pixel of a front surface holds samples,
or what lies behind shows through the gaps.

Camera frame as in SAPIEN: x forward, y left, z up.
"""

from __future__ import annotations

import numpy as np

DEPTH_TOLERANCE = 0.005  # m: a sample this far behind the nearest one in its pixel still counts as seen ...
SLANT_FOOTPRINTS = 2.0   # ... plus this many pixel footprints (a surface up to ~63 deg from facing the camera)


def look_at_frame(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(3, 3) rotation whose columns are the camera's forward, left and up axes in the world."""
    eye, target = np.asarray(eye, dtype=np.float64), np.asarray(target, dtype=np.float64)
    if eye.shape != (3,) or target.shape != (3,):
        raise ValueError(f"eye and target must be (3,), got {eye.shape} and {target.shape}")
    forward = target - eye
    norm = np.linalg.norm(forward)
    if norm < 1e-9:
        raise ValueError("eye and target coincide: the camera has no viewing direction")
    forward /= norm
    left = np.cross([0.0, 0.0, 1.0], forward)
    if np.linalg.norm(left) < 1e-6:
        left = np.array([0.0, 1.0, 0.0])
    left /= np.linalg.norm(left)
    up = np.cross(forward, left)
    return np.stack([forward, left, up], axis=1)


def visible_mask(
    points: np.ndarray,
    eye: np.ndarray,
    target: np.ndarray,
    fov: float,
    resolution: int,
    near: float = 0.05,
    tolerance: float = DEPTH_TOLERANCE,
) -> np.ndarray:
    """(M,) bool: which of the world points (M, 3) the camera sees.

    ``points`` must sample every surface that can hide another (occluders included),
    densely enough that each pixel a surface covers holds at least one of its samples.
    ``fov`` is the vertical (= horizontal) field of view in radians.
    Points behind the camera, nearer than ``near`` or outside the picture are not seen.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (M, 3), got {points.shape}")
    if not 0.0 < fov < np.pi or resolution < 1:
        raise ValueError(f"need 0 < fov < pi and resolution >= 1, got {fov} and {resolution}")
    axes = look_at_frame(eye, target)
    local = (points - np.asarray(eye, dtype=np.float64)) @ axes      # (M, 3): depth, left, up
    depth = local[:, 0]
    focal = (resolution / 2.0) / np.tan(fov / 2.0)
    in_front = depth > near
    safe = np.where(in_front, depth, 1.0)
    column = np.floor(resolution / 2.0 - focal * local[:, 1] / safe).astype(np.int64)
    row = np.floor(resolution / 2.0 - focal * local[:, 2] / safe).astype(np.int64)
    inside = in_front & (column >= 0) & (column < resolution) & (row >= 0) & (row < resolution)
    nearest = np.full((resolution, resolution), np.inf)
    np.minimum.at(nearest, (row[inside], column[inside]), depth[inside])
    footprint = depth[inside] / focal                                  # m per pixel at each depth
    seen = np.zeros(len(points), dtype=bool)
    seen[inside] = depth[inside] <= nearest[row[inside], column[inside]] + tolerance + SLANT_FOOTPRINTS * footprint
    return seen
