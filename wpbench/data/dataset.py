"""A torch ``Dataset`` over one split directory, every sample held in memory.

Memory: a sample is (NA + NB) * 3 float32 (~15 KB at 256 + 1024 points), so a
few thousand samples fit easily; loading once avoids re-reading npz files
every epoch.

Item (one sample): ``action`` (NA, 3) float32, ``anchor`` (NB, 3) float32,
``gt_transform`` (4, 4) float32, ``kind`` () int64 (0 articulated, 1 free),
``index`` () int64 (position in the dataset). ``gt_equivalents`` (N, K, 4, 4)
float32 holds every sample's equally correct goals (``equivalent_goals``; row 0
is ``gt_transform``, short rows repeat it; K = 1 for data without symmetric
objects or made before shards stored ``action_pose``). ``categories`` / ``object_ids``
are kept as lists beside the tensors for per-category reporting; ``content_hash``
identifies exactly the samples loaded: the fingerprint and, per shard loaded, its path,
kind, count and the sha256 of its arrays (``shards.array_digest``, computed from the arrays
read, so a manifest written before shards stored digests gives the same hash). A resumed
training run checks it.

``ConcatenatedSamples`` holds several such datasets as one (a training that mixes data
sets, ``wpbench.training.data_mix``).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from wpbench.data.config import KIND_CODE, KINDS
from wpbench.data.equivalent_goals import equivalent_goals
from wpbench.data.manifest import check_not_test_data, read_manifest
from wpbench.data.shards import DIGEST_KEY, array_digest, read_shard


class CrossPoseDataset(Dataset):
    """Samples of ``kinds`` in ``directory`` (a split directory with a manifest).

    A train/ or val/ directory holding test data, or samples of objects its split file
    now holds out, is refused (``manifest.check_not_test_data``): training never reads test data.

    limit_per_kind: keep only the first N samples of each kind (in manifest order).
    """

    def __init__(self, directory: Path, kinds: tuple[str, ...] = KINDS, limit_per_kind: int | None = None) -> None:
        unknown = [k for k in kinds if k not in KINDS]
        if unknown or not kinds:
            raise ValueError(f"kinds must be a non-empty subset of {KINDS}, got {kinds!r}")
        self.directory = Path(directory)
        self.manifest = read_manifest(self.directory)
        parts: dict[str, list[dict[str, np.ndarray]]] = {k: [] for k in kinds}
        used = []
        for entry in self.manifest["shards"]:
            if entry["kind"] in parts:
                shard = read_shard(self.directory / entry["path"])
                parts[entry["kind"]].append(shard)
                used.append({key: entry[key] for key in ("path", "kind", "count")} | {"digest": array_digest(shard)})
        # Identifies exactly the samples loaded (shards of other kinds may still be growing).
        identity = {"fingerprint": self.manifest["fingerprint"], "shards": used}
        if limit_per_kind is not None:
            identity["limit_per_kind"] = limit_per_kind
        self.content_hash = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:16]
        arrays: list[dict[str, np.ndarray]] = []
        for kind in kinds:
            if not parts[kind]:
                raise ValueError(
                    f"{self.directory} has no {kind} samples; generate them with "
                    f"`wpbench data generate --out {self.directory.parent} --split {self.directory.name}`"
                )
            merged = {key: np.concatenate([p[key] for p in parts[kind]]) for key in parts[kind][0]
                      if key not in ("fingerprint", DIGEST_KEY)}
            if limit_per_kind is not None:
                merged = {key: value[:limit_per_kind] for key, value in merged.items()}
            arrays.append(merged)
        data = {key: np.concatenate([a[key] for a in arrays]) for key in arrays[0]}
        self.action = torch.from_numpy(data["action_points"].astype(np.float32))
        self.anchor = torch.from_numpy(data["anchor_points"].astype(np.float32))
        self.gt_transform = torch.from_numpy(data["gt_transform"].astype(np.float32))
        self.kind = torch.from_numpy(data["kind"].astype(np.int64))
        self.categories = [str(c) for c in data["category"]]
        self.object_ids = [str(c) for c in data["object_id"]]
        self.seeds = data["seed"].astype(np.int64)
        check_not_test_data(self.directory, self.manifest, sorted(set(self.object_ids)))
        self.gt_equivalents = torch.from_numpy(_equivalent_goal_table(data).astype(np.float32))
        if not (len(self.action) == len(self.anchor) == len(self.gt_transform) == len(self.kind)):
            raise ValueError(f"{self.directory}: shard arrays disagree in length")

    def __len__(self) -> int:
        return len(self.kind)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        return {
            "action": self.action[index],
            "anchor": self.anchor[index],
            "gt_transform": self.gt_transform[index],
            "kind": self.kind[index],
            "index": torch.tensor(index, dtype=torch.int64),
        }

    def count(self, kind: str) -> int:
        return int((self.kind == KIND_CODE[kind]).sum())


def _equivalent_goal_table(data: dict[str, np.ndarray]) -> np.ndarray:
    """(N, K, 4, 4): each sample's equivalent goals under its Ravens object's discrete symmetries."""
    from wpbench.assets.ravens import RAVENS_OBJECTS

    T = data["gt_transform"].astype(np.float64)
    if "action_pose" not in data:
        return T[:, None]
    groups: dict[str, np.ndarray] = {}
    for name in set(str(n) for n in data["free_object"]):
        if name in RAVENS_OBJECTS:
            discrete = RAVENS_OBJECTS[name].symmetry.discrete.numpy()
            # The identity gives gt_transform itself, which is row 0 already.
            groups[name] = discrete[~np.isclose(discrete, np.eye(3), atol=1e-9).all(axis=(1, 2))]
    K = 1 + max((len(g) for g in groups.values()), default=0)
    table = np.repeat(T[:, None], K, axis=1)
    for i, name in enumerate(data["free_object"]):
        group = groups.get(str(name))
        if group is not None and len(group):
            table[i, 1:1 + len(group)] = equivalent_goals(T[i], data["action_pose"][i], group)
    return table


class ConcatenatedSamples:
    """Several ``CrossPoseDataset`` s as one, for a training that mixes data sets
    (``wpbench.training.data_mix``): the same tensors (``action``, ``anchor``, ``gt_transform``,
    ``gt_equivalents``, ``kind``), concatenated in order, and ``source`` (N,) int64, the set each
    sample came from; ``sizes`` the sets' lengths. Goal tables of different widths are padded by
    repeating each sample's own goal (row 0), which changes no nearest-goal choice.
    Every set's clouds must hold the same point counts (ValueError otherwise).
    """

    def __init__(self, parts: list[CrossPoseDataset]) -> None:
        if not parts:
            raise ValueError("nothing to concatenate: give at least one data set")
        shapes = {(tuple(p.action.shape[1:]), tuple(p.anchor.shape[1:])) for p in parts}
        if len(shapes) > 1:
            raise ValueError(f"the data sets store clouds of different sizes {sorted(shapes)}; "
                             "generate them with the same --num-action-points and --num-anchor-points")
        self.parts = parts
        self.sizes = [len(p) for p in parts]
        self.action = torch.cat([p.action for p in parts])
        self.anchor = torch.cat([p.anchor for p in parts])
        self.gt_transform = torch.cat([p.gt_transform for p in parts])
        self.kind = torch.cat([p.kind for p in parts])
        width = max(p.gt_equivalents.shape[1] for p in parts)
        self.gt_equivalents = torch.cat([_pad_goals(p.gt_equivalents, width) for p in parts])
        self.source = torch.cat([torch.full((len(p),), i, dtype=torch.int64) for i, p in enumerate(parts)])
        self.categories = [c for p in parts for c in p.categories]
        self.object_ids = [o for p in parts for o in p.object_ids]

    def __len__(self) -> int:
        return len(self.kind)

    def count(self, kind: str) -> int:
        return int((self.kind == KIND_CODE[kind]).sum())


def _pad_goals(table: torch.Tensor, width: int) -> torch.Tensor:
    """(N, K, 4, 4) -> (N, width, 4, 4), the extra columns repeating column 0."""
    missing = width - table.shape[1]
    if missing <= 0:
        return table
    return torch.cat([table, table[:, :1].expand(-1, missing, -1, -1)], dim=1)
