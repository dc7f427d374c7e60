"""``gt``: the ground-truth cross-pose. The upper bound: it proves the executor and the scoring."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from wpbench.policies.base import Policy, PolicyConfig, PolicyOutput


@dataclass
class GroundTruthConfig(PolicyConfig):
    name: ClassVar[str] = "gt"


class GroundTruthPolicy(Policy):
    uses_ground_truth = True

    def __init__(self, config: GroundTruthConfig | None = None):
        self.config = config or GroundTruthConfig()

    def predict(self, obs: dict[str, Any], info: dict[str, Any] | None = None) -> PolicyOutput:
        if info is None or "cross_pose" not in info:
            raise ValueError("the gt policy needs the env's ground truth as info (env.unwrapped.ground_truth())")
        return PolicyOutput(np.asarray(info["cross_pose"], dtype=np.float64).reshape(4, 4).copy())
