"""Small per-point MLP heads shared by the models."""

from __future__ import annotations

from torch import nn


def head_mlp(in_features: int, hidden: int, out_features: int, zero_output: bool = True) -> nn.Sequential:
    """Linear -> GELU -> Linear, applied to the last dimension of (..., in_features).

    zero_output: start the output layer at zero, so a freshly built model
    predicts zero residual flow / zero flow / uniform weights / w = 0.5 and
    its first SVDs see the geometry-only solution instead of random offsets.
    """
    head = nn.Sequential(nn.Linear(in_features, hidden), nn.GELU(), nn.Linear(hidden, out_features))
    if zero_output:
        nn.init.zeros_(head[-1].weight)
        nn.init.zeros_(head[-1].bias)
    return head
