"""Decomposition in worker processes, fallbacks for degenerate links, and ``wpbench assets check``.

The objects are made up: a procedural oven written in PartNet-Mobility's layout, given
extra links the way real downloads have them (a handle that is a flat sliver, a knob).
Workers run a fast exact decomposer (one convex hull per connected piece of the
mesh, which is exact for furniture built from boxes) instead of CoACD, and a crashing
one for the crash cases.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import trimesh

from wpbench.assets.collision_fallback import (
    CONVEX_HULL,
    MIN_THICKNESS_FRACTION,
    NO_COLLISION,
    THIN_BOX,
    fallback_pieces,
    principal_extents,
)
from wpbench.assets.decompose import LinkJob, read_entry, run_jobs, save_mesh
from wpbench.assets.partnet import PartNetLoadConfig, PartNetLoadError, load_partnet_object
from wpbench.assets.prepare import prepare_folder
from wpbench.assets.procedural import generate_object

DECOMPOSERS = '''
import os, signal, time
import trimesh
from wpbench.assets.decompose import convex_pieces_from_vertices


def exact(mesh, config):
    return convex_pieces_from_vertices([part.vertices for part in mesh.split(only_watertight=False)])


def crash_on_knob(mesh, config):
    if len(mesh.vertices) == KNOB_VERTICES:
        os.kill(os.getpid(), signal.SIGSEGV)
    return exact(mesh, config)


def crash_on_everything(mesh, config):
    os.kill(os.getpid(), signal.SIGSEGV)


def slow_after_first(mesh, config):
    marker = os.environ["FIRST_DONE_MARKER"]
    if os.path.exists(marker):
        time.sleep(120)
    open(marker, "w").close()
    return exact(mesh, config)
'''


@pytest.fixture()
def decomposers(tmp_path, monkeypatch) -> str:
    """A module of decomposers importable by the worker processes; returns its name."""
    folder = tmp_path / "plug"
    folder.mkdir()
    knob = trimesh.creation.cylinder(radius=0.02, height=0.02, sections=12)
    (folder / "fake_decomposers.py").write_text(DECOMPOSERS.replace("KNOB_VERTICES", str(len(knob.vertices))))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(folder), os.environ.get("PYTHONPATH")])))
    return "fake_decomposers"


def _add_link(urdf: Path, name: str, parent: str, mesh: trimesh.Trimesh, xyz) -> None:
    """Add link ``name`` (collision and visual ``mesh``) fixed to ``parent`` at ``xyz``."""
    folder = urdf.parent
    filename = f"textured_objs/{name}.obj"
    mesh.export(folder / filename)
    tree = ET.parse(urdf)
    root = tree.getroot()
    link = ET.SubElement(root, "link", name=name)
    for tag in ("visual", "collision"):
        ET.SubElement(ET.SubElement(link, tag), "geometry").append(ET.Element("mesh", filename=filename))
    joint = ET.SubElement(root, "joint", name=f"{name}_joint", type="fixed")
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=name)
    ET.SubElement(joint, "origin", xyz=" ".join(str(v) for v in xyz), rpy="0 0 0")
    tree.write(urdf)


def _sliver(length: float, width: float) -> trimesh.Trimesh:
    """A flat rectangle in the x = 0 plane (zero thickness), two triangles."""
    v = np.array([[0, -width / 2, -length / 2], [0, width / 2, -length / 2], [0, width / 2, length / 2],
                  [0, -width / 2, length / 2]], dtype=float)
    return trimesh.Trimesh(vertices=v, faces=[[0, 1, 2], [0, 2, 3]], process=False)


@pytest.fixture()
def oven(tmp_path) -> Path:
    """A made-up oven: body, door, a flat-sliver handle on the door and a knob on the body."""
    asset = generate_object("oven", 2, tmp_path / "objects")
    folder = tmp_path / "objects" / asset.object_id
    urdf = folder / "mobility.urdf"
    front, top = asset.bounds_high[0], asset.bounds_high[2]
    _add_link(urdf, "handle_link_0", asset.target_link, _sliver(0.15, 0.03), (front + 0.04, 0.0, 0.6 * top))
    knob = trimesh.creation.cylinder(radius=0.02, height=0.02, sections=12)
    _add_link(urdf, "knob_link_0", "link_0", knob, (front - 0.15, 0.1, top + 0.01))
    with open(folder / "semantics.txt", "a") as f:
        f.write("handle_link_0 static handle\nknob_link_0 static knob\n")
    return folder


# --------------------------------------------------------------------------- fallbacks, as pure geometry


def test_fallback_of_a_flat_sliver_is_a_thin_box_around_it():
    sliver = _sliver(0.3, 0.03)
    pieces, kind = fallback_pieces(sliver.vertices)
    assert kind == THIN_BOX and len(pieces) == 1
    box = pieces[0]
    _center, _axes, extents = principal_extents(box.vertices)
    assert extents == pytest.approx([MIN_THICKNESS_FRACTION * 0.3, 0.03, 0.3])
    assert box.contains(sliver.vertices * 0.999).all()  # the sliver lies inside its box


def test_fallback_of_a_solid_is_its_convex_hull_and_of_a_line_nothing():
    knob = trimesh.creation.cylinder(radius=0.02, height=0.02, sections=12)
    pieces, kind = fallback_pieces(knob.vertices)
    assert kind == CONVEX_HULL and pieces[0].volume == pytest.approx(knob.convex_hull.volume)
    line = np.array([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]], dtype=float)
    assert fallback_pieces(line) == ([], NO_COLLISION)
    assert fallback_pieces(np.zeros((0, 3))) == ([], NO_COLLISION)
    with pytest.raises(ValueError, match="shape"):
        principal_extents(np.zeros((4, 2)))


# --------------------------------------------------------------------------- the loader


@pytest.mark.slow
def test_a_flat_sliver_handle_falls_back_to_a_thin_box_and_the_object_loads(oven, decomposers, tmp_path):
    asset = load_partnet_object(oven, cache_dir=tmp_path / "cache",
                                config=PartNetLoadConfig(decomposer=f"{decomposers}:exact", workers=2))
    assert asset.target_link == "link_1"
    assert asset.extra["collision_fallbacks"]["handle_link_0"].startswith(THIN_BOX)
    assert "knob_link_0" not in asset.extra["collision_fallbacks"]
    assert asset.open_qpos == pytest.approx(asset.extra["open_qpos_limit"])  # nothing blocks the door
    handle = next(l for l in ET.parse(asset.urdf).getroot().findall("link") if l.get("name") == "handle_link_0")
    pieces = [trimesh.load(c.find("geometry/mesh").get("filename"), force="mesh") for c in handle.findall("collision")]
    assert len(pieces) == 1 and pieces[0].volume > 0


@pytest.mark.slow
def test_a_crash_costs_only_its_link_and_the_reason_is_recorded(oven, decomposers, tmp_path):
    asset = load_partnet_object(oven, cache_dir=tmp_path / "cache",
                                config=PartNetLoadConfig(decomposer=f"{decomposers}:crash_on_knob", workers=2))
    why = asset.extra["collision_fallbacks"]["knob_link_0"]
    assert why.startswith(CONVEX_HULL) and "crashed (SIGSEGV)" in why


@pytest.mark.slow
def test_a_body_whose_decomposition_crashes_is_refused_in_one_line(oven, decomposers, tmp_path):
    with pytest.raises(PartNetLoadError) as err:
        load_partnet_object(oven, cache_dir=tmp_path / "cache",
                            config=PartNetLoadConfig(decomposer=f"{decomposers}:crash_on_everything", workers=2))
    message = str(err.value)
    assert "\n" not in message and "no free cavity" in message and "convex hull" in message and "SIGSEGV" in message


def test_workers_write_every_entry_once_and_leave_no_temporary_files(decomposers, tmp_path):
    jobs = []
    for k in range(5):
        mesh = trimesh.creation.box(extents=(0.1 * (k + 1), 0.2, 0.3))
        save_mesh(mesh, tmp_path / f"m{k}.npz")
        jobs.append(LinkJob(label=f"obj/link_{k}", link=f"link_{k}", mesh_file=tmp_path / f"m{k}.npz",
                            entry=tmp_path / "pieces" / f"link_{k}", decomposer=f"{decomposers}:exact"))
    assert run_jobs(jobs, workers=3, progress=False) == {}
    for k, job in enumerate(jobs):
        info = read_entry(job.entry)
        assert info["source"] == "coacd" and info["pieces"] == 1
        assert trimesh.load(job.entry / "piece_000.obj", force="mesh").volume == pytest.approx(0.1 * (k + 1) * 0.06)
    assert sorted(p.name for p in (tmp_path / "pieces").iterdir()) == [f"link_{k}" for k in range(5)]
    with pytest.raises(ValueError, match="workers"):
        run_jobs(jobs, workers=0)


# --------------------------------------------------------------------------- the command a user runs


def _wpbench(*args: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from wpbench.cli import main; main()", *args],
                          capture_output=True, text=True, env=env, timeout=600)


@pytest.mark.slow
def test_assets_check_gives_one_line_per_object(oven, decomposers, tmp_path):
    objects = oven.parent
    no_meta = objects / "no_meta_no_body"
    shutil.copytree(oven, no_meta)
    (no_meta / "meta.json").unlink()
    root = ET.parse(no_meta / "mobility.urdf").getroot()
    for link in root.findall("link"):
        if link.get("name") != "link_1":
            for c in link.findall("collision"):
                link.remove(c)
    ET.ElementTree(root).write(no_meta / "mobility.urdf")
    (objects / "empty").mkdir()
    env = {**os.environ, "WPBENCH_CACHE": str(tmp_path / "cache"), "OMP_NUM_THREADS": "1"}
    # The check's decomposer is CoACD; prepare the cache with the fast one first (same keys).
    results = prepare_folder(objects, workers=2, progress=False, cache_dir=tmp_path / "cache" / "partnet",
                             decomposer=f"{decomposers}:exact")
    assert {r.folder.name: r.error is None for r in results} == {oven.name: True, "no_meta_no_body": True,
                                                                 "empty": False}
    done = _wpbench("assets", "check", str(objects), "--workers", "2", env=env)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert len(lines) == 4 and lines[-1] == "1 of 3 objects usable"
    by_id = {line.split()[0]: line for line in lines[:-1]}
    assert " usable " in by_id[oven.name] and "handle_link_0: thin box" in by_id[oven.name]
    assert " refused " in by_id["empty"] and "semantics.txt is missing" in by_id["empty"]
    assert " refused " in by_id["no_meta_no_body"] and "the body has none" in by_id["no_meta_no_body"]


def test_an_interrupted_prepare_leaves_only_finished_entries(oven, decomposers, tmp_path):
    import signal
    import time

    cache = tmp_path / "cache"
    marker = tmp_path / "first-done"
    script = textwrap.dedent(f"""
        from wpbench.assets.prepare import prepare_folder
        prepare_folder({str(oven)!r}, workers=1, cache_dir={str(cache)!r}, progress=False,
                       decomposer="{decomposers}:slow_after_first")
    """)
    env = {**os.environ, "FIRST_DONE_MARKER": str(marker)}
    process = subprocess.Popen([sys.executable, "-c", script], env=env, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    pieces = cache / oven.name / "pieces"
    while time.monotonic() < deadline and not (pieces.is_dir() and any(pieces.glob("*/timing.json"))):
        time.sleep(0.2)
    time.sleep(1.0)  # the second link's worker is now running (sleeping)
    process.send_signal(signal.SIGINT)
    _out, err = process.communicate(timeout=60)
    assert process.returncode != 0 and "KeyboardInterrupt" in err
    entries = sorted(pieces.iterdir())
    assert len(entries) == 1 and (entries[0] / "timing.json").is_file()  # the finished link only
    assert not list((cache / oven.name).glob("*.urdf"))
    assert not [p for p in (cache / oven.name).rglob("*") if p.name.startswith(".")]  # no temporary files


def test_a_generated_library_given_as_assets_is_not_decomposed(wpbench_exe, tmp_path, monkeypatch):
    """`wpbench assets generate` folders carry their own collision boxes: a run or data generation
    on worker processes reads them as they are, and nothing lands in the decomposition cache."""
    from wpbench.assets.library import load_library
    from wpbench.assets.prepare import prepare_asset_sources

    cache = tmp_path / "cache"
    monkeypatch.setenv("WPBENCH_CACHE", str(cache))
    library = tmp_path / "library"
    result = subprocess.run([str(wpbench_exe), "assets", "generate", "--out", str(library),
                             "--per-category", "2", "--val-per-category", "1", "--category", "microwave"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    prepare_asset_sources([str(library), "procedural"])
    assert not (cache / "partnet").exists()
    assert [a.object_id for a in load_library(library, split="val")] == ["microwave-0001"]
