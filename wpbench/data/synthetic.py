"""A tiny synthetic split (no simulator): random boxes of points and random cross-poses.

For tests and smoke runs of the trainer only; nothing is learnable about
furniture from it. ``write_synthetic_split(root, "train", per_kind=4)`` writes
shards and a manifest exactly as ``wpbench data generate`` would.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wpbench.data.config import KIND_CODE, KINDS, GenerationConfig
from wpbench.data.manifest import build_manifest, split_dir, write_manifest
from wpbench.data.shards import shard_path, stack_samples, write_shard


def _random_cross_pose(rng: np.random.Generator) -> np.ndarray:
    yaw = rng.uniform(-np.pi, np.pi)
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = rng.uniform(-0.3, 0.3, size=3)
    return T


def write_synthetic_split(root: Path, split: str, per_kind: int = 4, num_action_points: int = 64,
                          num_anchor_points: int = 128, seed: int = 0) -> dict:
    """Write ``per_kind`` samples of each kind under ``root/split`` (one shard per kind); returns the manifest."""
    rng = np.random.default_rng(seed)
    config = GenerationConfig(split=split, obs="mesh", seed=seed, samples_per_kind=per_kind, shard_size=per_kind,
                              scene_reuse=1, num_action_points=num_action_points,
                              num_anchor_points=num_anchor_points, extra={"synthetic": True})
    directory = split_dir(root, split)
    for kind in KINDS:
        samples = []
        for i in range(per_kind):
            action = rng.uniform(-0.1, 0.1, size=(num_action_points, 3)) + rng.uniform(-0.5, 0.5, size=3)
            anchor = rng.uniform(-0.4, 0.4, size=(num_anchor_points, 3))
            T = _random_cross_pose(rng)
            samples.append({
                "action_points": action, "anchor_points": anchor, "gt_transform": T, "gt_transform_raw": T,
                "action_pose": np.eye(4),
                "kind": KIND_CODE[kind], "category": "synthetic", "object_id": f"synthetic-{i % 2}",
                "free_object": "" if kind == KINDS[0] else "synthetic", "seed": i,
                "start_fraction": 0.1 if kind == KINDS[0] else np.nan, "camera_fallback": False,
            })
        write_shard(shard_path(directory, kind, 0), stack_samples(samples, config.sample_fingerprint()))
    manifest = build_manifest(directory, config)
    write_manifest(directory, manifest)
    return manifest
