"""Training on several data sets at once: ``wpbench train --data A:0.7 --data B:0.3``.

A data set is a data root with ``train/`` (and, for the first one, ``val/``) as
``wpbench data generate`` writes it. ``--data PATH[:WEIGHT]`` is repeatable; a set given
without ``:WEIGHT`` has weight 1, and the weights need not sum to 1 (they are normalised).

- Sampling: every sample of a batch comes from set i with probability w_i / sum(w),
  whatever the sets' sizes (:func:`mixed_batches`); within a set the samples are drawn
  in a fresh random order per pass, so each set is seen whole before any sample repeats.
- Validation and model selection (the per-epoch validation, ``metrics.json`` and so
  ``best.json`` and ``--promote``) use the first set's ``val/`` only: list the data the
  weights are meant for first.
- A set may hold only some of the policy's kinds (own objects may give articulated samples
  only); together the sets must hold every kind, and the first set's ``val/`` every kind.
- Sets must share one observation: the same ``--obs`` mode and the same stored point
  counts (camera noise options may differ: they are a kind of augmentation).
- One ``--data`` trains exactly as a single data root always did (:func:`training_batches`
  falls back to ``shuffled_batches``), and ``config.json`` records it in the same form.

:func:`mix_record` is what ``config.json`` records of a mix under ``data.mix``: every
set's path, given and normalised weight, sample counts per kind, the manifest content
hash, observation mode, assets and (for own objects) the split file's digest.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from wpbench.data.config import KINDS
from wpbench.data.dataset import ConcatenatedSamples, CrossPoseDataset
from wpbench.data.manifest import read_manifest
from wpbench.training.batches import shuffled_batches

# Stored-observation fields two data sets must agree on to be mixed in one batch.
OBSERVATION_FIELDS = ("obs", "num_action_points", "num_anchor_points")
WEIGHT_HINT = "give --data PATH or PATH:WEIGHT with WEIGHT a number > 0, e.g. --data data3:0.7 --data data-own:0.3"


@dataclass(frozen=True)
class DataSource:
    """One ``--data`` entry: a data root and its weight (None = not given, which counts as 1)."""

    path: Path
    weight: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))
        if self.weight is not None and not (math.isfinite(self.weight) and self.weight > 0):
            raise ValueError(f"--data {self.path}:{self.weight}: the weight must be a finite number > 0; {WEIGHT_HINT}")

    @property
    def share(self) -> float:
        return 1.0 if self.weight is None else float(self.weight)

    def text(self) -> str:
        return str(self.path) if self.weight is None else f"{self.path}:{self.weight:g}"


def parse_data_option(text: str) -> DataSource:
    """"data3" -> (data3, None); "data3:0.7" -> (data3, 0.7). A suffix after the last ':' that is
    not a number stays part of the path."""
    text = str(text)
    head, sep, tail = text.rpartition(":")
    if sep and head:
        try:
            weight = float(tail)
        except ValueError:
            return DataSource(Path(text))
        return DataSource(Path(head), weight)
    if sep and not head:
        raise ValueError(f"--data {text!r} has no path; {WEIGHT_HINT}")
    return DataSource(Path(text))


def as_sources(data) -> tuple[DataSource, ...]:
    """A path, a "PATH[:WEIGHT]" string, a DataSource, or a sequence of those -> DataSources (checked)."""
    items = [data] if isinstance(data, (str, Path, DataSource)) else list(data)
    if not items:
        raise ValueError(f"no data set given; {WEIGHT_HINT}")
    sources = tuple(item if isinstance(item, DataSource)
                    else parse_data_option(item) if isinstance(item, str)
                    else DataSource(Path(item)) for item in items)
    seen: set[Path] = set()
    for source in sources:
        key = source.path.expanduser().resolve()
        if key in seen:
            raise ValueError(f"--data {source.path} is given twice; give each data set once (its weight sets its share)")
        seen.add(key)
    return sources


def normalised_weights(sources: Sequence[DataSource]) -> list[float]:
    total = sum(source.share for source in sources)
    return [source.share / total for source in sources]


def mixed_batches(sizes: Sequence[int], weights: Sequence[float], batch_size: int,
                  generator: torch.Generator) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
    """Endless stream of (indices into the concatenated sets, set of each index), ``batch_size`` each.

    Each sample's set is drawn independently with probability ``weights`` (normalised); within
    a set, samples come in a random order that is redrawn after every pass over the set.
    """
    if len(sizes) != len(weights) or not sizes:
        raise ValueError("mixed_batches needs one weight per data set")
    if any(size < 1 for size in sizes):
        raise ValueError("cannot draw batches from an empty data set")
    probabilities = torch.tensor([float(w) for w in weights], dtype=torch.float64)
    if not torch.isfinite(probabilities).all() or (probabilities <= 0).any():
        raise ValueError(f"data set weights must be finite and > 0, got {list(weights)}")
    offsets = [0]
    for size in sizes[:-1]:
        offsets.append(offsets[-1] + size)
    orders: list[list[int]] = [[] for _ in sizes]
    while True:
        chosen = torch.multinomial(probabilities, batch_size, replacement=True, generator=generator)
        indices = []
        for which in chosen.tolist():
            if not orders[which]:
                orders[which] = torch.randperm(sizes[which], generator=generator).tolist()[::-1]
            indices.append(offsets[which] + orders[which].pop())
        yield torch.tensor(indices, dtype=torch.int64), chosen


def training_batches(train_set, sources: Sequence[DataSource], batch_size: int,
                     generator: torch.Generator) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
    """(indices, set of each index) batches for the trainer: one set -> ``shuffled_batches``
    (the single-data behaviour, batch for batch), several -> :func:`mixed_batches`."""
    if len(sources) == 1:
        for indices in shuffled_batches(len(train_set), batch_size, generator):
            yield indices, torch.zeros(len(indices), dtype=torch.int64)
        return
    yield from mixed_batches(train_set.sizes, normalised_weights(sources), batch_size, generator)


def _observation(manifest: dict) -> dict:
    config = manifest.get("config", {})
    return {name: config.get(name) for name in OBSERVATION_FIELDS}


def _observation_text(observation: dict) -> str:
    return (f"--obs {observation['obs']}, {observation['num_action_points']} action / "
            f"{observation['num_anchor_points']} anchor points")


def load_mix(sources: Sequence[DataSource], kinds: tuple[str, ...]) -> tuple[ConcatenatedSamples, list[dict]]:
    """The training samples of every set in ``sources`` (the kinds each holds among ``kinds``),
    concatenated in order, and one description per set (path, weight, counts, hash, observation).

    ValueError / FileNotFoundError, one line saying what to do, for a missing folder, a set with
    none of ``kinds``, kinds no set holds, or sets of different observations.
    """
    parts, described = [], []
    first_observation = None
    for source, weight in zip(sources, normalised_weights(sources)):
        directory = source.path / "train"
        if not source.path.is_dir():
            raise FileNotFoundError(f"--data {source.path}: no such folder; make it with `wpbench data generate "
                                    f"--out {source.path} --split train` or fix the path")
        manifest = read_manifest(directory)
        present = tuple(kind for kind in kinds if manifest.get("counts", {}).get(kind, 0) > 0)
        if not present:
            raise ValueError(f"--data {source.path}: {directory} holds none of the kinds this policy trains on "
                             f"({', '.join(kinds)}); generate them with `wpbench data generate --out {source.path} "
                             f"--split train --kind {kinds[0]}` or drop this --data")
        observation = _observation(manifest)
        if first_observation is None:
            first_observation = (source, observation)
        elif observation != first_observation[1]:
            first, seen = first_observation
            raise ValueError(f"--data {source.path} was generated with {_observation_text(observation)} but --data "
                             f"{first.path} with {_observation_text(seen)}; mix only data of one observation "
                             f"(regenerate one of them with the other's --obs and point counts)")
        dataset = CrossPoseDataset(directory, present)
        parts.append(dataset)
        record = {
            "path": str(source.path),
            "weight": round(weight, 6),
            "weight_given": source.weight,
            "samples": len(dataset),
            "samples_by_kind": {kind: dataset.count(kind) for kind in present},
            "train_manifest_hash": dataset.content_hash,
            "obs": observation["obs"],
            "assets": manifest.get("config", {}).get("assets"),
        }
        if manifest.get("asset_split"):
            record["asset_split"] = {key: manifest["asset_split"].get(key) for key in ("file", "digest")}
        described.append(record)
    missing = [kind for kind in kinds if not any(kind in record["samples_by_kind"] for record in described)]
    if missing:
        raise ValueError(f"no --data set holds {', '.join(missing)} samples, which this policy trains on; generate "
                         f"them with `wpbench data generate --split train --kind {missing[0]}` into one of the sets")
    return ConcatenatedSamples(parts), described


def mix_hash(described: Sequence[dict]) -> str:
    """What a mixed training trained on, as one hash (a resumed run checks it): every set's
    manifest hash and weight, in order."""
    content = json.dumps([[record["train_manifest_hash"], record["weight"]] for record in described])
    return hashlib.sha256(content.encode()).hexdigest()[:16]


def mix_record(described: Sequence[dict], drawn: Sequence[int]) -> list[dict]:
    """``described`` with how many training samples were drawn from each set."""
    return [{**record, "samples_drawn": int(n)} for record, n in zip(described, drawn)]


def describe_data(data: dict) -> str:
    """One line on what a run trained on, from its config.json ``data`` record."""
    mix = data.get("mix")
    if not mix:
        return f"trained on {data.get('path', '?')} (train hash {data.get('train_manifest_hash', '?')})"
    parts = [f"{record['path']} {record['weight']:.0%} ({record['samples']} samples, {record.get('assets') or '?'})"
             for record in mix]
    return f"trained on a mix: {'; '.join(parts)}; validated on {data.get('val_from', mix[0]['path'])}/val"
