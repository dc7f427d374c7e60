"""Shared by the executor tests: one stage carried out with a transform of the true
cross-pose, the true cross-pose turned 30 deg about a random axis, and a door's true
cross-pose turned further or less about its own hinge."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from wpbench.sim.screw_path import screw_at, screw_of


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


def turned_about_hinge(T: np.ndarray, degrees: float) -> np.ndarray:
    """A door's cross-pose ``T`` (4, 4) turned ``degrees`` further (negative: less) about its own hinge."""
    screw = screw_of(np.asarray(T))
    return screw_at(screw, (screw.angle + np.radians(degrees)) / screw.angle)
