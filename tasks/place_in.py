"""PlaceIn-v0: put a Ravens object inside the furniture, its door already open."""

from __future__ import annotations

import numpy as np
from mani_skill.utils.registration import register_env

from wpbench.tasks.base import FREE, CrossPoseEnv


@register_env("wpbench/PlaceIn-v0", max_episode_steps=1)
class PlaceInEnv(CrossPoseEnv):
    """
    **Task Description:**
    Free-floating cross-pose: the action object is a Ravens object (block by default)
    on the floor in front of the furniture, the anchor is the furniture with its
    target door or drawer fully open. The goal is the object resting upright inside
    the cavity ("in" region), aligned with the furniture. The executor moves the
    object to the predicted pose and lets it go; physics decides where it ends.

    **Randomizations:**
    - the furniture instance, its yaw in [-pi, pi] and position in a 0.6 m square
    - the object (among ``objects``), its scale (Ravens x TAX-Pose range: block x2 to x4),
      its yaw, and its place on the floor in front of the open furniture
    - the camera viewpoint (obs_mode "camera")

    **Success Conditions:**
    - the object's centroid is inside the "in" region after the simulation settles,
      and the object is at rest
    """

    STAGES = (FREE,)

    def _initialize_task(self, rng: np.random.Generator, options: dict) -> None:
        self.furniture.set_target_qpos(self.asset.open_qpos)
        self.place_free_object_in_front(rng)
