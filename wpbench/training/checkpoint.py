"""The full training state in ``checkpoint.pt``: enough to resume after an interruption.

Saved after every epoch (atomically): model and optimiser state, epoch, step,
accumulated training seconds, the log rows so far, the random states (torch
global, the batch generator, numpy, python) and what the run trained on
(policy, data hash), so a resume with other data is refused instead of mixed.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wpbench.weights import atomic_torch_save

CHECKPOINT_FILE = "checkpoint.pt"


def save_checkpoint(out: Path, state: dict[str, Any]) -> Path:
    """``state`` plus the global random states -> ``out/checkpoint.pt``."""
    path = Path(out) / CHECKPOINT_FILE
    full = dict(state)
    full["rng"] = {
        "torch": torch.get_rng_state(),
        "numpy": np.random.get_state(),
        "python": random.getstate(),
    }
    atomic_torch_save(full, path)
    return path


def load_checkpoint(out: Path) -> dict[str, Any] | None:
    """The checkpoint in ``out`` (global random states restored), or None if there is none."""
    path = Path(out) / CHECKPOINT_FILE
    if not path.is_file():
        return None
    try:
        state = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as err:  # noqa: BLE001 - a truncated or foreign file
        raise ValueError(f"{path} is corrupt ({err}); delete it or pass --restart to train from scratch") from err
    rng = state.get("rng", {})
    if "torch" in rng:
        torch.set_rng_state(rng["torch"])
    if "numpy" in rng:
        np.random.set_state(rng["numpy"])
    if "python" in rng:
        random.setstate(rng["python"])
    return state
