"""Training on several data sets: ``wpbench train --data A:0.7 --data B:0.3``.

The sampler draws each set in proportion to its weight (not its size), one --data trains
exactly as a single data root did, config.json records the mix and --promote shows it, and
bad input is refused in one line. Data sets are tiny synthetic splits, as in test_training.py.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

import wpbench.cli as cli
from wpbench.data.config import KINDS
from wpbench.data.dataset import ConcatenatedSamples, CrossPoseDataset
from wpbench.data.manifest import read_manifest, write_manifest
from wpbench.data.synthetic import write_synthetic_split
from wpbench.training import loop as train_loop
from wpbench.training.batches import shuffled_batches
from wpbench.training.config import TrainConfig
from wpbench.training.data_mix import (
    DataSource,
    load_mix,
    mixed_batches,
    normalised_weights,
    parse_data_option,
    training_batches,
)
from wpbench.training.loop import train

TINY_GF = {"encoder": {"k": 4, "edge_channels": [8, 8], "emb_dim": 16, "groups": 4}, "head_hidden": 16}
POINTS = dict(num_action_points=32, num_anchor_points=48)
ARTICULATED, FREE = KINDS


def _config(root: Path, data, out: str, **kw) -> TrainConfig:
    base = dict(policy="gf", data=data, out=root / "runs" / out, weights_root=root / "runs", max_steps=2,
                steps_per_epoch=1, batch_size=2, num_action_points=24, num_anchor_points=40, val_per_kind=2,
                final_val_per_kind=3, model_overrides=TINY_GF)
    base.update(kw)
    return TrainConfig(**base)


def _drop_kind(root: Path, split: str, kind: str) -> None:
    """Leave ``root/split`` with the samples of the other kind only (as own objects may give)."""
    directory = root / split
    manifest = read_manifest(directory)
    manifest["shards"] = [s for s in manifest["shards"] if s["kind"] != kind]
    manifest["counts"][kind] = 0
    write_manifest(directory, manifest)


@pytest.fixture(scope="module")
def sets(tmp_path_factory) -> Path:
    """A: 4 samples per kind with a val/; B: 12 per kind, train/ only; C: articulated only;
    D: other point counts; E: camera observation."""
    root = tmp_path_factory.mktemp("mix")
    write_synthetic_split(root / "A", "train", per_kind=4, **POINTS)
    write_synthetic_split(root / "A", "val", per_kind=3, seed=1, **POINTS)
    write_synthetic_split(root / "B", "train", per_kind=12, seed=2, **POINTS)
    write_synthetic_split(root / "C", "train", per_kind=5, seed=3, **POINTS)
    _drop_kind(root / "C", "train", FREE)
    write_synthetic_split(root / "D", "train", per_kind=4, seed=4, num_action_points=40, num_anchor_points=48)
    write_synthetic_split(root / "E", "train", per_kind=4, seed=5, **POINTS)
    manifest = read_manifest(root / "E" / "train")
    manifest["config"]["obs"] = "camera"
    write_manifest(root / "E" / "train", manifest)
    return root


# ------------------------------------------------------------------ sampling


@pytest.mark.parametrize("sizes, weights", [([40, 8], [0.7, 0.3]), ([5, 50, 10], [1.0, 1.0, 2.0])])
def test_each_set_is_drawn_in_proportion_to_its_weight_not_its_size(sizes, weights):
    generator = torch.Generator().manual_seed(0)
    stream = mixed_batches(sizes, normalised_weights([DataSource(Path(f"s{i}"), w) for i, w in enumerate(weights)]),
                           8, generator)
    offsets = [sum(sizes[:i]) for i in range(len(sizes))]
    counts, per_sample = Counter(), Counter()
    batches = 2500
    for _ in range(batches):
        indices, chosen = next(stream)
        assert len(indices) == 8
        for index, which in zip(indices.tolist(), chosen.tolist()):
            assert offsets[which] <= index < offsets[which] + sizes[which]  # the index lies in its set
            counts[which] += 1
            per_sample[index] += 1
    total = 8 * batches
    for which, weight in enumerate(weights):
        expected = weight / sum(weights)
        # The binomial standard deviation here is <= 0.0036; 0.015 is 4 of them. Drawing by size
        # (0.17 / 0.08 / 0.77) or evenly (0.5 / 0.33) misses by far more.
        assert abs(counts[which] / total - expected) < 0.015, (which, counts[which] / total, expected)
    for which, size in enumerate(sizes):
        # Within a set every sample comes once per pass: counts differ by at most one.
        seen = [per_sample[offsets[which] + i] for i in range(size)]
        assert max(seen) - min(seen) <= 1, (which, seen)


def test_one_data_set_gives_the_batches_a_single_data_root_always_gave():
    first, second = torch.Generator().manual_seed(7), torch.Generator().manual_seed(7)
    single = training_batches(list(range(11)), (DataSource(Path("A"), 3.0),), 4, first)
    plain = shuffled_batches(11, 4, second)
    for _ in range(20):
        indices, sets = next(single)
        assert torch.equal(indices, next(plain)) and not sets.any()


def test_the_trainer_draws_batches_by_weight(sets, monkeypatch):
    """A (4 articulated samples) at weight 3 and B (12) at weight 1: three quarters of what the
    trainer stacks come from A, where drawing by size would give one quarter."""
    seen = []
    make_batch = train_loop.make_batch

    def recording(dataset, indices):
        seen.extend(indices.tolist())
        return make_batch(dataset, indices)

    monkeypatch.setattr(train_loop, "make_batch", recording)
    config = _config(sets, [f"{sets / 'A'}:3", f"{sets / 'B'}:1"], "by-weight", max_steps=40, steps_per_epoch=40,
                     batch_size=4)
    metrics = train(config, echo=lambda _: None)
    from_a = sum(index < 4 for index in seen)
    assert len(seen) == 160 == metrics["samples_seen"]
    # 160 draws at p = 0.75: standard deviation 0.034; the tolerance is 4 of them.
    assert abs(from_a / len(seen) - 0.75) < 0.14
    assert metrics["samples_drawn_by_data"] == {str(sets / "A"): from_a, str(sets / "B"): len(seen) - from_a}


# ------------------------------------------------------------------ one --data as before


def test_one_data_option_trains_and_records_exactly_as_a_data_root(sets):
    runner = CliRunner()
    common = ["train", "--policy", "gf", "--max-steps", "3", "--steps-per-epoch", "1", "--batch-size", "2",
              "--num-action-points", "24", "--num-anchor-points", "40", "--val-per-kind", "2",
              "--final-val-per-kind", "3", "--seed", "5", "--lr-schedule", "constant", "--model-option", "encoder=" + json.dumps(TINY_GF["encoder"]),
              "--model-option", f"head_hidden={TINY_GF['head_hidden']}"]
    # A constant learning rate: the cosine schedule follows wall time, which no two runs share.
    reference = train(_config(sets, sets / "A", "plain", max_steps=3, seed=5, lr_schedule="constant"),
                      echo=lambda _: None)
    for name, data in (("cli", str(sets / "A")), ("cli-weighted", f"{sets / 'A'}:2.5")):
        out = sets / "runs" / name
        result = runner.invoke(cli.app, [*common, "--data", data, "--out", str(out)])
        assert result.exit_code == 0, result.output
        assert "data mix" not in result.output
        described = json.loads((out / "config.json").read_text())
        plain = json.loads((sets / "runs" / "plain" / "config.json").read_text())
        assert described["model_hash"] == plain["model_hash"]
        assert described["data"] == plain["data"] == {
            "path": str(sets / "A"),
            "train_manifest_hash": CrossPoseDataset(sets / "A" / "train", (ARTICULATED,)).content_hash,
            "val_manifest_hash": CrossPoseDataset(sets / "A" / "val", (ARTICULATED,)).content_hash}
        assert "data_sources" not in described["train_config"] and described["train_config"]["data"] == str(sets / "A")
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["val"] == reference["val"] and "samples_drawn_by_data" not in metrics


# ------------------------------------------------------------------ what config.json records


def test_config_json_records_the_mix_and_promote_shows_it(sets):
    config = _config(sets, [f"{sets / 'A'}:0.7", f"{sets / 'B'}:0.3"], "recorded", max_steps=6, steps_per_epoch=3)
    metrics = train(config, echo=lambda _: None)
    described = json.loads((config.out / "config.json").read_text())
    data = described["data"]
    assert data["path"] == data["val_from"] == str(sets / "A")
    assert data["val_manifest_hash"] == CrossPoseDataset(sets / "A" / "val", (ARTICULATED,)).content_hash
    assert [(m["path"], m["weight"], m["weight_given"]) for m in data["mix"]] == [
        (str(sets / "A"), 0.7, 0.7), (str(sets / "B"), 0.3, 0.3)]
    assert [m["samples"] for m in data["mix"]] == [4, 12]
    assert [m["samples_by_kind"] for m in data["mix"]] == [{ARTICULATED: 4}, {ARTICULATED: 12}]
    for record, name in zip(data["mix"], "AB"):
        assert record["train_manifest_hash"] == CrossPoseDataset(sets / name / "train", (ARTICULATED,)).content_hash
        assert record["obs"] == "mesh" and record["assets"] == "procedural"
    assert sum(m["samples_drawn"] for m in data["mix"]) == metrics["samples_seen"] == 12
    assert described["train_config"]["data_sources"] == [f"{sets / 'A'}:0.7", f"{sets / 'B'}:0.3"]
    # Another mix of the same sets is other training data: resuming into this run is refused.
    with pytest.raises(ValueError, match="--restart"):
        train(_config(sets, [f"{sets / 'A'}:0.5", f"{sets / 'B'}:0.5"], "recorded", max_steps=8), echo=lambda _: None)

    result = CliRunner().invoke(cli.app, ["train", "--promote", str(config.out), "--weights-root",
                                          str(sets / "shipped")])
    assert result.exit_code == 0, result.output
    assert f"trained on a mix: {sets / 'A'} 70% (4 samples, procedural); {sets / 'B'} 30% (12 samples" in result.output
    assert f"validated on {sets / 'A'}/val" in result.output


def test_a_set_may_hold_some_kinds_when_the_mix_holds_them_all(sets):
    samples, described = load_mix((DataSource(sets / "A"), DataSource(sets / "C")), KINDS)
    assert [d["samples_by_kind"] for d in described] == [{ARTICULATED: 4, FREE: 4}, {ARTICULATED: 5}]
    assert samples.sizes == [8, 5] and len(samples) == 13
    assert samples.source.tolist() == [0] * 8 + [1] * 5
    assert samples.count(FREE) == 4 and samples.count(ARTICULATED) == 9
    with pytest.raises(ValueError, match="none of the kinds") as refused:
        load_mix((DataSource(sets / "A"), DataSource(sets / "C")), (FREE,))
    assert "--data" in str(refused.value) and "\n" not in str(refused.value)
    with pytest.raises(ValueError, match=f"no --data set holds {FREE} samples") as refused:
        load_mix((DataSource(sets / "C"),), KINDS)
    assert "--kind free-floating" in str(refused.value)


def test_goal_tables_of_different_widths_are_padded_with_the_sample_own_goal(sets):
    a = CrossPoseDataset(sets / "A" / "train", (ARTICULATED,))
    b = CrossPoseDataset(sets / "B" / "train", (ARTICULATED,))
    b.gt_equivalents = torch.cat([b.gt_equivalents, torch.eye(4).expand(len(b), 2, 4, 4)], dim=1)  # K = 3
    both = ConcatenatedSamples([a, b])
    assert both.gt_equivalents.shape == (len(a) + len(b), 3, 4, 4)
    assert torch.equal(both.gt_equivalents[:len(a)], a.gt_transform[:, None].expand(-1, 3, -1, -1))
    assert torch.equal(both.gt_equivalents[len(a):], b.gt_equivalents)


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize("text, match", [
    ("A:0", "weight must be a finite number > 0"),
    ("A:-0.5", "weight must be a finite number > 0"),
    ("A:nan", "weight must be a finite number > 0"),
    (":0.5", "has no path"),
])
def test_bad_weights_are_refused_in_one_line(text, match):
    with pytest.raises(ValueError, match=match) as refused:
        parse_data_option(text)
    assert "\n" not in str(refused.value) and "PATH:WEIGHT" in str(refused.value)


def test_a_path_with_a_colon_and_no_number_stays_a_path():
    assert parse_data_option("runs/a:b") == DataSource(Path("runs/a:b"))
    assert parse_data_option("data3:0.25") == DataSource(Path("data3"), 0.25)


@pytest.mark.parametrize("second, match", [
    ("missing", "no such folder; make it with `wpbench data generate --out"),
    ("D", "generated with --obs mesh, 40 action / 48 anchor points but --data"),
    ("E", "generated with --obs camera, 32 action / 48 anchor points but --data"),
    ("A", "is given twice"),
])
def test_the_cli_refuses_a_bad_mix_in_one_line(sets, second, match):
    result = CliRunner().invoke(cli.app, ["train", "--policy", "gf", "--data", f"{sets / 'A'}:0.5",
                                          "--data", str(sets / second), "--max-steps", "1",
                                          "--out", str(sets / "runs" / f"refused-{second}")])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: ") and match in lines[0], result.output
    assert not (sets / "runs" / f"refused-{second}" / "model.pt").exists()


def test_a_mix_with_test_data_is_refused(sets, tmp_path):
    """The guard against test data holds for every set of a mix, not only the first."""
    write_synthetic_split(tmp_path / "T", "test", per_kind=2, **POINTS)
    (tmp_path / "T" / "test").rename(tmp_path / "T" / "train")
    with pytest.raises(ValueError, match="training and model selection never read test data"):
        load_mix((DataSource(sets / "A"), DataSource(tmp_path / "T")), (ARTICULATED,))
