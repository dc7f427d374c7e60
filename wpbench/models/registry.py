"""Find a cross-pose model by name: ``build_model("weightedpose", w_mode="per_point")``.

Importing this module does not import torch; ``build_model`` imports the
model module it needs.
"""

from __future__ import annotations

import dataclasses
import importlib
from typing import Any

from wpbench.models.configs import (
    GOALFLOW_FIELDS_BEFORE_DEFAULT_CHANGE,
    GoalFlowConfig,
    TaxPoseConfig,
    WeightedPoseConfig,
    apply_overrides,
)

MODEL_CONFIGS: dict[str, type] = {
    "taxpose": TaxPoseConfig,
    "goalflow": GoalFlowConfig,
    "weightedpose": WeightedPoseConfig,
}
"""Model name -> its config dataclass."""

_MODEL_CLASSES: dict[str, tuple[str, str]] = {
    "taxpose": ("wpbench.models.taxpose", "TaxPose"),
    "goalflow": ("wpbench.models.goalflow", "GoalFlow"),
    "weightedpose": ("wpbench.models.weightedpose", "WeightedPose"),
}


def _check_name(name: str) -> None:
    if name not in MODEL_CONFIGS:
        raise ValueError(f"unknown model {name!r}; choose one of {sorted(MODEL_CONFIGS)}")


def model_config(name: str, config: Any | None = None, **overrides: Any) -> Any:
    """The config of model ``name``: ``config`` (or the default) with ``overrides`` applied.

    Nested configs take dicts: ``model_config("taxpose", encoder={"k": 8})``.
    """
    _check_name(name)
    base = config if config is not None else MODEL_CONFIGS[name]()
    if not isinstance(base, MODEL_CONFIGS[name]):
        raise ValueError(f"model {name!r} takes a {MODEL_CONFIGS[name].__name__}, got {type(base).__name__}")
    return apply_overrides(base, overrides)


def saved_model_config(name: str, saved: dict[str, Any]) -> Any:
    """The config of a saved model (the ``model_config`` dict of its config.json).

    A field the saved dict lacks takes its default, except the Goal Flow fields of
    ``GOALFLOW_FIELDS_BEFORE_DEFAULT_CHANGE``, which take the value listed there, so
    that every saved model loads as the network it was trained as.
    """
    _check_name(name)
    base = MODEL_CONFIGS[name]()
    before = GOALFLOW_FIELDS_BEFORE_DEFAULT_CHANGE
    if name == "goalflow":
        base = dataclasses.replace(base, **before)
    elif name == "weightedpose":
        base = dataclasses.replace(base, goalflow=dataclasses.replace(base.goalflow, **before))
    return apply_overrides(base, saved)


def model_class(name: str) -> type:
    """The nn.Module class of model ``name`` (imports its module)."""
    _check_name(name)
    module_name, class_name = _MODEL_CLASSES[name]
    return getattr(importlib.import_module(module_name), class_name)


def build_model(name: str, config: Any | None = None, **overrides: Any):
    """A freshly initialised model ``name`` ("taxpose", "goalflow", "weightedpose").

    ``config``: a full config (default: the laptop-sized default); ``overrides``
    change fields of it (unknown fields raise ValueError listing valid ones).
    """
    return model_class(name)(model_config(name, config, **overrides))
