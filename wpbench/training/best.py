"""Which WeightedPose variant the ``wp`` alias means: ``policies/weights/best.json``.

Criterion: the lowest mean validation point error over both kinds (from each
variant's ``metrics.json``). Written after every WeightedPose training run and
by ``wpbench train --select-best``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from wpbench.training.artifacts import METRICS_FILE, atomic_write_text
from wpbench.training.specs import WEIGHTED_POSE_VARIANTS

BEST_FILE = "best.json"
CRITERION = "val_mean_point_m"


def select_best(weights_root: Path) -> dict | None:
    """Write ``best.json`` naming the best trained variant; None (and no file) if none is trained."""
    weights_root = Path(weights_root)
    candidates: dict[str, float] = {}
    for name in WEIGHTED_POSE_VARIANTS:
        path = weights_root / name / METRICS_FILE
        if not path.is_file():
            continue
        try:
            value = float(json.loads(path.read_text())[CRITERION])
        except (ValueError, KeyError, TypeError, json.JSONDecodeError):
            continue
        if math.isfinite(value):
            candidates[name] = value
    if not candidates:
        return None
    best = min(candidates, key=candidates.get)
    record = {"policy": best, "criterion": f"{CRITERION} (lower is better)", "candidates": candidates}
    atomic_write_text(weights_root / BEST_FILE, json.dumps(record, indent=2, sort_keys=True) + "\n")
    return record
