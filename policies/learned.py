"""Learned policies: a trained cross-pose model loaded from ``policies/weights/<name>/``.

``gf`` (Goal Flow), ``tp`` (TAX-Pose), ``wp-og`` / ``wp-postsvd`` / ``wp-postsvd-t``
(WeightedPose variants) are all a :class:`LearnedPolicy` with a different
``policy`` name; ``wp`` is the variant named in ``policies/weights/best.json``.
Weights come from ``wpbench train --policy NAME`` and ``wpbench train --promote RUN``
(``wpbench.weights``: loading, hashing, promotion, best.json).

The model was trained on random subsets of the stored clouds
(``config.json``: ``num_action_points`` / ``num_anchor_points``), so each
observation is subsampled the same way (fixed seed: the same observation gives
the same answer). ``subsets`` such subsets are answered in one batch and fused
into one pose, every second one in the scene mirrored in y = 0 (``mirror_views``):
``wpbench.models.subset_ensemble.ensemble_predict``, the same function the pose-error
tables use (1 subset = a single pass). The
per-point diagnostics are those of the first subset, mapped back to every observed
point by nearest kept neighbour (their displacement is copied), so a recorder can
draw them over the full cloud.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from wpbench.models.configs import DEFAULT_MIRROR_VIEWS, DEFAULT_SUBSETS
from wpbench.policies.base import Policy, PolicyConfig, PolicyOutput
from wpbench.weights import BEST_FILE, best_weighted_pose, weights_root_or_shipped
# diagnostic -> which cloud it is per-point on, and whether it is a position (expanded as a displacement)
_PER_POINT = {
    "flow": ("action", False),
    "action_targets": ("action", True),
    "action_weights": ("action", False),
    "anchor_sources": ("anchor", True),
    "anchor_weights": ("anchor", False),
}


@dataclass
class LearnedPolicyConfig(PolicyConfig):
    """policy: the trained policy's name (its folder under ``weights_root``).
    weights_root: where trained policies live [default: ``policies/weights``].
    seed: seed of the observation subsampling.
    subsets: random subsets of the observation answered and fused into one pose (>= 1).
    mirror_views: answer every second subset in the mirrored scene."""

    name: ClassVar[str] = "learned"
    policy: str = "wp-postsvd-t"
    weights_root: Path | None = None
    seed: int = 0
    subsets: int = DEFAULT_SUBSETS
    mirror_views: bool = DEFAULT_MIRROR_VIEWS

    def __post_init__(self) -> None:
        if int(self.subsets) < 1:
            raise ValueError(f"subsets must be >= 1, got {self.subsets}")
        self.subsets = int(self.subsets)

    @property
    def weights_dir(self) -> Path:
        return weights_root_or_shipped(self.weights_root) / self.policy


class LearnedPolicy(Policy):
    """A trained model as a policy. Missing/corrupt weights: FileNotFoundError / ValueError
    naming ``wpbench train --policy NAME``."""

    default_policy: ClassVar[str] = "wp-postsvd-t"

    def __init__(self, config: LearnedPolicyConfig | None = None, **kwargs: Any) -> None:
        if config is None:
            kwargs.setdefault("policy", self.default_policy)
            config = LearnedPolicyConfig(**kwargs)
        elif kwargs:
            raise ValueError("give either a config or keyword arguments, not both")
        self.config = config
        from wpbench.models import subset_ensemble
        from wpbench.weights import load_trained_model

        self._ensemble = subset_ensemble
        self.model, self.model_config = load_trained_model(config.weights_dir, config.policy)
        self.num_action_points = int(self.model_config["num_action_points"])
        self.num_anchor_points = int(self.model_config["num_anchor_points"])

    def describe(self) -> dict[str, Any]:
        return {
            "policy": self.config.policy,
            "config": {"policy": self.config.policy, "weights_dir": str(self.config.weights_dir), "seed": self.config.seed,
                       "subsets": self.config.subsets, "mirror_views": self.config.mirror_views},
            "model": self.model_config.get("model"),
            "loss_preset": self.model_config.get("loss_preset"),
            "model_hash": self.model_config.get("model_hash"),
            "data": self.model_config.get("data"),
        }

    def predict(self, obs: dict[str, Any], info: dict[str, Any] | None = None) -> PolicyOutput:
        action = _cloud(obs, "action_points")
        anchor = _cloud(obs, "anchor_points")
        answer = self._ensemble.ensemble_predict(self.model, action, anchor, self.num_action_points,
                                                 self.num_anchor_points, self.config.subsets,
                                                 self.config.mirror_views, self.config.seed)
        transform, out, picks = answer.transform.numpy(), answer.first, answer.picks
        ia, ib = picks[0]
        clouds = {"action": (action, ia), "anchor": (anchor, ib)}
        diagnostics: dict[str, Any] = {}
        for key, value in out.diagnostics.items():
            arr = value[0].double().numpy()
            if key in _PER_POINT:
                which, is_position = _PER_POINT[key]
                full, kept = clouds[which]
                arr = _expand(arr, full, kept, is_position)
            diagnostics[key] = arr
        return PolicyOutput(transform, diagnostics)


def _cloud(obs: dict[str, Any], key: str) -> np.ndarray:
    if key not in obs:
        raise ValueError(f"observation lacks {key!r} (an (N, 3) point cloud)")
    points = np.asarray(obs[key], dtype=np.float32)
    if points.ndim == 3 and points.shape[0] == 1:
        points = points[0]
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise ValueError(f"obs[{key!r}] must be a non-empty (N, 3) array, got shape {points.shape}")
    if not np.all(np.isfinite(points)):
        raise ValueError(f"obs[{key!r}] contains NaN or inf")
    return np.ascontiguousarray(points)


def _expand(values: np.ndarray, full: np.ndarray, kept: np.ndarray, is_position: bool) -> np.ndarray:
    """Per-kept-point values -> per-point values on the full cloud, from each point's nearest kept point.

    Positions are moved with the point (``value_j + p_i - p_j``); weights are renormalised
    to keep their sum.
    """
    if len(kept) == len(full):
        return values
    from scipy.spatial import cKDTree

    nearest = kept[cKDTree(full[kept]).query(full)[1]] if len(kept) else kept
    slot = np.searchsorted(kept, nearest)
    expanded = values[slot]
    if is_position:
        expanded = expanded + (full - full[nearest])
    elif values.ndim == 1 and np.all(values >= 0) and values.sum() > 0:
        expanded = expanded * (values.sum() / expanded.sum())
    return expanded


class GoalFlowPolicy(LearnedPolicy):
    default_policy = "gf"


class TaxPosePolicy(LearnedPolicy):
    default_policy = "tp"


class WeightedPoseOGPolicy(LearnedPolicy):
    default_policy = "wp-og"


class WeightedPosePostSVDPolicy(LearnedPolicy):
    default_policy = "wp-postsvd"


class WeightedPosePostSVDTPolicy(LearnedPolicy):
    default_policy = "wp-postsvd-t"


class BestWeightedPosePolicy(LearnedPolicy):
    """``wp``: the best WeightedPose variant (``best.json``; ``wpbench.weights.FALLBACK_WEIGHTED_POSE``
    if there is none)."""

    def __init__(self, config: LearnedPolicyConfig | None = None, **kwargs: Any) -> None:
        if config is None and "policy" not in kwargs:
            root = kwargs.get("weights_root")
            chosen = best_weighted_pose(root)
            try:
                super().__init__(policy=chosen, **kwargs)
            except FileNotFoundError as err:
                has_best = (weights_root_or_shipped(root) / BEST_FILE).is_file()
                source = BEST_FILE if has_best else "the fallback (no best.json)"
                raise FileNotFoundError(
                    f"wp is an alias of {chosen!r} ({source}), whose weights are missing: {err}. "
                    "Train the WeightedPose variants (`wpbench train --policy wp-postsvd-t`, ...), "
                    "then `wpbench train --select-best`"
                ) from err
        else:
            super().__init__(config, **kwargs)

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d["alias_of"] = self.config.policy
        d["policy"] = "wp"
        return d
