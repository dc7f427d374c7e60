"""``wpbench data generate --ray``: whole shards drawn as Ray tasks, written by the driver,
the same shards as a serial run; ``--workers`` with ``--ray`` is refused.

The cluster here is a local one on 127.0.0.1 with 2 CPUs. One's own objects reach the
tasks through Ray's object store with their split file, even one kept in the driver's
cache: had a task loaded every object of the folder, its shards would hold other objects.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from test_assets_decompose import decomposers  # noqa: F401  (fixture)
from wpbench.data.config import ARTICULATED, FREE, GenerationConfig
from wpbench.data.generate import generate
from wpbench.data.manifest import read_manifest
from wpbench.data.shards import read_shard, shard_path
from wpbench.evaluation.ray_workers import SINGLE_MACHINE_VARIABLE

# Before ray is imported: 127.0.0.1 stays 127.0.0.1 (see wpbench.evaluation.ray_workers.connect).
os.environ.setdefault(SINGLE_MACHINE_VARIABLE, "0")
ray = pytest.importorskip("ray")


def assert_same_shards(one_root, two_root, split: str, kinds, shards: int) -> None:
    """The shards of two data roots hold the same arrays, bit for bit, in the same files."""
    for kind in kinds:
        for index in range(shards):
            one = read_shard(shard_path(one_root / split, kind, index))
            two = read_shard(shard_path(two_root / split, kind, index))
            assert set(one) == set(two)
            for key in one:
                assert one[key].dtype == two[key].dtype and one[key].shape == two[key].shape, (kind, index, key)
                assert one[key].tobytes() == two[key].tobytes(), (kind, index, key)
            # and the files: numpy's zip entries carry no write time
            assert shard_path(one_root / split, kind, index).read_bytes() == \
                shard_path(two_root / split, kind, index).read_bytes()


def test_workers_and_ray_together_are_refused_in_one_line(tmp_path):
    done = subprocess.run([sys.executable, "-c", "from wpbench.cli import main; main()", "data", "generate",
                           "--workers", "2", "--ray", "local", "--out", str(tmp_path / "data")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.startswith("Error: --workers and --ray cannot be combined") and done.stderr.count("\n") == 1
    assert not (tmp_path / "data").exists()


@pytest.mark.slow
def test_a_local_ray_cluster_with_two_cpus_writes_the_serial_shards(tmp_path):
    config = GenerationConfig(split="train", obs="mesh", seed=3, samples_per_kind=4, shard_size=2, scene_reuse=2,
                              num_action_points=32, num_anchor_points=64)   # two shards of each kind
    serial = generate(tmp_path / "serial", config, progress=False)
    landed = []
    on_ray = generate(tmp_path / "ray", config, progress=False, use_ray=True, ray_address=None, ray_cpus=2,
                      on_shard=lambda kind, shard: landed.append(
                          (kind, shard, read_manifest(tmp_path / "ray" / "train")["counts"])))
    assert not ray.is_initialized()  # the cluster it started is shut down
    assert serial.written_shards == on_ray.written_shards == 4 and on_ray.new_samples == 8
    assert_same_shards(tmp_path / "serial", tmp_path / "ray", "train", (ARTICULATED, FREE), 2)
    # The manifest was current after every shard the driver wrote, and is complete at the end.
    assert sorted((kind, shard) for kind, shard, _ in landed) == [(k, i) for k in (ARTICULATED, FREE) for i in (0, 1)]
    assert [sum(counts.values()) for _, _, counts in landed] == [2, 4, 6, 8]
    assert read_manifest(tmp_path / "ray" / "train")["counts"] == {ARTICULATED: 4, FREE: 4}
    assert read_manifest(tmp_path / "ray" / "train")["content_hash"] == serial.manifest["content_hash"]
    assert not np.isnan(read_shard(shard_path(tmp_path / "ray" / "train", ARTICULATED, 0))["start_fraction"]).any()


@pytest.mark.slow
def test_own_objects_reach_the_tasks_with_a_split_file_kept_in_the_cache(tmp_path, decomposers, monkeypatch):  # noqa: F811
    from wpbench.assets.object_split import SPLIT_FILE_NAME, find_split_file, split_of_objects, write_split_file
    from wpbench.assets.prepare import prepare_folder
    from wpbench.assets.procedural import generate_object

    monkeypatch.setenv("WPBENCH_CACHE", str(tmp_path / "cache"))
    objects = tmp_path / "objects"
    for index in range(4):
        generate_object("microwave", index, objects)
    prepared = prepare_folder(objects, workers=2, progress=False, decomposer=f"{decomposers}:exact")
    assert all(r.error is None for r in prepared)
    (objects / SPLIT_FILE_NAME).mkdir()  # the folder cannot take the split file: it goes to the cache
    write_split_file(objects, val_fraction=0.25, test_fraction=0.25, seed=0)
    assert find_split_file(objects).is_relative_to(tmp_path / "cache")
    train = {i for i, s in split_of_objects(objects).items() if s == "train"}
    assert len(train) == 2
    config = GenerationConfig(split="train", obs="mesh", seed=1, samples_per_kind=4, shard_size=2, scene_reuse=1,
                              kinds=(ARTICULATED,), num_action_points=32, num_anchor_points=64, assets=str(objects))
    generate(tmp_path / "serial", config, progress=False)
    generate(tmp_path / "ray", config, progress=False, use_ray=True, ray_cpus=2)
    assert_same_shards(tmp_path / "serial", tmp_path / "ray", "train", (ARTICULATED,), 2)
    drawn = set(read_shard(shard_path(tmp_path / "ray" / "train", ARTICULATED, 0))["object_id"])
    drawn |= set(read_shard(shard_path(tmp_path / "ray" / "train", ARTICULATED, 1))["object_id"])
    assert drawn <= train
