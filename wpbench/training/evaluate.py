"""Validation errors of a model on a dataset, per kind (DESIGN.md metrics).

rotation error (deg), translation error (m, goal position of the action
centroid), point error (m, mean |T_pred p - T_gt p| over the action points),
all against the equivalent goal nearest to the prediction in rotation (for a symmetric
object every equivalent goal is correct; ``wpbench.data.equivalent_goals``).

``subsets`` > 1 answers each sample from that many random subsets of its stored clouds,
fused like the learned policies do (``wpbench.models.subset_ensemble``; with ``mirror_views``
every second one in the mirrored scene); the errors are then measured on every stored action
point. Training validates with one subset.
"""

from __future__ import annotations

import math

import torch

from wpbench.data.config import KIND_CODE, KINDS
from wpbench.data.dataset import CrossPoseDataset
from wpbench.data.equivalent_goals import nearest_goal
from wpbench.geometry import metrics
from wpbench.models import subset_ensemble as ensemble
from wpbench.models.configs import DEFAULT_MIRROR_VIEWS
from wpbench.training.batches import make_batch, subsample_points


@torch.no_grad()
def per_sample_errors(
    model: torch.nn.Module,
    dataset: CrossPoseDataset,
    indices: torch.Tensor,
    num_action: int,
    num_anchor: int,
    batch_size: int = 16,
    seed: int = 0,
    subsets: int = 1,
    mirror_views: bool = DEFAULT_MIRROR_VIEWS,
) -> dict[str, torch.Tensor]:
    """Errors of each sample ``indices`` of ``dataset``: {"rot_deg", "trans_m", "point_m"[, "w"]}, each (len(indices),).

    The clouds are subsampled to the model's point counts with a fixed seed (``subsets`` times,
    fused, when > 1). NaN predictions give NaN errors.
    """
    if subsets < 1:
        raise ValueError(f"subsets must be >= 1, got {subsets}")
    was_training = model.training
    model.eval()
    generator = torch.Generator().manual_seed(seed)
    columns: dict[str, list[torch.Tensor]] = {"rot_deg": [], "trans_m": [], "point_m": [], "w": []}
    try:
        for start in range(0, len(indices), batch_size):
            batch = make_batch(dataset, indices[start:start + batch_size])
            action = subsample_points(batch["action"], num_action, generator)
            anchor = subsample_points(batch["anchor"], num_anchor, generator)
            output = model(action, anchor)
            T_pred = output.transform.double()
            count = ensemble.subsets_worth_drawing(subsets, (batch["action"].shape[1], batch["anchor"].shape[1]),
                                                   (num_action, num_anchor))
            if count > 1:
                views = ensemble.view_transforms(count, mirror_views)
                more = []
                for view in views[1:, None]:  # the first subset was answered as observed
                    seen = [ensemble.into_view(subsample_points(batch[key], n, generator)[None], view)[0]
                            for key, n in (("action", num_action), ("anchor", num_anchor))]
                    more.append(ensemble.out_of_view(model(*seen).transform.double()[None], view)[0])
                action = batch["action"]
                T_pred = ensemble.fuse_goal_clouds(action.double(), torch.stack([T_pred, *more]))
            if "w" in output.diagnostics:
                columns["w"].append(output.diagnostics["w"].reshape(len(T_pred), -1).mean(dim=1).double())
            T_gt = nearest_goal(T_pred, batch["gt_equivalents"].double())
            pts = action.double()
            columns["rot_deg"].append(metrics.rotation_error_deg(T_pred[:, :3, :3], T_gt[:, :3, :3]))
            columns["trans_m"].append(metrics.translation_error(T_pred, T_gt, pts.mean(dim=1)))
            columns["point_m"].append(metrics.point_error(T_pred, T_gt, pts)[0])
    finally:
        model.train(was_training)
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
    subsets: int = 1,
    mirror_views: bool = DEFAULT_MIRROR_VIEWS,
) -> dict[str, dict[str, float]]:
    """{kind: {"rot_deg", "trans_m", "point_m", "failures", "n"[, "w"]}} on ``per_kind`` samples of each kind
    spread evenly over the split (fixed subsampling seed, so epochs are comparable).

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
    subsets: int = 1,
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
