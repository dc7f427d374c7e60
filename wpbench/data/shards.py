"""One shard file = a dict of stacked sample arrays, written atomically.

Schema (S samples, NA action points, NB anchor points):

| key | shape | dtype | meaning |
|---|---|---|---|
| ``action_points`` | (S, NA, 3) | float32 | action object cloud, world frame |
| ``anchor_points`` | (S, NB, 3) | float32 | anchor object cloud, world frame |
| ``gt_transform`` | (S, 4, 4) | float64 | cross-pose, ``p_goal = T p_now``; for a symmetric free object the equivalent one with the smallest rotation |
| ``gt_transform_raw`` | (S, 4, 4) | float64 | the task's own cross-pose |
| ``action_pose`` | (S, 4, 4) | float64 | the action object's (free) or moving link's (articulated) world pose when observed: its symmetries act in this frame |
| ``kind`` | (S,) | int8 | 0 articulated, 1 free-floating |
| ``category`` | (S,) | str | furniture category |
| ``object_id`` | (S,) | str | furniture instance |
| ``free_object`` | (S,) | str | Ravens object ("" for articulated) |
| ``seed`` | (S,) | int64 | episode seed that reproduces the sample |
| ``start_fraction`` | (S,) | float32 | articulated start, fraction closed->open (NaN for free) |
| ``camera_fallback`` | (S,) | bool | the camera missed an object and the task used mesh samples |
| ``fingerprint`` | () | str | ``GenerationConfig.sample_fingerprint()`` of the writer |
| ``content_digest`` | () | str | ``array_digest`` of every other array, set by ``write_shard`` (absent in older shards) |

``content_digest`` identifies what the shard holds: two shards written with the same
options from different furniture (or a different generator version) differ in it. The
manifest and the dataset hash it, so their ``content_hash`` identifies the samples.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

ARRAY_KEYS = (
    "action_points", "anchor_points", "gt_transform", "gt_transform_raw", "action_pose", "kind", "category",
    "object_id", "free_object", "seed", "start_fraction", "camera_fallback",
)

DIGEST_KEY = "content_digest"


def shard_path(split_dir: Path, kind: str, index: int) -> Path:
    return Path(split_dir) / kind / f"shard-{index:05d}.npz"


def stack_samples(samples: list[dict], fingerprint: str) -> dict[str, np.ndarray]:
    """List of per-sample dicts (keys of ``ARRAY_KEYS``) -> stacked shard arrays."""
    if not samples:
        raise ValueError("a shard needs at least one sample")
    out = {key: np.stack([np.asarray(s[key]) for s in samples]) for key in ARRAY_KEYS}
    out["action_points"] = out["action_points"].astype(np.float32)
    out["anchor_points"] = out["anchor_points"].astype(np.float32)
    out["gt_transform"] = out["gt_transform"].astype(np.float64)
    out["gt_transform_raw"] = out["gt_transform_raw"].astype(np.float64)
    out["action_pose"] = out["action_pose"].astype(np.float64)
    out["kind"] = out["kind"].astype(np.int8)
    out["seed"] = out["seed"].astype(np.int64)
    out["start_fraction"] = out["start_fraction"].astype(np.float32)
    out["camera_fallback"] = out["camera_fallback"].astype(bool)
    out["fingerprint"] = np.asarray(fingerprint)
    return out


def array_digest(arrays: dict[str, np.ndarray]) -> str:
    """sha256 (hex) of a shard's arrays other than ``content_digest``: each key's name, dtype,
    shape and bytes, keys sorted. Depends on the values only, not on how the file compresses them."""
    digest = hashlib.sha256()
    for key in sorted(k for k in arrays if k != DIGEST_KEY):
        value = np.ascontiguousarray(arrays[key])
        digest.update(f"{key}|{value.dtype.str}|{value.shape}|".encode())
        digest.update(value)
    return digest.hexdigest()


def write_shard(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` to ``path`` atomically, with their ``content_digest``: a reader sees the
    whole shard or none."""
    path = Path(path)
    arrays = {**{k: v for k, v in arrays.items() if k != DIGEST_KEY}, DIGEST_KEY: np.asarray(array_digest(arrays))}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    with open(tmp, "wb") as handle:
        np.savez_compressed(handle, **arrays)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


def read_shard(path: Path, keys: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """Arrays of a shard (all, or only ``keys``). ValueError if the file is not a valid shard."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            wanted = keys if keys is not None else tuple(data.files)
            missing = [k for k in wanted if k not in data.files]
            if missing:
                raise ValueError(f"shard {path} lacks {missing}")
            return {key: data[key] for key in wanted}
    except (OSError, EOFError, ValueError) as err:
        raise ValueError(
            f"cannot read shard {path}: {err}. Delete it and rerun `wpbench data generate` to rewrite it"
        ) from err


def shard_digest(path: Path) -> str:
    """The ``content_digest`` a shard stores, or for a shard written before shards stored one,
    ``array_digest`` of its arrays (the whole file is read)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            if DIGEST_KEY in data.files:
                return str(data[DIGEST_KEY])
    except (OSError, EOFError, ValueError) as err:
        raise ValueError(
            f"cannot read shard {path}: {err}. Delete it and rerun `wpbench data generate` to rewrite it"
        ) from err
    return array_digest(read_shard(path))
