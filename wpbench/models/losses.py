"""Training losses for cross-pose models, as pure functions of tensors.

Every loss is a scalar: a squared distance in m^2 (summed over xyz) averaged
over points and samples, as TAX-Pose's MSE terms, unless stated otherwise.
Shapes: action ``p`` (B, NA, 3), anchor ``q`` (B, NB, 3), transforms (B, 4, 4),
``p_goal = T p``. Which loss trains which model is decided in ``loss_presets``.
"""

from __future__ import annotations

import torch

from wpbench.geometry import se3


def _mean_squared_distance(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Mean over points and samples of |a - b|^2; a, b (B, N, 3)."""
    if a.shape != b.shape:
        raise ValueError(f"loss operands differ in shape: {tuple(a.shape)} vs {tuple(b.shape)}")
    return (a - b).square().sum(dim=-1).mean()


def point_displacement_loss(T_pred: torch.Tensor, T_gt: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Mean |T_pred p - T_gt p|^2 over the points p (B, N, 3): how far each point lands from its goal."""
    return _mean_squared_distance(se3.apply(T_pred, points), se3.apply(T_gt, points))


def post_svd_point_loss(T_final: torch.Tensor, T_gt: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    """The point displacement loss on the *final* (WeightedPose, fused) SVD pose.

    Named separately because it trains both branches and w end to end through
    the one weighted SVD, while ``point_displacement_loss`` in the ``wp-og``
    preset is applied to the TAX-Pose branch's own pose.
    """
    return point_displacement_loss(T_final, T_gt, action)


def direct_correspondence_loss(
    action: torch.Tensor,
    action_targets: torch.Tensor,
    anchor: torch.Tensor,
    anchor_sources: torch.Tensor,
    T_gt: torch.Tensor,
) -> torch.Tensor:
    """Correspondences against the truth: |v_i - T_gt p_i|^2 + |u_j - T_gt^-1 q_j|^2 (each a mean)."""
    action_term = _mean_squared_distance(action_targets, se3.apply(T_gt, action))
    anchor_term = _mean_squared_distance(anchor_sources, se3.apply(se3.invert(T_gt), anchor))
    return action_term + anchor_term


def correspondence_consistency_loss(
    T_pred: torch.Tensor,
    action: torch.Tensor,
    action_targets: torch.Tensor,
    anchor: torch.Tensor,
    anchor_sources: torch.Tensor,
) -> torch.Tensor:
    """Correspondences against the pose solved from them: |v_i - T p_i|^2 + |u_j - T^-1 q_j|^2.

    TAX-Pose's consistency term: pushes the soft correspondences towards a
    single rigid motion (the SVD's), which the SVD alone does not require.
    """
    action_term = _mean_squared_distance(action_targets, se3.apply(T_pred, action))
    anchor_term = _mean_squared_distance(anchor_sources, se3.apply(se3.invert(T_pred), anchor))
    return action_term + anchor_term


def goal_flow_loss(flow: torch.Tensor, action: torch.Tensor, T_gt: torch.Tensor) -> torch.Tensor:
    """Flow supervision: mean |d_i - (T_gt p_i - p_i)|^2; flow d and action p (B, NA, 3)."""
    return _mean_squared_distance(flow, se3.apply(T_gt, action) - action)


def rotation_loss(T_pred: torch.Tensor, T_gt: torch.Tensor) -> torch.Tensor:
    """Mean squared Frobenius distance |R_pred - R_gt|_F^2 (= 8 sin^2(theta / 2), theta the angle between).

    Chosen over the geodesic angle because acos has an infinite gradient at
    zero error, which is exactly where training ends up.
    """
    return (T_pred[..., :3, :3] - T_gt[..., :3, :3]).square().sum(dim=(-1, -2)).mean()


def translation_loss(T_pred: torch.Tensor, T_gt: torch.Tensor, centroid: torch.Tensor) -> torch.Tensor:
    """Mean |T_pred c - T_gt c|^2 for the action centroid c (B, 3).

    The centroid's goal, not the raw |t_pred - t_gt|: the raw translation of a
    pose depends on where the world origin is (rotating about a far origin
    moves t a lot), the centroid's goal does not (the translation error of docs/design.md).
    """
    if centroid.dim() != 2 or centroid.shape[-1] != 3:
        raise ValueError(f"centroid must have shape (B, 3), got {tuple(centroid.shape)}")
    return point_displacement_loss(T_pred, T_gt, centroid.unsqueeze(1))
