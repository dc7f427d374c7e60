"""Cross-object attention: action points attend to anchor points and vice versa.

TAX-Pose mixes each object's DGCNN embeddings with the other object's through
a transformer; this module is that mixing in pre-norm transformer style
(LayerNorm per point, so no sample sees the rest of its batch). Both
directions in a layer read the embeddings from before the layer, so the
result does not depend on which direction is computed first.
"""

from __future__ import annotations

import torch
from torch import nn


class CrossAttentionBlock(nn.Module):
    """queries (B, NQ, D) attend to context (B, NC, D) -> (B, NQ, D); attention + FFN, residual."""

    def __init__(self, dim: int, heads: int, ffn_mult: int) -> None:
        super().__init__()
        self.query_norm = nn.LayerNorm(dim)
        self.context_norm = nn.LayerNorm(dim)
        self.attention = nn.MultiheadAttention(dim, heads, batch_first=True)
        self.ffn_norm = nn.LayerNorm(dim)
        self.ffn = nn.Sequential(nn.Linear(dim, ffn_mult * dim), nn.GELU(), nn.Linear(ffn_mult * dim, dim))

    def forward(self, queries: torch.Tensor, context: torch.Tensor) -> torch.Tensor:
        context_normed = self.context_norm(context)
        attended, _ = self.attention(self.query_norm(queries), context_normed, context_normed, need_weights=False)
        x = queries + attended
        return x + self.ffn(self.ffn_norm(x))


class BidirectionalCrossAttention(nn.Module):
    """(action (B, NA, D), anchor (B, NB, D)) -> both updated by attending to each other."""

    def __init__(self, dim: int, heads: int, ffn_mult: int, layers: int) -> None:
        super().__init__()
        self.action_blocks = nn.ModuleList(CrossAttentionBlock(dim, heads, ffn_mult) for _ in range(layers))
        self.anchor_blocks = nn.ModuleList(CrossAttentionBlock(dim, heads, ffn_mult) for _ in range(layers))

    def forward(self, action: torch.Tensor, anchor: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        for action_block, anchor_block in zip(self.action_blocks, self.anchor_blocks):
            action, anchor = action_block(action, anchor), anchor_block(anchor, action)
        return action, anchor
