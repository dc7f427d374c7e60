"""Goal Flow: a dense flow from each action point to its goal (FlowBot3D-style).

The network runs in the heading frame (``heading_frame``), so the flow is
exactly yaw-equivariant. One DGCNN runs over the whole scene, action ∪ anchor, with an extra
"is action" channel, in a frame centred on the action centroid (so the flow
is translation invariant and ``p + d`` translation equivariant). Per action
point a head reads the point feature and the scene's max-pooled global
feature (and its own centred xyz) and predicts its displacement ``d_i``. A second head predicts the
WeightedPose mixing weight ``w = sigmoid(.)``, per sample from the global
feature or per action point from (point, global) features.

Alone (the ``gf`` baseline), T is the Kabsch fit of ``p -> p + d`` with
uniform weights (``weighted_procrustes``, i.e. ``weighted_pose_svd`` at w = 1).
"""

from __future__ import annotations

import torch
from torch import nn

from wpbench.geometry.procrustes import weighted_procrustes
from wpbench.models.configs import GoalFlowConfig
from wpbench.models.dgcnn import DGCNN
from wpbench.models.heading_frame import from_heading_frame, heading_rotation, to_heading_frame
from wpbench.models.inputs import check_point_clouds
from wpbench.models.mlp import head_mlp
from wpbench.models.output import CrossPoseOutput


class GoalFlow(nn.Module):
    """forward(action (B, NA, 3), anchor (B, NB, 3)) -> CrossPoseOutput.

    Diagnostics: ``flow`` d (B, NA, 3) and ``w`` (B,) or (B, NA) (used by WeightedPose).
    """

    def __init__(self, config: GoalFlowConfig | None = None) -> None:
        super().__init__()
        self.config = config or GoalFlowConfig()
        dim = self.config.encoder.emb_dim
        self.encoder = DGCNN(self.config.encoder, extra_features=1)
        # Point feature + global feature + the point's own centred xyz: the goal flow of a
        # rigid motion is affine in the point position, (R - I) p + t, which the xyz skip
        # connection makes easy to express. The xyz is scaled (position_scale) to unit size:
        # in metres a 10 cm object gives inputs ~0.05, whose weights learn slowly.
        # Optional: the anchor's bounding box (2 corners = 6 numbers) joins the global feature,
        # a direct signal of the furniture's depth, which max-pooled point features carry
        # poorly (docs/experiment-log.md).
        extent = 6 if self.config.anchor_extent else 0
        self.flow_head = head_mlp(2 * dim + 3 + extent, self.config.head_hidden, 3)
        # The flow of a rigid motion is affine in the point, (R - I) p + t. This head reads the
        # global feature and predicts that affine map (a 3x3 matrix and a vector) for the whole
        # action object; the per-point head above adds what is not affine. Without it the
        # per-point MLP must multiply global features by coordinates itself, which it learns slowly.
        self.affine_head = head_mlp(dim + extent, self.config.head_hidden, 12) if self.config.affine_flow else None
        mixing_inputs = dim if self.config.mixing_weight == "per_sample" else 2 * dim + 3
        self.mixing_head = head_mlp(mixing_inputs, self.config.head_hidden, 1)

    def flow_terms(self, action: torch.Tensor, anchor: torch.Tensor) -> dict[str, torch.Tensor]:
        """``flow`` (B, NA, 3) (world frame) and mixing weight ``w`` (B,) or (B, NA) in (0, 1)."""
        check_point_clouds(action, anchor)
        if not self.config.heading_frame:
            return self._flow_terms_in_frame(action, anchor)
        rotation = heading_rotation(action, anchor, self.config.heading_source)
        terms = self._flow_terms_in_frame(to_heading_frame(rotation, action), to_heading_frame(rotation, anchor))
        terms["flow"] = from_heading_frame(rotation, terms["flow"])
        return terms

    def _flow_terms_in_frame(self, action: torch.Tensor, anchor: torch.Tensor) -> dict[str, torch.Tensor]:
        batch, action_points, _ = action.shape
        if action_points + anchor.shape[1] < self.config.encoder.k:
            raise ValueError(f"the scene needs at least k={self.config.encoder.k} points")
        centre = action.mean(dim=1, keepdim=True)
        scene = torch.cat([action, anchor], dim=1) - centre
        is_action = torch.zeros(batch, scene.shape[1], 1, dtype=scene.dtype, device=scene.device)
        is_action[:, :action_points] = 1.0
        features = self.encoder(scene, is_action)  # (B, NA + NB, D)
        global_feature = features.amax(dim=1)  # (B, D)
        action_features = torch.cat(
            [
                features[:, :action_points],
                global_feature.unsqueeze(1).expand(-1, action_points, -1),
                scene[:, :action_points] * self.config.position_scale,
            ],
            dim=-1,
        )
        # The flow heads may also read the anchor's bounding box; the mixing head never does.
        flow_inputs, affine_inputs = action_features, global_feature
        if self.config.anchor_extent:
            anchor_scaled = scene[:, action_points:] * self.config.position_scale
            extent = torch.cat([anchor_scaled.amin(dim=1), anchor_scaled.amax(dim=1)], dim=-1)  # (B, 6)
            flow_inputs = torch.cat([action_features, extent.unsqueeze(1).expand(-1, action_points, -1)], dim=-1)
            affine_inputs = torch.cat([global_feature, extent], dim=-1)
        flow = self.flow_head(flow_inputs)
        if self.affine_head is not None:
            affine = self.affine_head(affine_inputs)  # (B, 12)
            matrix, offset = affine[:, :9].view(batch, 3, 3), affine[:, 9:]
            flow = flow + scene[:, :action_points] @ matrix.transpose(1, 2) + offset.unsqueeze(1)
        if self.config.mixing_weight == "per_sample":
            w = torch.sigmoid(self.mixing_head(global_feature)).squeeze(-1)  # (B,)
        else:
            w = torch.sigmoid(self.mixing_head(action_features)).squeeze(-1)  # (B, NA)
        return {"flow": flow, "w": w}

    def forward(self, action: torch.Tensor, anchor: torch.Tensor) -> CrossPoseOutput:
        terms = self.flow_terms(action, anchor)
        uniform = torch.ones(action.shape[:2], dtype=action.dtype, device=action.device)
        transform = weighted_procrustes(action, action + terms["flow"], uniform)
        return CrossPoseOutput(transform=transform, diagnostics=terms)
