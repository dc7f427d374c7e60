"""Segmented point clouds of the action and anchor objects, in the world frame.

Two sources, one output format ((N, 3) float32 per object):
- ``camera``: a SAPIEN depth + segmentation picture back-projected to the world,
  the points of each object picked by segmentation id (partial, view-dependent,
  as a real depth camera gives);
- ``mesh``: area-weighted samples of the collision geometry (all of it, or what a camera
  would see of it: ``wpbench.sim.visibility``; no renderer).
Both are reduced to a fixed size by farthest-point sampling (fpsample).
"""

from __future__ import annotations

import fpsample
import numpy as np
import trimesh


def fixed_size(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """(M, 3) -> (n, 3): farthest-point sampling when M >= n, otherwise all points
    plus random repeats (so a half-hidden object still gives a fixed-size cloud).

    Raises ValueError when M == 0: an object that is not seen at all cannot be sampled.
    """
    points = np.asarray(points, dtype=np.float32)
    m = len(points)
    if m == 0:
        raise ValueError("cannot sample a fixed-size cloud from zero points")
    if m == n:
        return points
    if m < n:
        extra = rng.integers(0, m, size=n - m)
        return np.concatenate([points, points[extra]], axis=0)
    start = int(rng.integers(0, m))
    if m > 8 * n:  # FPS cost grows with M: thin very dense clouds uniformly first
        points = points[rng.choice(m, size=8 * n, replace=False)]
        start = 0
    idx = fpsample.bucket_fps_kdline_sampling(points, n, h=5, start_idx=start)
    return points[np.asarray(idx, dtype=np.int64)]


def sample_mesh_surface(mesh: trimesh.Trimesh, n: int, rng: np.random.Generator) -> np.ndarray:
    """Area-weighted uniform samples on a mesh surface, (n, 3) float64, reproducible by ``rng``."""
    areas = mesh.area_faces
    if areas.sum() <= 0:
        raise ValueError("mesh has no surface area")
    faces = rng.choice(len(areas), size=n, p=areas / areas.sum())
    tri = mesh.triangles[faces]
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])


def camera_points_by_segment(
    position_gl: np.ndarray, segmentation: np.ndarray, cam_to_world_gl: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Back-project a SAPIEN ``Position`` picture to the world.

    Args:
        position_gl: (H, W, 4) float32, xyz in the OpenGL camera frame (w = depth flag).
        segmentation: (H, W) int, per-scene entity id of each pixel (0 = background).
        cam_to_world_gl: (4, 4) model matrix of the camera.
    Returns:
        points (M, 3) float64 in the world frame and their ids (M,), background removed.
    """
    seg = np.asarray(segmentation).reshape(-1)
    xyz = np.asarray(position_gl, dtype=np.float64)[..., :3].reshape(-1, 3)
    keep = seg != 0
    xyz, seg = xyz[keep], seg[keep]
    world = xyz @ cam_to_world_gl[:3, :3].T + cam_to_world_gl[:3, 3]
    return world, seg
