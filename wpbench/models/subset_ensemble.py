"""Test-time subset ensemble: one cross-pose from several random subsets of the observed clouds.

The models see a fixed number of points (``config.json``: ``num_action_points`` /
``num_anchor_points``), a random subset of what was observed, and different subsets give
slightly different poses. :func:`ensemble_predict` is the one inference path of a trained
model: the learned policies (``wpbench.policies.learned``) answer the simulator with it, and
the pose-error tables (``wpbench.training.evaluate`` with ``subsets``, ``wpbench paper-table``)
measure exactly what the policies answer.

1. Draw the subsets (:func:`draw_subsets`): a NumPy generator seeded ``seed`` draws, subset by
   subset, the action points and then the anchor points (sorted indices, without
   replacement). A cloud no larger than the model's input is taken whole, and when neither
   cloud is larger only one subset is answered (:func:`subsets_worth_drawing`), since every
   subset would be the same.
2. Answer them in one batch, every second one in the mirrored scene (``mirror_views``,
   :func:`view_transforms`): every model is trained on scenes mirrored in a vertical plane
   (``wpbench.data.augment.random_yaw``), which keeps gravity and turns a left-hinged door
   into a right-hinged one, so a mirrored scene is one the model knows. The network is not
   exactly mirror-equivariant, and its errors on a scene and on its mirror image differ, so
   answering both and fusing cancels part of them. A mirrored subset goes in as ``M p``
   (``M`` the reflection y -> -y) and its answer ``T'`` comes back as ``M T' M`` (``M = M^-1``;
   the reflections cancel, so the result is a rigid motion). The first subset is always the
   scene as observed. Yaw views are not used: the heading frame makes the models
   yaw-equivariant, so a yawed view would give the same answer.
3. Fuse the answers where the metrics live (:func:`fuse_goal_clouds`): each of the K
   predictions moves the whole observed action cloud, and one Kabsch fit
   (``weighted_procrustes``, uniform weights) turns the mean of the goal clouds back into a
   rigid transform. Only the goal clouds that agree are averaged (:func:`consensus_size`):
   the medoid (the goal cloud with the least summed distance to the others) and the ones
   nearest to it, half of the K (at least 2). A symmetric object makes the plain mean go
   wrong: a cube's goals a quarter turn apart are equally correct, one subset may answer one
   and the next subset the other, and the point-by-point mean of the two lies 45 deg from
   both. With one subset the model's answer is returned as it is.

How much the ensemble, the consensus and the mirrored views gain, per policy and kind, is
measured in ``docs/experiment-log.md`` (the entries "Subset ensemble at test time", "The subset
ensemble's consensus" and "Mirrored views in the subset ensemble"); the default number of
subsets is ``wpbench.models.configs.DEFAULT_SUBSETS``.

Convention: transforms act on column vectors, ``p_goal = R p + t``; clouds are (B, N, 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from wpbench.geometry import se3
from wpbench.geometry.procrustes import weighted_procrustes
from wpbench.models.output import CrossPoseOutput


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


def random_subset(size: int, keep: int, rng: np.random.Generator) -> np.ndarray:
    """Sorted indices of ``keep`` of ``size`` points drawn without replacement (all of them,
    drawing nothing, when there are not more than ``keep``)."""
    if size <= keep:
        return np.arange(size)
    return np.sort(rng.choice(size, size=keep, replace=False))


def draw_subsets(observed: tuple[int, int], model_input: tuple[int, int], count: int,
                 rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    """``count`` (action indices, anchor indices) pairs: per subset the action points are drawn,
    then the anchor points (``random_subset``), from ``observed`` = (action, anchor) point counts
    down to ``model_input`` = the model's (action, anchor) point counts."""
    (num_action, num_anchor), (keep_action, keep_anchor) = observed, model_input
    picks = []
    for _ in range(count):
        action = random_subset(num_action, keep_action, rng)
        anchor = random_subset(num_anchor, keep_anchor, rng)
        picks.append((action, anchor))
    return picks


@dataclass
class EnsembleAnswer:
    """What :func:`ensemble_predict` returns.

    transform: (B, 4, 4) float64 fused cross-poses, or (4, 4) for an unbatched scene.
    first: the model's output on the first subset (the scene as observed), batch B
        (1 for an unbatched scene); its per-point diagnostics are on the points ``picks[0]`` kept.
    picks: the K subsets answered, (action indices, anchor indices) into the observed clouds,
        the same for every scene of the batch.
    """

    transform: torch.Tensor
    first: CrossPoseOutput
    picks: list[tuple[np.ndarray, np.ndarray]]


def _as_clouds(points: torch.Tensor, name: str) -> torch.Tensor:
    """(N, 3) or (B, N, 3) points -> a (B, N, 3) float32 tensor."""
    if points.dim() == 2:
        points = points[None]
    if points.dim() != 3 or points.shape[-1] != 3 or points.shape[0] == 0 or points.shape[1] == 0:
        raise ValueError(f"{name} must be a non-empty (N, 3) or (B, N, 3) cloud, got shape {tuple(points.shape)}")
    return points.to(torch.float32)


def ensemble_predict(
    model: torch.nn.Module,
    action: np.ndarray | torch.Tensor,
    anchor: np.ndarray | torch.Tensor,
    num_action: int,
    num_anchor: int,
    subsets: int,
    mirror_views: bool,
    seed: int,
) -> EnsembleAnswer:
    """The fused cross-pose of ``model`` (in eval mode) for observed clouds (module docstring).

    action: (N, 3) or (B, N, 3) observed action points; anchor: (M, 3) or (B, M, 3) observed
    anchor points, the same batch (float32; other dtypes are converted).
    num_action / num_anchor: the points per cloud the model was trained with.
    subsets: random subsets answered and fused (>= 1); mirror_views: answer every second
    subset in the mirrored scene; seed: seeds the NumPy generator that draws the subsets.

    The subsets are drawn once from the cloud sizes and used for every scene of a batch, so a
    scene in a batch gets the answer it gets alone with the same seed (up to float rounding in
    the batched forward pass). All K * B clouds go through the model in one call.
    """
    action, anchor = torch.as_tensor(action), torch.as_tensor(anchor)
    action_t, anchor_t = _as_clouds(action, "action"), _as_clouds(anchor, "anchor")
    unbatched = action.dim() == 2
    if action.dim() != anchor.dim() or action_t.shape[0] != anchor_t.shape[0]:
        raise ValueError(f"action and anchor must hold the same scenes, got shapes {tuple(action.shape)} "
                         f"and {tuple(anchor.shape)}")
    if subsets < 1:
        raise ValueError(f"subsets must be >= 1, got {subsets}")
    if num_action < 1 or num_anchor < 1:
        raise ValueError(f"the model's point counts must be >= 1, got {num_action} action / {num_anchor} anchor")
    scenes, observed = action_t.shape[0], (action_t.shape[1], anchor_t.shape[1])
    rng = np.random.default_rng(seed)
    count = subsets_worth_drawing(subsets, observed, (num_action, num_anchor))
    picks = draw_subsets(observed, (num_action, num_anchor), count, rng)
    views = view_transforms(count, mirror_views and count > 1)
    # (K, B, n, 3) -> (K * B, n, 3), subset-major: rows [0, B) are the first subset.
    seen_action = into_view(torch.stack([action_t[:, torch.from_numpy(ia)] for ia, _ in picks]), views)
    seen_anchor = into_view(torch.stack([anchor_t[:, torch.from_numpy(ib)] for _, ib in picks]), views)
    with torch.no_grad():
        out = model(seen_action.reshape(count * scenes, *seen_action.shape[2:]),
                    seen_anchor.reshape(count * scenes, *seen_anchor.shape[2:]))
        answers = out_of_view(out.transform.double().reshape(count, scenes, 4, 4), views)
        # one subset is the model's answer as it is
        transform = fuse_goal_clouds(action_t.double(), answers) if count > 1 else answers[0]
    first = CrossPoseOutput(out.transform[:scenes], {key: _first_rows(value, count * scenes, scenes)
                                                     for key, value in out.diagnostics.items()})
    return EnsembleAnswer(transform[0] if unbatched else transform, first, picks)


def _first_rows(value: torch.Tensor, rows: int, keep: int) -> torch.Tensor:
    """The first ``keep`` rows of a per-cloud diagnostic (anything else as it is)."""
    if isinstance(value, torch.Tensor) and value.dim() >= 1 and value.shape[0] == rows:
        return value[:keep]
    return value
