"""OpenThenPlace-v0: open the door, then put the block inside (the paper's task)."""

from __future__ import annotations

import numpy as np
from mani_skill.utils.registration import register_env

from wpbench.tasks.base import ARTICULATED, FREE, CrossPoseEnv
from wpbench.tasks.open_door import START_FRACTION


@register_env("wpbench/OpenThenPlace-v0", max_episode_steps=2)
class OpenThenPlaceEnv(CrossPoseEnv):
    """
    **Task Description:**
    The two stages in one episode. Stage 0 (articulated): open the target door or
    drawer fully. Stage 1 (free-floating): put the Ravens object inside the cavity,
    with the door wherever stage 0 left it. One observation and one cross-pose per
    stage; the second observation is made after the first stage has been simulated.

    **Randomizations:**
    - as OpenDoor-v0 for the furniture, its pose and the start joint value
    - as PlaceIn-v0 for the object, its scale, yaw and place on the floor
    - the camera viewpoint (obs_mode "camera"), one per episode

    **Success Conditions:**
    - stage 0: |q_open - q_final| / |q_open - q_start| < 0.1 with the joint at rest
    - stage 1: the object's centroid inside the "in" region, at rest
    - the episode succeeds only if both stages do
    """

    STAGES = (ARTICULATED, FREE)

    def _initialize_task(self, rng: np.random.Generator, options: dict) -> None:
        self.furniture.set_target_qpos(self.joint_fraction(float(rng.uniform(*START_FRACTION))))
        self.place_free_object_in_front(rng)
