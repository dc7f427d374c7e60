"""Validation errors of a model on a dataset, per kind (metrics as in ``wpbench.geometry.metrics``).

rotation error (deg), translation error (m, goal position of the action
centroid), point error (m, mean |T_pred p - T_gt p| over the action points),
all against the equivalent goal nearest to the prediction in rotation (for a symmetric
object every equivalent goal is correct; ``wpbench.data.equivalent_goals``).

Two ways to answer a sample:

- ``subsets=None`` (training's per-epoch and final validation): one random subset of each
  stored cloud, drawn for a whole batch from a torch generator seeded ``seed``; the errors
  are measured on the action points the model saw.
- ``subsets=K``: the sample answered exactly as a learned policy with that ``seed``,
  ``subsets`` and ``mirror_views`` answers it in the simulator
  (``wpbench.models.subset_ensemble.ensemble_predict``); the errors are measured on every
  stored action point. The paper table measures this way.
"""

from __future__ import annotations

import math

import torch

from wpbench.data.config import KIND_CODE, KINDS
from wpbench.data.dataset import CrossPoseDataset
from wpbench.data.equivalent_goals import nearest_goal
from wpbench.geometry import metrics
from wpbench.models.configs import DEFAULT_MIRROR_VIEWS
from wpbench.models.subset_ensemble import ensemble_predict
from wpbench.training.batches import make_batch, subsample_points


def _check_subsets(subsets: int | None) -> None:
    if subsets is not None and subsets < 1:
        raise ValueError(f"subsets must be >= 1 (or None for one subset per sample, as in training), got {subsets}")


@torch.no_grad()
def predicted_poses(
    model: torch.nn.Module,
    dataset: CrossPoseDataset,
    indices: torch.Tensor,
    num_action: int,
    num_anchor: int,
    batch_size: int = 16,
    seed: int = 0,
    subsets: int | None = None,
    mirror_views: bool = DEFAULT_MIRROR_VIEWS,
):
    """Yield, batch by batch, (batch, T_pred (B, 4, 4) float64, points (B, N, 3) the errors are
    measured on, first-subset model output) for the samples ``indices`` (module docstring for
    ``subsets``). ``batch_size`` counts model inputs: with K subsets, batch_size // K samples a batch.
    The model is put in eval mode while it answers."""
    _check_subsets(subsets)
    was_training = model.training
    model.eval()
    generator = torch.Generator().manual_seed(seed)
    step = batch_size if subsets is None else max(1, batch_size // subsets)
    try:
        for start in range(0, len(indices), step):
            batch = make_batch(dataset, indices[start:start + step])
            if subsets is None:
                action = subsample_points(batch["action"], num_action, generator)
                anchor = subsample_points(batch["anchor"], num_anchor, generator)
                output = model(action, anchor)
                yield batch, output.transform.double(), action, output
            else:
                answer = ensemble_predict(model, batch["action"], batch["anchor"], num_action, num_anchor,
                                          subsets, mirror_views, seed)
                yield batch, answer.transform, batch["action"], answer.first
    finally:
        model.train(was_training)


@torch.no_grad()
def per_sample_errors(
    model: torch.nn.Module,
    dataset: CrossPoseDataset,
    indices: torch.Tensor,
    num_action: int,
    num_anchor: int,
    batch_size: int = 16,
    seed: int = 0,
    subsets: int | None = None,
    mirror_views: bool = DEFAULT_MIRROR_VIEWS,
) -> dict[str, torch.Tensor]:
    """Errors of each sample ``indices`` of ``dataset``: {"rot_deg", "trans_m", "point_m"[, "w"]}, each (len(indices),).

    ``subsets``: None = one subset per sample, as in training; K = as the learned policy answers
    with K subsets (module docstring). NaN predictions give NaN errors; "w" (models that predict a
    mixing weight) is the first subset's mean weight.
    """
    columns: dict[str, list[torch.Tensor]] = {"rot_deg": [], "trans_m": [], "point_m": [], "w": []}
    for batch, T_pred, points, output in predicted_poses(model, dataset, indices, num_action, num_anchor, batch_size,
                                                         seed, subsets, mirror_views):
        if "w" in output.diagnostics:
            columns["w"].append(output.diagnostics["w"].reshape(len(T_pred), -1).mean(dim=1).double())
        T_gt = nearest_goal(T_pred, batch["gt_equivalents"].double())
        pts = points.double()
        columns["rot_deg"].append(metrics.rotation_error_deg(T_pred[:, :3, :3], T_gt[:, :3, :3]))
        columns["trans_m"].append(metrics.translation_error(T_pred, T_gt, pts.mean(dim=1)))
        columns["point_m"].append(metrics.point_error(T_pred, T_gt, pts)[0])
    # "w" only for models that predict a mixing weight.
    return {key: torch.cat(values) if values else torch.zeros(0, dtype=torch.float64)
            for key, values in columns.items() if values or key != "w"}


def evaluate(
    model: torch.nn.Module,
    dataset: CrossPoseDataset,
    kinds: tuple[str, ...],
    per_kind: int,
    num_action: int,
    num_anchor: int,
    batch_size: int = 16,
    seed: int = 0,
    subsets: int | None = None,
    mirror_views: bool = DEFAULT_MIRROR_VIEWS,
) -> dict[str, dict[str, float]]:
    """{kind: {"rot_deg", "trans_m", "point_m", "failures", "n"[, "w"]}} on ``per_kind`` samples of each kind
    spread evenly over the split (fixed subsampling seed, so epochs are comparable; ``subsets`` as in
    :func:`per_sample_errors`).

    Means are over finite predictions; ``failures`` counts samples whose prediction was NaN.
    """
    results: dict[str, dict[str, float]] = {}
    for kind in kinds:
        idx = torch.nonzero(dataset.kind == KIND_CODE[kind]).flatten()
        if len(idx) > per_kind:  # spread over the whole split (consecutive samples share furniture)
            idx = idx[torch.linspace(0, len(idx) - 1, per_kind).round().long()]
        errors = per_sample_errors(model, dataset, idx, num_action, num_anchor, batch_size, seed, subsets,
                                   mirror_views)
        results[kind] = _summarise(errors)
    return results


def evaluate_by_category(
    model: torch.nn.Module,
    dataset: CrossPoseDataset,
    kind: str,
    num_action: int,
    num_anchor: int,
    seed: int = 0,
    subsets: int | None = None,
    mirror_views: bool = DEFAULT_MIRROR_VIEWS,
) -> dict[str, dict[str, float]]:
    """{category: the ``evaluate`` statistics} over every sample of ``kind`` in ``dataset``."""
    idx = torch.nonzero(dataset.kind == KIND_CODE[kind]).flatten()
    errors = per_sample_errors(model, dataset, idx, num_action, num_anchor, seed=seed, subsets=subsets,
                               mirror_views=mirror_views)
    categories = [dataset.categories[i] for i in idx.tolist()]
    out = {}
    for category in sorted(set(categories)):
        mask = torch.tensor([c == category for c in categories])
        out[category] = _summarise({key: value[mask] for key, value in errors.items()})
    return out


def _summarise(errors: dict[str, torch.Tensor]) -> dict[str, float]:
    r, t, p = errors["rot_deg"], errors["trans_m"], errors["point_m"]
    if len(r) == 0:
        return {"rot_deg": math.nan, "trans_m": math.nan, "point_m": math.nan, "failures": 0, "n": 0}
    ok = torch.isfinite(r) & torch.isfinite(t) & torch.isfinite(p)
    mean = lambda x: float(x[ok].mean()) if ok.any() else math.nan  # noqa: E731
    out = {"rot_deg": mean(r), "trans_m": mean(t), "point_m": mean(p), "failures": int((~ok).sum()), "n": int(len(r))}
    if "w" in errors and len(errors["w"]):
        out["w"] = float(errors["w"].mean())
    return out


def mean_point_error(results: dict[str, dict[str, float]]) -> float:
    """Mean over kinds of the point error (the criterion for the best WeightedPose variant)."""
    values = [results[k]["point_m"] for k in KINDS if k in results]
    return float(sum(values) / len(values)) if values else math.nan
