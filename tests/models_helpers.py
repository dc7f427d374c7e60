"""Shared scenes and small model configs for the tests/test_models_*.py files.

Small widths and point counts keep every test fast; the architecture is the
same as at the default size.
"""

from __future__ import annotations

import math
from functools import lru_cache

import torch

from wpbench.geometry import se3
from wpbench.models import build_model

SMALL_ENCODER = {"k": 8, "edge_channels": (16, 16, 32), "emb_dim": 32, "groups": 4}
MODEL_NAMES = ("taxpose", "goalflow", "weightedpose")


def small_overrides(name: str, dynamic_graph: bool = False, **extra) -> dict:
    encoder = {**SMALL_ENCODER, "dynamic_graph": dynamic_graph}
    branch = {"encoder": encoder, "head_hidden": 32}
    if name == "weightedpose":
        return {"taxpose": branch, "goalflow": branch, **extra}
    return {**branch, **extra}


@lru_cache(maxsize=None)
def small_model(name: str, dynamic_graph: bool = False, seed: int = 0, dtype: torch.dtype = torch.float64):
    """A small model in eval mode (cached: treat it as read-only)."""
    torch.manual_seed(seed)
    return build_model(name, **small_overrides(name, dynamic_graph)).to(dtype).eval()


def scene(batch: int = 1, action_points: int = 48, anchor_points: int = 96, seed: int = 0, dtype=torch.float32):
    """A box-like action object near a larger anchor, and a true cross-pose.

    Returns dict(action (B,NA,3), anchor (B,NB,3), gt_transform (B,4,4)); the
    goal is a 34-degree turn about z plus ~30 cm of translation.
    """
    g = torch.Generator().manual_seed(seed)
    action = (torch.rand(batch, action_points, 3, generator=g) - 0.5) * torch.tensor([0.1, 0.06, 0.04])
    action = action + torch.tensor([0.5, 0.0, 0.1])
    anchor = (torch.rand(batch, anchor_points, 3, generator=g) - 0.5) * torch.tensor([0.4, 0.4, 0.3])
    anchor = anchor + torch.tensor([0.0, 0.2, 0.15])
    half = 0.3
    quat = torch.tensor([[math.cos(half), 0.0, 0.0, math.sin(half)]]).expand(batch, 4)
    T_gt = se3.make_transform(se3.quat_wxyz_to_matrix(quat), torch.tensor([[-0.3, 0.1, 0.05]]).expand(batch, 3))
    return {"action": action.to(dtype), "anchor": anchor.to(dtype), "gt_transform": T_gt.to(dtype)}
