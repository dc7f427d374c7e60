"""TAX-Pose: cross-pose from soft cross-object correspondences and a weighted SVD.

The network runs in the heading frame (``heading_frame``), so its
correspondences are exactly yaw-equivariant. Per object a DGCNN embeds the cloud centred on its own centroid (so features
are translation invariant; with ``absolute_height`` centred only horizontally); cross-attention lets each object's points read
the other's. Scores ``s_ij = <phi_i, psi_j> / sqrt(D)`` give

- for each action point a target ``v_i = sum_j softmax_j(s_ij) q_j + r_i``,
- for each anchor point a source ``u_j = sum_i softmax_i(s_ij) p_i + r_j``,

with ``q``, ``p`` in the world frame (soft correspondences are convex
combinations of real points, hence translation equivariant) plus a residual
``r`` from a per-point head, which also gives weights ``a_i``, ``b_j``
(softmax over points, so >= 0 and sum 1). ``dual_flow_svd`` turns them into T.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from wpbench.geometry.procrustes import dual_flow_svd
from wpbench.models.attention import BidirectionalCrossAttention
from wpbench.models.configs import TaxPoseConfig
from wpbench.models.dgcnn import DGCNN
from wpbench.models.heading_frame import from_heading_frame, heading_rotation, to_heading_frame
from wpbench.models.inputs import check_point_clouds
from wpbench.models.mlp import head_mlp
from wpbench.models.output import CrossPoseOutput


class TaxPose(nn.Module):
    """forward(action (B, NA, 3), anchor (B, NB, 3)) -> CrossPoseOutput.

    Diagnostics: ``action_targets`` v (B, NA, 3), ``action_weights`` a (B, NA),
    ``anchor_sources`` u (B, NB, 3), ``anchor_weights`` b (B, NB).
    """

    def __init__(self, config: TaxPoseConfig | None = None) -> None:
        super().__init__()
        self.config = config or TaxPoseConfig()
        dim = self.config.encoder.emb_dim
        self.action_encoder = DGCNN(self.config.encoder)
        self.anchor_encoder = DGCNN(self.config.encoder)
        self.cross_attention = BidirectionalCrossAttention(
            dim, self.config.attention_heads, self.config.ffn_mult, self.config.attention_layers
        )
        # 3 residual-flow channels + 1 weight logit per point.
        self.action_head = head_mlp(dim, self.config.head_hidden, 4)
        self.anchor_head = head_mlp(dim, self.config.head_hidden, 4)
        # Log of a learned factor on the correspondence scores. The scores of normalised
        # features start near N(0, 1): every soft target is then close to the other cloud's
        # centroid, and sharpening through the features alone is slow to learn.
        self.log_sharpness = nn.Parameter(torch.zeros(())) if self.config.learn_sharpness else None

    def correspondence_terms(self, action: torch.Tensor, anchor: torch.Tensor) -> dict[str, torch.Tensor]:
        """The dual-flow SVD inputs (world frame): action_targets, action_weights, anchor_sources, anchor_weights."""
        check_point_clouds(action, anchor, min_points=self.config.encoder.k)
        if not self.config.heading_frame:
            return self._correspondence_terms_in_frame(action, anchor)
        rotation = heading_rotation(action, anchor)
        terms = self._correspondence_terms_in_frame(to_heading_frame(rotation, action), to_heading_frame(rotation, anchor))
        for key in ("action_targets", "anchor_sources"):
            terms[key] = from_heading_frame(rotation, terms[key])
        return terms

    def _encoder_centre(self, points: torch.Tensor) -> torch.Tensor:
        """(B, 1, 3): the centroid the encoder input is taken relative to; with
        ``absolute_height`` its height is 0, so heights above the floor stay in the input."""
        centre = points.mean(dim=1, keepdim=True)
        if self.config.absolute_height:
            centre = centre * centre.new_tensor([1.0, 1.0, 0.0])
        return centre

    def _correspondence_terms_in_frame(self, action: torch.Tensor, anchor: torch.Tensor) -> dict[str, torch.Tensor]:
        action_features = self.action_encoder(action - self._encoder_centre(action))
        anchor_features = self.anchor_encoder(anchor - self._encoder_centre(anchor))
        action_features, anchor_features = self.cross_attention(action_features, anchor_features)

        scores = action_features @ anchor_features.transpose(1, 2) / math.sqrt(action_features.shape[-1])
        if self.log_sharpness is not None:
            scores = scores * self.log_sharpness.exp()
        soft_targets = torch.softmax(scores, dim=2) @ anchor  # (B, NA, 3) in the world frame
        soft_sources = torch.softmax(scores, dim=1).transpose(1, 2) @ action  # (B, NB, 3)

        action_out = self.action_head(action_features)
        anchor_out = self.anchor_head(anchor_features)
        return {
            "action_targets": soft_targets + action_out[..., :3],
            "action_weights": torch.softmax(action_out[..., 3], dim=1),
            "anchor_sources": soft_sources + anchor_out[..., :3],
            "anchor_weights": torch.softmax(anchor_out[..., 3], dim=1),
        }

    def forward(self, action: torch.Tensor, anchor: torch.Tensor) -> CrossPoseOutput:
        terms = self.correspondence_terms(action, anchor)
        transform = dual_flow_svd(
            action,
            terms["action_targets"],
            terms["action_weights"],
            terms["anchor_sources"],
            anchor,
            terms["anchor_weights"],
        )
        return CrossPoseOutput(transform=transform, diagnostics=terms)
