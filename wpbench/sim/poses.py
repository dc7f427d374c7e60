"""Conversions between SAPIEN poses and 4x4 matrices (numpy, float64).

Convention (docs/design.md): 4x4 homogeneous matrices acting on column vectors,
``p' = R p + t``; quaternions (w, x, y, z) as in SAPIEN.
"""

from __future__ import annotations

import numpy as np
import sapien


def pose_to_matrix(pose: sapien.Pose) -> np.ndarray:
    """sapien.Pose -> (4, 4) float64."""
    return np.asarray(pose.to_transformation_matrix(), dtype=np.float64)


def matrix_to_pose(T: np.ndarray) -> sapien.Pose:
    """(4, 4) rigid transform -> sapien.Pose. Raises ValueError if T is not finite."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"expected a (4, 4) matrix, got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError("pose matrix contains NaN or inf")
    return sapien.Pose(T.astype(np.float32))


def project_to_rigid(T: np.ndarray) -> np.ndarray:
    """Nearest rigid transform to a (4, 4) matrix (rotation block projected on SO(3) by SVD).

    Policies may return slightly non-orthogonal matrices (float32 round-off, or a raw
    regression); the executor applies the nearest rigid motion, never a shear.
    """
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"a cross-pose must be a (4, 4) matrix, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError("cross-pose contains NaN or inf")
    U, _, Vt = np.linalg.svd(T[:3, :3])
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    out = np.eye(4)
    out[:3, :3] = U @ D @ Vt
    out[:3, 3] = T[:3, 3]
    return out


def yaw_matrix(yaw: float) -> np.ndarray:
    """(4, 4) rotation about world z by ``yaw`` radians."""
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    return T


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply (4, 4) T to (N, 3) points."""
    return points @ T[:3, :3].T + T[:3, 3]
