"""Shared by the executor tests: one stage carried out with a transform of the true
cross-pose, and the true cross-pose turned 30 deg about a random axis."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def step_with(env, seed: int, transform_of) -> dict:
    """Reset to ``seed``, act with ``transform_of(true cross-pose)``; the stage result."""
    env.reset(seed=seed)
    T = transform_of(env.unwrapped.ground_truth()["cross_pose"])
    _, _, _, _, info = env.step(T)
    return info["stage_result"]


def rotated_30(T: np.ndarray, seed: int) -> np.ndarray:
    """``T`` (4, 4) turned 30 deg about a random axis (drawn from ``seed``) through the origin."""
    axis = np.random.default_rng(seed).normal(size=3)
    R = np.eye(4)
    R[:3, :3] = Rotation.from_rotvec(np.radians(30) * axis / np.linalg.norm(axis)).as_matrix()
    return R @ T
