"""``wpbench run --ray``: the same records on a Ray cluster as in one process.

Clusters here listen on 127.0.0.1 only: a local one with 2 CPUs, and two nodes on this
machine (``ray.cluster_utils.Cluster``) to show episodes run on both and that the
trained weights reach the actors through the object store.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import pytest

from wpbench.evaluation.ray_workers import SINGLE_MACHINE_VARIABLE, pack_folder, unpack_folder

# Before ray is imported: 127.0.0.1 stays 127.0.0.1 (see RayPool._connect).
os.environ.setdefault(SINGLE_MACHINE_VARIABLE, "0")
ray = pytest.importorskip("ray")

SCHEDULE_FIELDS = ("timings", "ran_on")


def content(run: Path) -> list[dict]:
    records = []
    for line in (run / "episodes.jsonl").read_text().splitlines():
        record = {k: v for k, v in json.loads(line).items() if k not in SCHEDULE_FIELDS}
        record["stages"] = [{k: v for k, v in stage.items() if k != "exec_seconds"} for stage in record["stages"]]
        records.append(record)
    return records


def nodes(run: Path) -> set[str]:
    return {json.loads(line)["ran_on"]["node"] for line in (run / "episodes.jsonl").read_text().splitlines()}


def run_serial_then(pool, tmp_path: Path, **settings) -> tuple[Path, Path]:
    from wpbench.evaluation.driver import InProcessPool, run_many
    from wpbench.evaluation.runner import RunConfig

    serial = RunConfig(out=tmp_path / "serial", **settings)
    parallel = RunConfig(out=tmp_path / "ray", **settings)
    run_many([serial], InProcessPool(), progress=False)
    run_many([parallel], pool, progress=False)
    return serial.out, parallel.out


def test_a_packed_folder_unpacks_to_the_same_files_once_per_machine(tmp_path):
    source = tmp_path / "weights"
    (source / "wp").mkdir(parents=True)
    (source / "wp" / "model.pt").write_bytes(bytes(range(256)) * 10)
    (source / "best.json").write_text('{"policy": "wp-og"}')
    (source / ".hidden").write_text("left out")
    digest, data = pack_folder(source)
    assert pack_folder(source) == (digest, data)  # same content, same archive
    target = unpack_folder(digest, data, tmp_path / "nodes")
    assert target.name == digest
    assert (target / "wp" / "model.pt").read_bytes() == (source / "wp" / "model.pt").read_bytes()
    assert (target / "best.json").read_text() == '{"policy": "wp-og"}' and not (target / ".hidden").exists()
    (target / "marker").write_text("already there")
    assert unpack_folder(digest, data, tmp_path / "nodes") == target and (target / "marker").exists()


@pytest.mark.slow
def test_a_local_ray_cluster_with_two_cpus_gives_the_serial_run(tmp_path):
    from wpbench.evaluation.ray_workers import RayPool

    serial, parallel = run_serial_then(RayPool(address=None, num_cpus=2), tmp_path, policy="identity",
                                       task="open-then-place", obs="mesh", episodes=4)
    assert content(parallel) == content(serial)
    assert len({json.loads(line)["ran_on"]["pid"] for line in (parallel / "episodes.jsonl").read_text().splitlines()}) == 2
    assert not ray.is_initialized()  # the pool shut down the cluster it started


@pytest.mark.slow
def test_two_nodes_share_the_episodes_and_the_weights_travel_through_the_object_store(tmp_path):
    from ray.cluster_utils import Cluster

    from wpbench.evaluation.ray_workers import RayPool
    from wpbench.weights import shipped_weights_root

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "node_ip_address": "127.0.0.1",
                                                            "include_dashboard": False})
    cluster.add_node(num_cpus=1, node_ip_address="127.0.0.1")
    try:
        serial, parallel = run_serial_then(RayPool(address=cluster.address), tmp_path, policy="wp",
                                           task="open-door", obs="mesh", episodes=4)
    finally:
        ray.shutdown()
        cluster.shutdown()
    assert content(parallel) == content(serial)
    assert len(nodes(parallel)) == 2
    digest, _ = pack_folder(shipped_weights_root())
    assert (Path(tempfile.gettempdir()) / "wpbench-ray" / digest / "best.json").is_file()
