"""``wpbench data generate --ray``: whole shards drawn as Ray tasks, written by the driver,
the same shards as a serial run; ``--workers`` with ``--ray`` is refused.

The cluster here is a local one on 127.0.0.1 with 2 CPUs.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from wpbench.data.config import ARTICULATED, FREE, GenerationConfig
from wpbench.data.generate import generate
from wpbench.data.manifest import read_manifest
from wpbench.data.shards import read_shard, shard_path
from wpbench.evaluation.ray_workers import SINGLE_MACHINE_VARIABLE

# Before ray is imported: 127.0.0.1 stays 127.0.0.1 (see wpbench.evaluation.ray_workers.connect).
os.environ.setdefault(SINGLE_MACHINE_VARIABLE, "0")
ray = pytest.importorskip("ray")


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
    for kind in (ARTICULATED, FREE):
        for index in range(2):
            one = read_shard(shard_path(tmp_path / "serial" / "train", kind, index))
            two = read_shard(shard_path(tmp_path / "ray" / "train", kind, index))
            assert set(one) == set(two)
            for key in one:
                assert one[key].dtype == two[key].dtype and one[key].shape == two[key].shape, key
                assert one[key].tobytes() == two[key].tobytes(), key
    # The manifest was current after every shard the driver wrote, and is complete at the end.
    assert sorted((kind, shard) for kind, shard, _ in landed) == [(k, i) for k in (ARTICULATED, FREE) for i in (0, 1)]
    assert [sum(counts.values()) for _, _, counts in landed] == [2, 4, 6, 8]
    assert read_manifest(tmp_path / "ray" / "train")["counts"] == {ARTICULATED: 4, FREE: 4}
    assert read_manifest(tmp_path / "ray" / "train")["content_hash"] == serial.manifest["content_hash"]
    assert not np.isnan(read_shard(shard_path(tmp_path / "ray" / "train", ARTICULATED, 0))["start_fraction"]).any()
