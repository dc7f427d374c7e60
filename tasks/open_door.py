"""OpenDoor-v0: open a door or drawer of a piece of furniture fully."""

from __future__ import annotations

import numpy as np
from mani_skill.utils.registration import register_env

from wpbench.tasks.base import ARTICULATED, CrossPoseEnv

START_FRACTION = (0.0, 0.25)   # start in the lower quarter of the joint range


@register_env("wpbench/OpenDoor-v0", max_episode_steps=1)
class OpenDoorEnv(CrossPoseEnv):
    """
    **Task Description:**
    Articulated cross-pose: the action object is the furniture's target door (revolute)
    or drawer (prismatic) link, the anchor is the rest of the furniture. The policy
    sees both point clouds and answers with one cross-pose; the executor drives the
    joint to the value that best realises it.

    **Randomizations:**
    - the furniture instance, drawn from the chosen split of the asset library
    - the furniture's yaw in [-pi, pi] and its position in a 0.6 m x 0.6 m square
    - the start joint value, uniformly in the lower quarter of the range (closed .. 25% open)
    - the camera viewpoint (obs_mode "camera"): azimuth +-35 deg around the front,
      elevation 15-40 deg, distance to fit the furniture in view

    **Success Conditions:**
    - |q_open - q_final| / |q_open - q_start| < 0.1 with the joint at rest
    """

    STAGES = (ARTICULATED,)

    def _initialize_task(self, rng: np.random.Generator, options: dict) -> None:
        self.furniture.set_target_qpos(self.joint_fraction(float(rng.uniform(*START_FRACTION))))
