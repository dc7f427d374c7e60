"""The files a trained policy is made of, under ``policies/weights/<policy>/``:

- ``model.pt``: the model's ``state_dict`` (float32 tensors only, loaded with ``weights_only``);
- ``config.json``: model name + full model config + loss preset + the point counts it
  was trained with + the data manifest hashes;
- ``metrics.json``: final validation errors by kind, wall time, peak memory.

``load_trained_model`` is what the learned policies and the WeightedPose warm start use.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any

import torch

from wpbench.models.registry import build_model, saved_model_config

FORMAT_VERSION = 1
MODEL_FILE, CONFIG_FILE, METRICS_FILE = "model.pt", "config.json", "metrics.json"


def atomic_write_text(path: Path, text: str) -> None:
    path = Path(path)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def atomic_torch_save(obj: Any, path: Path) -> None:
    path = Path(path)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def config_to_json(config: Any) -> dict:
    """A model config dataclass -> JSON-able dict (tuples become lists)."""
    return json.loads(json.dumps(dataclasses.asdict(config)))


def save_final(out: Path, model: torch.nn.Module, description: dict, metrics: dict) -> None:
    """Write model.pt (float32 state_dict), config.json and metrics.json into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().to(torch.float32).contiguous().clone() if v.is_floating_point() else v.detach().clone()
             for k, v in model.state_dict().items()}
    atomic_torch_save(state, out / MODEL_FILE)
    atomic_write_text(out / CONFIG_FILE, json.dumps({"format": FORMAT_VERSION, **description}, indent=2, sort_keys=True) + "\n")
    atomic_write_text(out / METRICS_FILE, json.dumps(metrics, indent=2, sort_keys=True) + "\n")


def _train_command(policy: str) -> str:
    return f"`wpbench train --policy {policy}`"


def read_config(weights_dir: Path, policy: str | None = None) -> dict:
    """``config.json`` of a trained policy; clear errors naming the command that makes it."""
    weights_dir = Path(weights_dir)
    policy = policy or weights_dir.name
    path = weights_dir / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"no trained weights for {policy!r}: {path} is missing; make them with {_train_command(policy)}")
    try:
        config = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{path} is corrupt ({err}); retrain with {_train_command(policy)}") from err
    if not isinstance(config, dict) or config.get("format") != FORMAT_VERSION or "model" not in config:
        raise ValueError(f"{path} is not a wpbench model config (format {FORMAT_VERSION}); retrain with {_train_command(policy)}")
    return config


def load_state(weights_dir: Path, policy: str | None = None) -> dict[str, torch.Tensor]:
    """``model.pt`` of a trained policy as a state_dict."""
    weights_dir = Path(weights_dir)
    policy = policy or weights_dir.name
    path = weights_dir / MODEL_FILE
    if not path.is_file():
        raise FileNotFoundError(f"no trained weights for {policy!r}: {path} is missing; make them with {_train_command(policy)}")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001 - any unpickling failure means a corrupt file
        reason = (str(err).strip().splitlines() or [type(err).__name__])[-1][:200]
        raise ValueError(f"{path} is corrupt or not a model file ({reason}); retrain with {_train_command(policy)}") from err
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise ValueError(f"{path} does not hold a state_dict; retrain with {_train_command(policy)}")
    return state


def build_from_config(config: dict) -> torch.nn.Module:
    """A freshly initialised model as described by a ``config.json`` dict."""
    cfg = saved_model_config(config["model"], config["model_config"])
    return build_model(config["model"], config=cfg)


def load_trained_model(weights_dir: Path, policy: str | None = None) -> tuple[torch.nn.Module, dict]:
    """(model in eval mode with its trained weights, its config.json dict)."""
    policy = policy or Path(weights_dir).name
    config = read_config(weights_dir, policy)
    try:
        model = build_from_config(config)
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{Path(weights_dir) / CONFIG_FILE} describes no buildable model ({err}); "
                         f"retrain with {_train_command(policy)}") from err
    state = load_state(weights_dir, policy)
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as err:
        raise ValueError(f"{Path(weights_dir) / MODEL_FILE} does not match its config.json ({err}); "
                         f"retrain with {_train_command(policy)}") from err
    model.eval()
    return model, config
