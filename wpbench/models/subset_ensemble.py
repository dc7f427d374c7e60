"""Test-time subset ensemble: one cross-pose from several random subsets of the observed clouds.

The models see a fixed number of points (``config.json``: ``num_action_points`` /
``num_anchor_points``), a random subset of what was observed, and different subsets
give slightly different poses. The ensemble averages them where the metrics live:
each of the K predictions moves the whole observed action cloud, and one Kabsch fit
(``weighted_procrustes``, uniform weights) turns the mean of the goal clouds back into a
rigid transform. For K = 1 that fit returns the prediction itself.

Only the goal clouds that agree are averaged (``consensus_size``): the medoid (the goal
cloud with the least summed distance to the others) and the ones nearest to it, half of
the K (at least 2). A symmetric object makes the plain mean go wrong: a cube's goals a
quarter turn apart are equally correct, one subset may answer one and the next subset the
other, and the point-by-point mean of the two lies 45 deg from both. Measured on the data3
val split (all 300 samples per kind, two subset seeds, rotation deg / translation cm), with
the plain mean / the consensus:

- wp-postsvd-t, 4 subsets: free-floating 6.49-7.14 / 2.05-2.08 and 5.70-5.79 / 2.12-2.15
  (blocks more than 10 deg off: 50-53 -> 37-39); articulated 3.03-3.14 / 2.81-2.85 and
  3.26 / 2.92-2.99.
- wp-postsvd-t, 8 subsets: free-floating 6.67-7.00 / 1.97-2.03 and 5.48-5.57 / 2.02-2.07
  (30-35 blocks past 10 deg); articulated 2.96-3.09 / 2.72-2.75 and 3.14-3.18 / 2.85.
- tp, 8 subsets: 6.85-7.36 / 2.36-2.46 and 5.54-5.67 / 2.38-2.45; gf, 8 subsets:
  3.45-3.55 / 3.43-3.46 and 3.49-3.61 / 3.45-3.53.

Against the plain mean of 4 (the previous default), the consensus of 8 is 1-1.6 deg better
in rotation on free-floating objects and about as good elsewhere (translation within 0.05 cm
on both kinds, articulated rotation within 0.15 deg), so
``wpbench.models.configs.DEFAULT_SUBSETS`` is 8: eight forward passes in one batch.
(Before the no-gate training, 1 -> 4 subsets with the plain mean took 0.4 cm off both
kinds' translation error.)

Mirrored views. Every model is trained on scenes mirrored in a vertical plane
(``wpbench.data.augment.random_yaw``), which keeps gravity and turns a left-hinged door into a
right-hinged one, so a mirrored scene is one the model knows. The network is not exactly
mirror-equivariant, and its errors on a scene and on its mirror image differ: averaging both
cancels part of them. So every second subset is answered in the scene mirrored in the plane
y = 0 (``view_transforms``): its clouds go in as ``M p`` and its answer ``T'`` comes back as
``M T' M`` (``M = M^-1``; the reflections cancel, so the result is a rigid motion), then all K
are fused as above. Yaw views are not worth it: the heading frame makes the models
yaw-equivariant (8 yaw views gave the same errors as 8 plain subsets, within 0.01).
Measured with the previous wp-postsvd-t (C in results/experiments) on data3 val (200 samples per kind, 8 subsets, consensus;
rotation deg / translation cm), plain subsets / every second one mirrored: free-floating
4.72 / 1.97 and 4.53 / 1.88; articulated 2.50 / 2.47 and 2.23 / 2.41 (safes 4.3 -> 3.1 cm and
fridges 3.0 -> 2.5 cm gain, drawers 4.5 -> 5.0 cm lose).

Convention: transforms act on column vectors, ``p_goal = R p + t``; clouds are (B, N, 3).
"""

from __future__ import annotations

import torch

from wpbench.geometry import se3
from wpbench.geometry.procrustes import weighted_procrustes


# The reflection y -> -y: a vertical plane through the world origin, as the training mirror.
MIRROR_Y = (1.0, -1.0, 1.0, 1.0)


def view_transforms(count: int, mirror: bool, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """(count, 4, 4) the frame each subset is answered in: the identity, and with ``mirror``
    the reflection ``MIRROR_Y`` for every odd subset (the first is always the scene as observed)."""
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    views = torch.eye(4, dtype=dtype).repeat(count, 1, 1)
    if mirror:
        views[1::2] = torch.diag(torch.tensor(MIRROR_Y, dtype=dtype))
    return views


def into_view(points: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """Clouds as seen in their views: (K, B, N, 3) or (K, N, 3) points, (K, 4, 4) linear views."""
    if views.dim() != 3 or views.shape[-2:] != (4, 4) or points.shape[0] != views.shape[0] or points.shape[-1] != 3:
        raise ValueError(f"need (K, ..., 3) points and (K, 4, 4) views, got {tuple(points.shape)} and {tuple(views.shape)}")
    R = views[:, :3, :3].to(points.dtype)
    R = R.reshape(R.shape[0], *([1] * (points.dim() - 3)), 3, 3)
    return points @ R.transpose(-1, -2)


def out_of_view(transforms: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """Answers given in the views, back in the observed frame: ``V^-1 T V`` for (K, B, 4, 4) or (K, 4, 4)
    transforms and (K, 4, 4) orthogonal views (``V^-1 = V^T``)."""
    if views.dim() != 3 or views.shape[-2:] != (4, 4) or transforms.shape[0] != views.shape[0] \
            or transforms.shape[-2:] != (4, 4):
        raise ValueError(f"need (K, ..., 4, 4) transforms and (K, 4, 4) views, "
                         f"got {tuple(transforms.shape)} and {tuple(views.shape)}")
    V = views.to(transforms.dtype).reshape(views.shape[0], *([1] * (transforms.dim() - 3)), 4, 4)
    return V.transpose(-1, -2) @ transforms @ V


def subsets_worth_drawing(subsets: int, observed: tuple[int, int], model_input: tuple[int, int]) -> int:
    """How many subsets to answer: ``subsets``, or 1 when neither observed cloud (action,
    anchor point counts) is larger than the model's input, since every subset would be the
    whole cloud and the same answer."""
    return subsets if any(n > m for n, m in zip(observed, model_input)) else 1


def consensus_size(subsets: int) -> int:
    """How many of ``subsets`` goal clouds the fused answer averages: half, at least 2 (all when fewer)."""
    return min(subsets, max(2, subsets // 2))


def fuse_goal_clouds(points: torch.Tensor, transforms: torch.Tensor) -> torch.Tensor:
    """The rigid transform taking ``points`` closest to the mean of the agreeing predicted goals.

    points: (B, N, 3) the observed action points; transforms: (K, B, 4, 4) K predictions
    for each of the B scenes. Per scene, the ``consensus_size(K)`` goal clouds nearest to
    the medoid (mean point distance) are averaged. Returns (B, 4, 4) in the dtype of ``points``.
    """
    if points.dim() != 3 or points.shape[-1] != 3:
        raise ValueError(f"points must be (B, N, 3), got {tuple(points.shape)}")
    if transforms.dim() != 4 or transforms.shape[1] != points.shape[0] or transforms.shape[-2:] != (4, 4):
        raise ValueError(f"transforms must be (K, B, 4, 4) with B = {points.shape[0]}, got {tuple(transforms.shape)}")
    if transforms.shape[0] == 0:
        raise ValueError("need at least one prediction to fuse")
    goals = se3.apply(transforms.to(points.dtype), points)  # (K, B, N, 3)
    keep = consensus_size(goals.shape[0])
    if keep < goals.shape[0]:
        distance = (goals[:, None] - goals[None]).norm(dim=-1).mean(dim=-1)  # (K, K, B)
        scenes = torch.arange(points.shape[0], device=points.device)
        medoid = distance.sum(dim=1).argmin(dim=0)  # (B,)
        nearest = distance[medoid, :, scenes].topk(keep, dim=1, largest=False).indices  # (B, keep)
        goals = goals[nearest, scenes[:, None]].transpose(0, 1)  # (keep, B, N, 3)
    uniform = torch.ones(points.shape[:2], dtype=points.dtype, device=points.device)
    return weighted_procrustes(points, goals.mean(dim=0), uniform)
