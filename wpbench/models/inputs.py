"""Validation of the (action, anchor) point clouds every model takes."""

from __future__ import annotations

import torch


def check_point_clouds(action: torch.Tensor, anchor: torch.Tensor, min_points: int = 1) -> None:
    """Raise ValueError unless action (B, NA, 3) and anchor (B, NB, 3) are usable model input.

    min_points: the fewest points a cloud may have (a DGCNN needs more than k).
    """
    for name, cloud in (("action", action), ("anchor", anchor)):
        if not isinstance(cloud, torch.Tensor):
            raise ValueError(f"{name} must be a torch.Tensor (B, N, 3), got {type(cloud).__name__}")
        if cloud.dim() != 3 or cloud.shape[-1] != 3:
            raise ValueError(
                f"{name} must have shape (B, N, 3), got {tuple(cloud.shape)}; add a batch axis with {name}[None]"
            )
        if not cloud.is_floating_point():
            raise ValueError(f"{name} must be float32/float64, got {cloud.dtype}; cast with {name}.float()")
        if cloud.shape[1] < min_points:
            raise ValueError(
                f"{name} has {cloud.shape[1]} points but this model needs at least {min_points} "
                "(DGCNN neighbours); sample more points or lower encoder.k"
            )
    if action.shape[0] != anchor.shape[0]:
        raise ValueError(f"action and anchor batch sizes differ: {action.shape[0]} vs {anchor.shape[0]}")
    if action.dtype != anchor.dtype:
        raise ValueError(f"action ({action.dtype}) and anchor ({anchor.dtype}) must share a dtype")
