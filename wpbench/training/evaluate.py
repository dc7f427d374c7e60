"""Validation errors of a model on a dataset, per kind (DESIGN.md metrics).

rotation error (deg, no symmetry: free-object targets are already the
least-rotation equivalent, see ``wpbench.data.generate``), translation error (m,
goal position of the action centroid), point error (m, mean |T_pred p - T_gt p|
over the action points).
"""

from __future__ import annotations

import math

import torch

from wpbench.data.config import KIND_CODE, KINDS
from wpbench.data.dataset import CrossPoseDataset
from wpbench.geometry import metrics
from wpbench.training.batches import make_batch, subsample_points


@torch.no_grad()
def evaluate(
    model: torch.nn.Module,
    dataset: CrossPoseDataset,
    kinds: tuple[str, ...],
    per_kind: int,
    num_action: int,
    num_anchor: int,
    batch_size: int = 16,
    seed: int = 0,
) -> dict[str, dict[str, float]]:
    """{kind: {"rot_deg", "trans_m", "point_m", "failures", "n"[, "w"]}} on ``per_kind`` samples of each kind
    spread evenly over the split (fixed subsampling seed, so epochs are comparable).

    Means are over finite predictions; ``failures`` counts samples whose prediction was NaN.
    """
    was_training = model.training
    model.eval()
    generator = torch.Generator().manual_seed(seed)
    results: dict[str, dict[str, float]] = {}
    try:
        for kind in kinds:
            idx = torch.nonzero(dataset.kind == KIND_CODE[kind]).flatten()
            if len(idx) > per_kind:  # spread over the whole split (consecutive samples share furniture)
                idx = idx[torch.linspace(0, len(idx) - 1, per_kind).round().long()]
            rot, trans, point, w = [], [], [], []
            for start in range(0, len(idx), batch_size):
                batch = make_batch(dataset, idx[start:start + batch_size])
                action = subsample_points(batch["action"], num_action, generator)
                anchor = subsample_points(batch["anchor"], num_anchor, generator)
                output = model(action, anchor)
                T_pred = output.transform.double()
                if "w" in output.diagnostics:
                    w.append(output.diagnostics["w"].reshape(len(T_pred), -1).mean(dim=1).double())
                T_gt = batch["gt_transform"].double()
                pts = action.double()
                rot.append(metrics.rotation_error_deg(T_pred[:, :3, :3], T_gt[:, :3, :3]))
                trans.append(metrics.translation_error(T_pred, T_gt, pts.mean(dim=1)))
                point.append(metrics.point_error(T_pred, T_gt, pts)[0])
            results[kind] = _summarise(rot, trans, point)
            if w:
                results[kind]["w"] = float(torch.cat(w).mean())
    finally:
        model.train(was_training)
    return results


def _summarise(rot: list[torch.Tensor], trans: list[torch.Tensor], point: list[torch.Tensor]) -> dict[str, float]:
    if not rot:
        return {"rot_deg": math.nan, "trans_m": math.nan, "point_m": math.nan, "failures": 0, "n": 0}
    r, t, p = torch.cat(rot), torch.cat(trans), torch.cat(point)
    ok = torch.isfinite(r) & torch.isfinite(t) & torch.isfinite(p)
    mean = lambda x: float(x[ok].mean()) if ok.any() else math.nan  # noqa: E731
    return {"rot_deg": mean(r), "trans_m": mean(t), "point_m": mean(p),
            "failures": int((~ok).sum()), "n": int(len(r))}


def mean_point_error(results: dict[str, dict[str, float]]) -> float:
    """Mean over kinds of the point error (the criterion for the best WeightedPose variant)."""
    values = [results[k]["point_m"] for k in KINDS if k in results]
    return float(sum(values) / len(values)) if values else math.nan
