"""Cross-pose models: TAX-Pose, Goal Flow and WeightedPose, their losses and presets.

``build_model(name, **overrides)`` (names in ``MODEL_CONFIGS``) builds a model;
``model(action (B,NA,3), anchor (B,NB,3)) -> CrossPoseOutput``;
``compute_loss(output, batch, preset)`` trains it. Torch-heavy modules are
imported on first attribute access, so ``import wpbench.models`` stays cheap.
"""

from __future__ import annotations

import importlib
from typing import Any

from wpbench.models.configs import DGCNNConfig, GoalFlowConfig, TaxPoseConfig, WeightedPoseConfig
from wpbench.models.registry import MODEL_CONFIGS, build_model, model_class, model_config

_LAZY = {
    "CrossPoseOutput": "wpbench.models.output",
    "TaxPose": "wpbench.models.taxpose",
    "GoalFlow": "wpbench.models.goalflow",
    "WeightedPose": "wpbench.models.weightedpose",
    "compute_loss": "wpbench.models.loss_presets",
    "LossPreset": "wpbench.models.loss_presets",
    "LOSS_PRESETS": "wpbench.models.loss_presets",
}

__all__ = [
    "DGCNNConfig",
    "GoalFlowConfig",
    "MODEL_CONFIGS",
    "TaxPoseConfig",
    "WeightedPoseConfig",
    "build_model",
    "model_class",
    "model_config",
    *_LAZY,
]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'wpbench.models' has no attribute {name!r}")
