"""Test-time subset ensemble: one cross-pose from several random subsets of the observed clouds.

The models see a fixed number of points (``config.json``: ``num_action_points`` /
``num_anchor_points``), a random subset of what was observed, and different subsets
give slightly different poses. The ensemble averages them where the metrics live:
each of the K predictions moves the whole observed action cloud, the K goal clouds
are averaged point by point, and one Kabsch fit (``weighted_procrustes``, uniform
weights) turns the mean goal cloud back into a rigid transform. For K = 1 that fit
returns the prediction itself.

Measured on the data3 val split (every sample), shipped wp-postsvd-t, 1 / 4 / 8 subsets:
translation error 4.05 / 3.65 / 3.63 cm on articulated and 3.11 / 2.78 cm (1 / 4) on
free-floating samples; rotation error about unchanged (articulated 4.66 / 4.65 / 4.55 deg,
free-floating 11.8 / 12.0 deg). Beyond 4 subsets the gain is small for twice the cost, so
``wpbench.models.configs.DEFAULT_SUBSETS`` is 4. A per-point median instead of the mean
gave the same numbers (8 subsets), so the simpler mean is used.

Convention: transforms act on column vectors, ``p_goal = R p + t``; clouds are (B, N, 3).
"""

from __future__ import annotations

import torch

from wpbench.geometry.procrustes import weighted_procrustes


def subsets_worth_drawing(subsets: int, observed: tuple[int, int], model_input: tuple[int, int]) -> int:
    """How many subsets to answer: ``subsets``, or 1 when neither observed cloud (action,
    anchor point counts) is larger than the model's input, since every subset would be the
    whole cloud and the same answer."""
    return subsets if any(n > m for n, m in zip(observed, model_input)) else 1


def fuse_goal_clouds(points: torch.Tensor, transforms: torch.Tensor) -> torch.Tensor:
    """The rigid transform taking ``points`` closest to the mean of their K predicted goals.

    points: (B, N, 3) the observed action points; transforms: (K, B, 4, 4) K predictions
    for each of the B scenes. Returns (B, 4, 4) in the dtype of ``points``.
    """
    if points.dim() != 3 or points.shape[-1] != 3:
        raise ValueError(f"points must be (B, N, 3), got {tuple(points.shape)}")
    if transforms.dim() != 4 or transforms.shape[1] != points.shape[0] or transforms.shape[-2:] != (4, 4):
        raise ValueError(f"transforms must be (K, B, 4, 4) with B = {points.shape[0]}, got {tuple(transforms.shape)}")
    if transforms.shape[0] == 0:
        raise ValueError("need at least one prediction to fuse")
    T = transforms.to(points.dtype)
    goals = torch.einsum("kbij,bnj->kbni", T[..., :3, :3], points) + T[:, :, None, :3, 3]
    uniform = torch.ones(points.shape[:2], dtype=points.dtype, device=points.device)
    return weighted_procrustes(points, goals.mean(dim=0), uniform)
