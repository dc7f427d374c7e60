"""What a policy is to wpbench: something that maps one observation to one cross-pose.

``obs`` (numpy, unbatched, world frame): ``action_points`` (NA, 3) float32 and
``anchor_points`` (NB, 3) float32, the segmented clouds, and nothing else.
``info`` is the env's ground truth (``CrossPoseEnv.ground_truth()``: ``cross_pose``
(4, 4), ``kind``, ``stage``), given only to policies with ``uses_ground_truth = True``
(the ``gt`` reference and the ``oracle`` switcher); every other policy gets ``None``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np


@dataclass
class PolicyOutput:
    """A cross-pose ``transform`` (4, 4) float64 with ``p_goal = T p_now``, and whatever
    the policy wants to show (flows, correspondences, ``w``) in ``diagnostics``."""

    transform: np.ndarray
    diagnostics: dict[str, Any] = field(default_factory=dict)


@dataclass
class PolicyConfig:
    """Base of every policy's typed config."""

    name: ClassVar[str] = ""


class Policy(ABC):
    config: PolicyConfig
    uses_ground_truth: ClassVar[bool] = False

    @abstractmethod
    def predict(self, obs: dict[str, Any], info: dict[str, Any] | None = None) -> PolicyOutput:
        """One observation -> one cross-pose."""

    def describe(self) -> dict[str, Any]:
        """What to record about this policy beside each result (name, config, weights)."""
        from dataclasses import asdict

        return {"policy": self.config.name, "config": asdict(self.config)}
