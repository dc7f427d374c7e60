"""What every cross-pose model returns."""

from __future__ import annotations

from dataclasses import dataclass, field

import torch


@dataclass
class CrossPoseOutput:
    """A batch of predicted cross-poses and the terms they were solved from.

    transform: (B, 4, 4) rigid transforms, ``p_goal = T p_now`` (world frame).
    diagnostics: named tensors, keys as in docs/CONTRACTS.md where they exist:
        ``flow`` (B,NA,3), ``w`` (B,) or (B,NA), ``action_targets`` (B,NA,3),
        ``action_weights`` (B,NA), ``anchor_sources`` (B,NB,3),
        ``anchor_weights`` (B,NB); WeightedPose adds ``taxpose_transform`` and
        ``goalflow_transform`` (B,4,4), the pose each branch gives alone.
    """

    transform: torch.Tensor
    diagnostics: dict[str, torch.Tensor] = field(default_factory=dict)

    def require(self, key: str) -> torch.Tensor:
        """The diagnostic ``key``, or a ValueError naming what this model provides."""
        if key not in self.diagnostics:
            raise ValueError(
                f"this model output has no {key!r} diagnostic (it has {sorted(self.diagnostics)}); "
                "use a loss preset that matches the model"
            )
        return self.diagnostics[key]
