"""WeightedPose: Goal Flow and TAX-Pose fused by one weighted SVD.

Both branches see the same (action, anchor) clouds. Goal Flow gives a flow
``d`` and the mixing weight ``w``; TAX-Pose gives (v, a, u, b). One
``weighted_pose_svd`` solves the objective of docs/design.md: ``w -> 1`` trusts the
flow (articulated parts), ``w -> 0`` the correspondences (free objects).

Starting from trained branches::

    model = WeightedPose.from_pretrained(goalflow.state_dict(), taxpose.state_dict(), config)

loads each branch's weights (the config's branch sizes must match them). The
mixing-weight head is part of Goal Flow; if its shape differs (a Goal Flow
trained with per-sample w loaded into a per-point WeightedPose) it keeps its
fresh initialisation (w = 0.5) and a warning says so.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping

import torch
from torch import nn

from wpbench.geometry.procrustes import dual_flow_svd, weighted_pose_svd, weighted_procrustes
from wpbench.models.configs import WeightedPoseConfig
from wpbench.models.goalflow import GoalFlow
from wpbench.models.output import CrossPoseOutput
from wpbench.models.taxpose import TaxPose

_MIXING_HEAD_PREFIX = "mixing_head."


class WeightedPose(nn.Module):
    """forward(action (B, NA, 3), anchor (B, NB, 3)) -> CrossPoseOutput.

    Diagnostics: ``flow``, ``w``, ``action_targets``, ``action_weights``,
    ``anchor_sources``, ``anchor_weights`` and each branch's own pose,
    ``goalflow_transform`` and ``taxpose_transform`` (B, 4, 4) (used by the
    ``wp-og`` loss preset, which supervises the branches separately).
    """

    def __init__(self, config: WeightedPoseConfig | None = None) -> None:
        super().__init__()
        self.config = config or WeightedPoseConfig()
        self.goalflow = GoalFlow(self.config.goalflow_branch)
        self.taxpose = TaxPose(self.config.taxpose)

    def forward(self, action: torch.Tensor, anchor: torch.Tensor) -> CrossPoseOutput:
        flow_terms = self.goalflow.flow_terms(action, anchor)
        corr = self.taxpose.correspondence_terms(action, anchor)
        p, v, a = action, corr["action_targets"], corr["action_weights"]
        u, q, b = corr["anchor_sources"], anchor, corr["anchor_weights"]
        d, w = flow_terms["flow"], flow_terms["w"]
        transform = weighted_pose_svd(p, v, a, u, q, b, d, w)
        uniform = torch.ones(p.shape[:2], dtype=p.dtype, device=p.device)
        diagnostics = {
            **flow_terms,
            **corr,
            "taxpose_transform": dual_flow_svd(p, v, a, u, q, b),
            "goalflow_transform": weighted_procrustes(p, p + d, uniform),
        }
        return CrossPoseOutput(transform=transform, diagnostics=diagnostics)

    @classmethod
    def from_pretrained(
        cls,
        goalflow_state: Mapping[str, torch.Tensor],
        taxpose_state: Mapping[str, torch.Tensor],
        config: WeightedPoseConfig | None = None,
    ) -> WeightedPose:
        """A WeightedPose whose branches start from trained Goal Flow and TAX-Pose weights.

        goalflow_state / taxpose_state: ``state_dict()`` of a ``GoalFlow`` / ``TaxPose``
        built with ``config.goalflow`` / ``config.taxpose`` sizes.
        """
        model = cls(config)
        _load_branch(model.taxpose, taxpose_state, "TAX-Pose", "config.taxpose")
        own = model.goalflow.state_dict()
        head_keys = [key for key in own if key.startswith(_MIXING_HEAD_PREFIX)]
        head_fits = all(
            key in goalflow_state and tuple(goalflow_state[key].shape) == tuple(own[key].shape) for key in head_keys
        )
        kept = dict(goalflow_state)
        if not head_fits:
            # Load the head whole or not at all: half a head trained for another input is noise.
            warnings.warn(
                f"Goal Flow mixing head does not fit w_mode={model.config.w_mode!r} "
                "(trained for the other mode); keeping it freshly initialised (w = 0.5)",
                stacklevel=2,
            )
            kept = {key: value for key, value in kept.items() if not key.startswith(_MIXING_HEAD_PREFIX)}
            kept.update({key: own[key] for key in head_keys})
        _load_branch(model.goalflow, kept, "Goal Flow", "config.goalflow")
        return model


def _load_branch(module: nn.Module, state: Mapping[str, torch.Tensor], label: str, field: str) -> None:
    """load_state_dict with an error that says which config to fix."""
    try:
        module.load_state_dict(dict(state), strict=True)
    except RuntimeError as error:
        raise ValueError(
            f"the {label} weights do not fit this WeightedPose: {error}\n"
            f"Build the WeightedPoseConfig with {field} equal to the config the {label} model was trained with."
        ) from error
