"""Training and validation batches: shuffling, point subsampling, augmentation.

Point subsampling keeps a random subset of each stored cloud (the stored
clouds are farthest-point samples, so a random subset of them is still spread
over the object). :func:`subsample_points` is also what the learned policies
use on their observations, with a fixed generator, so models see clouds of the
same density in training and in the benchmark.
"""

from __future__ import annotations

from collections.abc import Iterator

import torch

from wpbench.data.augment import random_scale, random_slide_stretch, random_yaw
from wpbench.data.dataset import CrossPoseDataset


def subsample_points(points: torch.Tensor, n: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """(B, N, 3) -> (B, n, 3): a random subset of n points per cloud (all N if n >= N)."""
    B, N, _ = points.shape
    if n >= N:
        return points
    order = torch.rand(B, N, generator=generator).argsort(dim=1)[:, :n]
    return torch.gather(points, 1, order.unsqueeze(-1).expand(-1, -1, 3))


def make_batch(dataset: CrossPoseDataset, indices: torch.Tensor) -> dict[str, torch.Tensor]:
    """Stack the samples ``indices`` of ``dataset`` into model-ready tensors."""
    return {
        "action": dataset.action[indices],
        "anchor": dataset.anchor[indices],
        "gt_transform": dataset.gt_transform[indices],
        "gt_equivalents": dataset.gt_equivalents[indices],
        "kind": dataset.kind[indices],
    }


def prepare(
    batch: dict[str, torch.Tensor], num_action: int, num_anchor: int, augment: bool, generator: torch.Generator,
    mirror: bool = False, scale: float = 0.0, stretch: float = 0.0,
) -> dict[str, torch.Tensor]:
    """Subsample both clouds and (optionally) rotate the scene by a random yaw, mirrored half the time,
    stretch sliding samples along their slide by a factor in [1 - stretch, 1 + stretch], and scale
    the scene by a random factor in [1 - scale, 1 + scale] (each off at 0)."""
    out = dict(batch)
    out["action"] = subsample_points(batch["action"], num_action, generator)
    out["anchor"] = subsample_points(batch["anchor"], num_anchor, generator)
    if augment:
        out = random_yaw(out, generator, mirror)
    if stretch > 0:
        out = random_slide_stretch(out, stretch, generator)
    return random_scale(out, scale, generator) if scale > 0 else out


def shuffled_batches(size: int, batch_size: int, generator: torch.Generator) -> Iterator[torch.Tensor]:
    """Endless stream of index batches, reshuffled after every pass (last partial batch dropped
    unless the dataset is smaller than one batch)."""
    if size < 1:
        raise ValueError("cannot draw batches from an empty dataset")
    while True:
        order = torch.randperm(size, generator=generator)
        if size < batch_size:
            yield order
            continue
        for start in range(0, size - batch_size + 1, batch_size):
            yield order[start:start + batch_size]
