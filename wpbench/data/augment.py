"""Scene augmentation that keeps the ground truth consistent.

A random yaw ``A`` (rotation about world z through the origin) applied to the
whole scene moves every point ``p -> A p``; the cross-pose that takes the
rotated action object to its rotated goal is ``T' = A T A^-1``, because
``A p_goal = A T p = (A T A^-1) (A p)``. Gravity stays along z, so the
augmented scene is one the simulator could have produced.

A mirror ``M`` in a vertical plane (``y -> -y``) keeps gravity too, and the same
rule holds: ``M T M^-1`` is again a rigid motion (``det(M R M) = det R``, the
reflections cancel). It turns a left-hinged door into a right-hinged one, so
the training furniture counts twice for the hinge side, which a model must read
from the handle. A least-rotation target stays least-rotation, because the
mirror conjugates every symmetric equivalent alike and keeps rotation angles.

A uniform scale ``s`` about the world origin (``p -> s p``) keeps rotations and
scales translations: ``s p_goal = s (R p + t) = R (s p) + s t``, so ``T' = [R | s t]``.
The floor (z = 0) stays where it is. A chest of drawers scaled by ``s`` slides ``s``
times as far, so scaling ties a drawer's travel to the furniture's visible size
instead of to one of the few training instances (their open limit is a fixed
fraction of their depth, ``wpbench.assets.procedural.storage``).

A uniform scale ties the travel to the chest's size as a whole, but a chest's depth is
drawn independently of its width and height, so the rule a model needs is "deeper chest,
longer slide". A stretch along the slide direction ``a`` (a unit horizontal vector) by
``s``, ``S = I + (s - 1) a a^T`` about the anchor's centroid, is that rule exactly: the
chest, the drawer and its travel get longer along ``a`` alone, and a goal that is a pure
translation ``t`` along ``a`` becomes ``S t = s t`` (``T' = [I | s t]``). Only sliding
samples get it (a stretch does not keep a door's rotation rigid); they are recognised from
the ground truth, a translation of more than 1 cm with no rotation.
"""

from __future__ import annotations

import math

import torch

from wpbench.data.config import ARTICULATED, KIND_CODE


def yaw_rotations(angles: torch.Tensor) -> torch.Tensor:
    """(B,) radians -> (B, 4, 4) rotations about z."""
    c, s = torch.cos(angles), torch.sin(angles)
    A = torch.zeros(angles.shape[0], 4, 4, dtype=angles.dtype, device=angles.device)
    A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1] = c, -s, s, c
    A[:, 2, 2] = A[:, 3, 3] = 1.0
    return A


def random_yaw(
    batch: dict[str, torch.Tensor], generator: torch.Generator | None = None, mirror: bool = False
) -> dict[str, torch.Tensor]:
    """Rotate each sample of ``batch`` by its own random yaw in [-pi, pi), and with
    ``mirror`` reflect half of them (at random) in the plane y = 0 first.

    batch: ``action`` (B, NA, 3), ``anchor`` (B, NB, 3), ``gt_transform`` (B, 4, 4),
    optionally ``gt_equivalents`` (B, K, 4, 4) (moved like ``gt_transform``);
    other keys are passed through. Returns a new dict (inputs are not modified).
    """
    B = batch["action"].shape[0]
    dtype = batch["action"].dtype
    angles = (torch.rand(B, generator=generator, dtype=torch.float64) * 2 - 1) * math.pi
    A = yaw_rotations(angles)
    if mirror:
        flip = torch.rand(B, generator=generator, dtype=torch.float64) < 0.5
        A[:, :, 1] = torch.where(flip[:, None], -A[:, :, 1], A[:, :, 1])  # A <- A diag(1, -1, 1, 1)
    R = A[:, :3, :3].to(dtype)
    out = dict(batch)
    out["action"] = batch["action"] @ R.transpose(1, 2)
    out["anchor"] = batch["anchor"] @ R.transpose(1, 2)
    T = batch["gt_transform"].to(torch.float64)
    out["gt_transform"] = (A @ T @ A.transpose(1, 2)).to(batch["gt_transform"].dtype)
    if "gt_equivalents" in batch:
        E = batch["gt_equivalents"].to(torch.float64)
        out["gt_equivalents"] = (A[:, None] @ E @ A.transpose(1, 2)[:, None]).to(batch["gt_equivalents"].dtype)
    return out


def random_scale(
    batch: dict[str, torch.Tensor], spread: float, generator: torch.Generator | None = None
) -> dict[str, torch.Tensor]:
    """Scale each sample of ``batch`` about the world origin by its own factor, uniform in
    ``[1 - spread, 1 + spread]`` (0 <= spread < 1).

    batch: as for :func:`random_yaw`; ``gt_transform`` (B, 4, 4) and ``gt_equivalents``
    (B, K, 4, 4) keep their rotations and have their translations scaled.
    """
    if not 0.0 <= spread < 1.0:
        raise ValueError(f"scale spread must be in [0, 1), got {spread}")
    B = batch["action"].shape[0]
    factor = 1.0 + (torch.rand(B, generator=generator, dtype=torch.float64) * 2 - 1) * spread
    out = dict(batch)
    for key in ("action", "anchor"):
        out[key] = batch[key] * factor.to(batch[key].dtype)[:, None, None]
    return _scale_goal_translations(batch, out, factor)


def sliding_samples(batch: dict[str, torch.Tensor], min_travel: float = 0.01) -> torch.Tensor:
    """(B,) bool: the articulated samples whose goal (and every equivalent goal) is a pure
    translation of more than ``min_travel`` metres (a drawer with travel left)."""
    T = batch["gt_transform"].to(torch.float64)
    eye = torch.eye(3, dtype=torch.float64)
    pure = (T[:, :3, :3] - eye).abs().amax(dim=(1, 2)) < 1e-5
    if "gt_equivalents" in batch:
        E = batch["gt_equivalents"].to(torch.float64)
        pure &= (E[..., :3, :3] - eye).abs().flatten(1).amax(dim=1) < 1e-5
    moving = T[:, :3, 3].norm(dim=1) > min_travel
    return (batch["kind"] == KIND_CODE[ARTICULATED]) & pure & moving


def random_slide_stretch(
    batch: dict[str, torch.Tensor], spread: float, generator: torch.Generator | None = None
) -> dict[str, torch.Tensor]:
    """Stretch each sliding sample of ``batch`` (:func:`sliding_samples`) along its slide
    direction by its own factor, uniform in ``[1 - spread, 1 + spread]`` (0 <= spread < 1),
    about the anchor's centroid; other samples are passed through.

    batch: as for :func:`random_yaw`, plus ``kind`` (B,) (``KIND_CODE``); the goal
    translations of the stretched samples (``gt_transform`` and ``gt_equivalents``) are
    multiplied by their factor.
    """
    if not 0.0 <= spread < 1.0:
        raise ValueError(f"stretch spread must be in [0, 1), got {spread}")
    B = batch["action"].shape[0]
    factor = 1.0 + (torch.rand(B, generator=generator, dtype=torch.float64) * 2 - 1) * spread
    chosen = sliding_samples(batch)
    factor = torch.where(chosen, factor, torch.ones_like(factor))
    t = batch["gt_transform"][:, :3, 3].to(torch.float64)
    direction = t / t.norm(dim=1, keepdim=True).clamp_min(1e-12)
    # S = I + (s - 1) a a^T; identity where the sample is not stretched.
    S = torch.eye(3, dtype=torch.float64) + (factor - 1.0)[:, None, None] * direction[:, :, None] * direction[:, None, :]
    centre = batch["anchor"].to(torch.float64).mean(dim=1, keepdim=True)
    out = dict(batch)
    for key in ("action", "anchor"):
        points = batch[key].to(torch.float64)
        out[key] = ((points - centre) @ S.transpose(1, 2) + centre).to(batch[key].dtype)
    return _scale_goal_translations(batch, out, factor)


def _scale_goal_translations(batch: dict[str, torch.Tensor], out: dict[str, torch.Tensor],
                             factor: torch.Tensor) -> dict[str, torch.Tensor]:
    """Write into ``out`` the goals of ``batch`` (``gt_transform`` (B, 4, 4), ``gt_equivalents``
    (B, K, 4, 4) if present) with their translations multiplied by ``factor`` (B,); returns ``out``."""
    for key in ("gt_transform", "gt_equivalents"):
        if key in batch:
            T = batch[key].clone()
            per_sample = factor.to(T.dtype).view(-1, *([1] * (T.dim() - 2)))  # (B, 1) or (B, 1, 1)
            T[..., :3, 3] = T[..., :3, 3] * per_sample
            out[key] = T
    return out
