"""Cross-poses that are equally correct for a symmetric action object.

An object at world pose ``O`` looks the same at ``O S`` for every symmetry ``S``
of its group (object frame, ``wpbench.geometry.symmetry``). So if ``T`` takes it
to its goal, so does every ``T O S O^-1``: these are its *equivalent goals*
(:func:`equivalent_goals`; a cube has 24). Data generation stores the one that
rotates least.

:func:`nearest_goal` picks, per sample, the equivalent goal whose rotation is
nearest to a prediction; training uses it as the target. With ``within_deg`` it
keeps the stored goal unless another one lies within that angle of the
prediction, a gate for models whose early predictions are arbitrary. The
training default is no gate (``within_deg`` 180, ``PolicySpec.retarget_within_deg``
in ``wpbench.training.specs``; ``wpbench train --retarget-within DEG`` changes it).
Why the default is what it is: docs/experiment-log.md.

Only the discrete part of a group is enumerated: an object with a continuous
axis (a disk, a bowl) gets its discrete elements, which is exact for none of
them but never wrong (every element listed is a true symmetry).
Convention: 4x4 homogeneous matrices on column vectors, ``p_goal = T p``.
"""

from __future__ import annotations

import numpy as np
import torch


def equivalent_goals(T: np.ndarray, object_pose: np.ndarray, discrete: np.ndarray) -> np.ndarray:
    """``T O S_k O^-1`` for every ``S_k`` of ``discrete``.

    T, object_pose (4, 4); discrete (K, 3, 3) -> (K, 4, 4), in the order of ``discrete``.
    """
    T, object_pose, discrete = (np.asarray(a, dtype=np.float64) for a in (T, object_pose, discrete))
    if T.shape != (4, 4) or object_pose.shape != (4, 4) or discrete.ndim != 3 or discrete.shape[1:] != (3, 3):
        raise ValueError(f"expected T (4, 4), object_pose (4, 4), discrete (K, 3, 3); got "
                         f"{T.shape}, {object_pose.shape}, {discrete.shape}")
    S = np.tile(np.eye(4), (len(discrete), 1, 1))
    S[:, :3, :3] = discrete
    return T @ object_pose @ S @ np.linalg.inv(object_pose)


def nearest_goal(T_pred: torch.Tensor, goals: torch.Tensor, within_deg: float | None = None) -> torch.Tensor:
    """Per sample, the equivalent goal whose rotation is nearest to ``T_pred``'s.

    Nearest in rotation, not in where the points land: for a partial cloud a translation
    error can make a goal turned 90 degrees land the points closer. So the rotation error
    against the chosen goal is exactly the symmetric metric (``metrics.rotation_error_deg``
    with the object's group).

    T_pred (B, 4, 4); goals (B, K, 4, 4), row 0 the stored goal -> (B, 4, 4), a row of
    ``goals`` (in its dtype). With ``within_deg``, the stored goal is kept unless another is
    within that angle of ``T_pred``. Chosen without gradient; NaN predictions pick row 0.
    """
    if T_pred.dim() != 3 or T_pred.shape[1:] != (4, 4):
        raise ValueError(f"T_pred must have shape (B, 4, 4), got {tuple(T_pred.shape)}")
    B = T_pred.shape[0]
    if goals.dim() != 4 or goals.shape[0] != B or goals.shape[2:] != (4, 4):
        raise ValueError(f"goals must have shape (B, K, 4, 4) with B = {B}, got {tuple(goals.shape)}")
    if goals.shape[1] == 1:
        return goals[:, 0]
    with torch.no_grad():
        relative = T_pred.detach().double()[:, None, :3, :3].transpose(-1, -2) @ goals.double()[..., :3, :3]
        cosine = ((relative.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1.0, 1.0)
        angle = torch.rad2deg(torch.arccos(cosine))  # (B, K)
        if within_deg is not None:
            angle[:, 1:] = angle[:, 1:].masked_fill(angle[:, 1:] > within_deg, torch.inf)
            angle[:, 0] = torch.where(torch.isinf(angle[:, 1:]).all(dim=1), -1.0, angle[:, 0])
        best = torch.nan_to_num(angle, nan=torch.inf).argmin(dim=1)
    return goals[torch.arange(B), best]
