"""Pose-error metrics for cross-poses (docs/design.md, "Metrics").

Convention: transforms ``T`` are 4x4 homogeneous matrices on column vectors,
``p' = R p + t``; a cross-pose moves the action object from where it is now to
its goal, in the world frame. Leading batch dimensions (written ``B``) may be
any shape that broadcasts. NaN in gives NaN out: no metric turns a NaN into 0.

Rotation error with symmetry. The cross-pose rotations act in the world frame
but an object's symmetries ``S`` live in its own frame. With the object's
current world orientation ``R_o``, the goal orientation is ``R_gt R_o``, and
the object would look the same at ``R_gt R_o S``. So every world-frame
cross rotation ``R_gt R_o S R_o^T`` is an equally correct answer, and

    err = min_S angle(R_pred^T R_gt R_o S R_o^T) = min_S angle(E S),
    E = R_o^T R_pred^T R_gt R_o

(conjugating by ``R_o`` does not change a rotation angle). Without
``object_rotation`` the object frame is taken to be aligned with the world
(``R_o = I``). For a continuous axis ``a`` the elements are
``S_k Rot(a, theta)`` and the minimum over ``theta`` has a closed form
(swing-twist): ``min_theta angle(F Rot(a, theta)) = angle(a, F a)``, because
a rotation by ``phi`` moves no unit vector by more than ``phi`` (so it is a
lower bound), and removing the twist of ``F`` about ``a`` leaves a pure swing
whose angle is exactly that (so it is attained).

Angles are computed as ``atan2(|vee(E - E^T)| / 2, (trace(E) - 1) / 2)``: for
a rotation this equals the textbook ``acos(clip((trace - 1) / 2, -1, 1))`` but
keeps full precision near 0 and 180 degrees, where acos of a rounded cosine
would report e.g. ~0.03 deg in float32 for identical rotations; its gradient
is finite at zero error.
"""

from __future__ import annotations

import torch

from wpbench.geometry._checks import require_same_dtype, require_trailing
from wpbench.geometry.se3 import apply
from wpbench.geometry.symmetry import Symmetry

__all__ = [
    "rotation_angle",
    "rotation_error_deg",
    "translation_error",
    "raw_translation_error",
    "point_error",
]


def _safe_norm(vectors: torch.Tensor) -> torch.Tensor:
    """Euclidean norm over the last axis with a zero (not NaN) gradient at 0."""
    squared = vectors.square().sum(dim=-1)
    positive = squared > 0
    return torch.where(positive, torch.where(positive, squared, 1.0).sqrt(), squared)


def rotation_angle(R: torch.Tensor) -> torch.Tensor:
    """Rotation angle in radians, in [0, pi], of rotations ``R`` (..., 3, 3) -> (...)."""
    require_trailing("R", R, (3, 3), "(..., 3, 3)")
    skew = R - R.transpose(-1, -2)
    twice_sin_axis = torch.stack([skew[..., 2, 1], skew[..., 0, 2], skew[..., 1, 0]], dim=-1)
    sine = 0.5 * _safe_norm(twice_sin_axis)
    cosine = 0.5 * (R.diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0)
    return torch.atan2(sine, cosine)


def _vector_angle(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Angle in radians between vectors ``a`` and ``b`` (..., 3), broadcast -> (...)."""
    cross = torch.linalg.cross(a.expand_as(b), b)
    return torch.atan2(_safe_norm(cross), (a * b).sum(-1))


def rotation_error_deg(
    R_pred: torch.Tensor,
    R_gt: torch.Tensor,
    symmetry: Symmetry | None = None,
    object_rotation: torch.Tensor | None = None,
) -> torch.Tensor:
    """Geodesic rotation error in degrees, minimised over the object's symmetry group.

    Args:
        R_pred: (B, 3, 3) predicted world-frame cross rotation.
        R_gt: (B, 3, 3) true world-frame cross rotation.
        symmetry: the action object's group in its own frame (None = no symmetry).
        object_rotation: ``R_o`` (B, 3, 3) or (3, 3), the object's current world
            orientation (its object frame); None means aligned with the world.

    Returns:
        (B,) error in [0, 180] degrees; NaN where any input is NaN.
    """
    require_trailing("R_pred", R_pred, (3, 3), "(B, 3, 3)")
    require_trailing("R_gt", R_gt, (3, 3), "(B, 3, 3)")
    require_same_dtype(R_pred=R_pred, R_gt=R_gt)
    if symmetry is not None and not isinstance(symmetry, Symmetry):
        raise ValueError(f"symmetry must be a wpbench.geometry.symmetry.Symmetry or None, got {type(symmetry).__name__}")
    error = R_pred.transpose(-1, -2) @ R_gt  # (B, 3, 3)
    if object_rotation is not None:
        require_trailing("object_rotation", object_rotation, (3, 3), "(B, 3, 3) or (3, 3)")
        require_same_dtype(R_pred=R_pred, object_rotation=object_rotation)
        error = object_rotation.transpose(-1, -2) @ error @ object_rotation
    if symmetry is None or symmetry.is_trivial:
        return torch.rad2deg(rotation_angle(error))

    candidates = error.unsqueeze(-3) @ symmetry.discrete_as(error)  # (B, K, 3, 3) = E S_k
    axis = symmetry.axis_as(error)
    if axis is None:
        angles = rotation_angle(candidates)  # (B, K)
    else:
        angles = _vector_angle(axis, candidates @ axis)  # (B, K)
    # amin propagates NaN, so a NaN prediction stays NaN.
    return torch.rad2deg(angles.amin(dim=-1))


def _check_transform_pair(T_pred: torch.Tensor, T_gt: torch.Tensor) -> None:
    require_trailing("T_pred", T_pred, (4, 4), "(B, 4, 4)")
    require_trailing("T_gt", T_gt, (4, 4), "(B, 4, 4)")
    require_same_dtype(T_pred=T_pred, T_gt=T_gt)


def translation_error(T_pred: torch.Tensor, T_gt: torch.Tensor, centroid: torch.Tensor) -> torch.Tensor:
    """Distance (B,) between the predicted and true goal of the action centroid.

    ``|T_pred c - T_gt c|`` for ``T_pred``, ``T_gt`` (B, 4, 4) and ``centroid``
    ``c`` (B, 3) in the world frame; unlike ``|t_pred - t_gt|`` it does not
    depend on where the world origin is.
    """
    _check_transform_pair(T_pred, T_gt)
    require_trailing("centroid", centroid, (3,), "(B, 3)")
    require_same_dtype(T_pred=T_pred, centroid=centroid)
    point = centroid.unsqueeze(-2)  # (B, 1, 3)
    return _safe_norm((apply(T_pred, point) - apply(T_gt, point)).squeeze(-2))


def raw_translation_error(T_pred: torch.Tensor, T_gt: torch.Tensor) -> torch.Tensor:
    """``|t_pred - t_gt|`` (B,) for ``T_pred``, ``T_gt`` (B, 4, 4) (origin dependent; recorded for reference)."""
    _check_transform_pair(T_pred, T_gt)
    return _safe_norm(T_pred[..., :3, 3] - T_gt[..., :3, 3])


def point_error(T_pred: torch.Tensor, T_gt: torch.Tensor, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-point goal error of the action cloud.

    Args:
        T_pred, T_gt: (B, 4, 4).
        points: (B, N, 3) action points now, world frame.

    Returns:
        ``(mean_err (B,), mse (B,))``: the mean over points of
        ``|T_pred p - T_gt p|`` (metres) and the mean of its square (m^2).
    """
    _check_transform_pair(T_pred, T_gt)
    require_trailing("points", points, (3,), "(B, N, 3)")
    if points.dim() < 2 or points.shape[-2] == 0:
        raise ValueError(f"points must have shape (B, N, 3) with N >= 1, got {tuple(points.shape)}")
    require_same_dtype(T_pred=T_pred, points=points)
    difference = apply(T_pred, points) - apply(T_gt, points)  # (B, N, 3)
    squared = difference.square().sum(-1)  # (B, N)
    return _safe_norm(difference).mean(-1), squared.mean(-1)

