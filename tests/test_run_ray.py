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


EXACT_DECOMPOSER = '''
from wpbench.assets.decompose import convex_pieces_from_vertices


def exact(mesh, config):
    return convex_pieces_from_vertices([part.vertices for part in mesh.split(only_watertight=False)])
'''


def collision_entries(cache: Path) -> dict[str, bytes]:
    """{<object>/pieces/<entry>/timing.json: its bytes} of a collision cache."""
    return {str(p.relative_to(cache)): p.read_bytes() for p in sorted((cache / "partnet").glob("*/pieces/*/timing.json"))}


@pytest.mark.slow
def test_a_folder_is_decomposed_once_and_a_node_with_its_own_cache_does_not_decompose_again(tmp_path, monkeypatch):
    """Two nodes with a collision cache each (as on two machines): the driver's entries, made
    by a fast exact decomposer, reach the second node as they are; had that node decomposed
    again it would have run CoACD, whose entries have other pieces and times."""
    from ray.cluster_utils import Cluster

    from wpbench.assets.prepare import prepare_folder
    from wpbench.assets.procedural import generate_object
    from wpbench.evaluation.ray_workers import RayPool

    plug = tmp_path / "plug"
    plug.mkdir()
    (plug / "exact_decomposer.py").write_text(EXACT_DECOMPOSER)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(plug), os.environ.get("PYTHONPATH")])))
    objects = tmp_path / "objects"
    generate_object("oven", 2, objects)
    driver_cache, node_cache = tmp_path / "driver-cache", tmp_path / "node-cache"
    monkeypatch.setenv("WPBENCH_CACHE", str(driver_cache))
    prepared = prepare_folder(objects, workers=2, progress=False, decomposer="exact_decomposer:exact")
    assert [p.error for p in prepared] == [None]
    made_on_driver = collision_entries(driver_cache)
    assert made_on_driver

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "node_ip_address": "127.0.0.1",
                                                            "include_dashboard": False})
    monkeypatch.setenv("WPBENCH_CACHE", str(node_cache))  # the second node's processes inherit it
    cluster.add_node(num_cpus=1, node_ip_address="127.0.0.1")
    monkeypatch.setenv("WPBENCH_CACHE", str(driver_cache))
    try:
        serial, parallel = run_serial_then(RayPool(address=cluster.address), tmp_path, policy="gt",
                                           task="open-door", obs="mesh", episodes=4, assets=str(objects))
    finally:
        ray.shutdown()
        cluster.shutdown()
    assert content(parallel) == content(serial)
    assert {r["object_id"] for r in content(parallel)} == {"oven-0002"}
    assert len(nodes(parallel)) == 2
    assert collision_entries(node_cache) == made_on_driver
    assert collision_entries(driver_cache) == made_on_driver


def test_collision_cache_entries_travel_to_a_node_cache_without_overwriting_it(tmp_path, monkeypatch):
    from wpbench.evaluation.ray_workers import install_collision_cache, pack_files, unpack_folder

    source = tmp_path / "driver"
    for name, text in (("link_0-aaa", "0"), ("link_1-bbb", "1")):
        entry = source / "oven-1" / "pieces" / name
        entry.mkdir(parents=True)
        (entry / "piece_000.obj").write_text(f"v {text} 0 0\n")
        (entry / "timing.json").write_text(json.dumps({"seconds": float(text)}))
    files = [(p.relative_to(source).as_posix(), p) for p in source.rglob("*") if p.is_file()]
    digest, data = pack_files(files)
    monkeypatch.setenv("WPBENCH_CACHE", str(tmp_path / "node"))
    kept = tmp_path / "node" / "partnet" / "oven-1" / "pieces" / "link_1-bbb"
    kept.mkdir(parents=True)
    (kept / "timing.json").write_text("already there")
    copied = install_collision_cache(unpack_folder(digest, data, tmp_path / "unpacked"))
    assert [p.name for p in copied] == ["link_0-aaa"]
    node_entry = tmp_path / "node" / "partnet" / "oven-1" / "pieces" / "link_0-aaa"
    assert (node_entry / "piece_000.obj").read_text() == "v 0 0 0\n"
    assert (kept / "timing.json").read_text() == "already there"
    assert not [p for p in node_entry.parent.iterdir() if p.name.startswith(".")]  # no staging left
