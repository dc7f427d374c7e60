"""``wpbench run --assets DIR --workers 2``: the driver decomposes the folder's objects once,
before its workers start; no worker decomposes.

CoACD is replaced by a module of the same name (first on PYTHONPATH, so every process
the run starts imports it) that takes each connected part's convex hull and logs which
process asked for the decomposition: the parent of the decomposition process, i.e. the
driver or a worker.
"""

from __future__ import annotations

import os
import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

FAKE_COACD = '''
import hashlib
import os

import numpy as np
import trimesh


def set_log_level(level):
    pass


class Mesh:
    def __init__(self, vertices, faces):
        self.vertices, self.faces = np.asarray(vertices), np.asarray(faces)


def run_coacd(mesh, **options):
    with open(os.environ["FAKE_COACD_LOG"], "a") as log:
        log.write(f"{os.getppid()} {hashlib.sha256(mesh.vertices.tobytes()).hexdigest()}\\n")
    whole = trimesh.Trimesh(vertices=mesh.vertices, faces=mesh.faces, process=False)
    hulls = [part.convex_hull for part in whole.split(only_watertight=False)]
    return [(np.asarray(h.vertices), np.asarray(h.faces)) for h in hulls]
'''


@pytest.mark.slow
def test_the_driver_decomposes_an_uncached_folder_once_before_two_workers_run_it(tmp_path):
    from wpbench.assets.procedural import generate_object

    plug = tmp_path / "plug"
    plug.mkdir()
    (plug / "coacd.py").write_text(FAKE_COACD)
    objects = tmp_path / "objects"
    generate_object("oven", 2, objects)
    log = tmp_path / "decompositions.log"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "WPBENCH_CACHE": str(tmp_path / "cache"),
           "FAKE_COACD_LOG": str(log),
           "PYTHONPATH": os.pathsep.join(filter(None, [str(plug), os.environ.get("PYTHONPATH")]))}
    out = tmp_path / "run"
    driver = subprocess.Popen(
        [sys.executable, "-c", "from wpbench.cli import main; main()", "run", "--policy", "gt", "--task", "open-door",
         "--obs", "mesh", "--episodes", "4", "--workers", "2", "--assets", str(objects), "--out", str(out),
         "--no-progress"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stdout, stderr = driver.communicate(timeout=900)
    assert driver.returncode == 0, stderr[-3000:]
    asked = [line.split() for line in log.read_text().splitlines()]
    assert asked, "nothing was decomposed: the cache was not empty"
    assert {parent for parent, _ in asked} == {str(driver.pid)}  # the driver's decomposition processes only
    assert max(Counter(mesh for _, mesh in asked).values()) == 1  # each link once
    records = (out / "episodes.jsonl").read_text().splitlines()
    assert len(records) == 4 and all('"object_id": "oven-0002"' in r for r in records)
    assert len({json.loads(r)["ran_on"]["pid"] for r in records}) == 2  # two workers ran episodes
    assert list((tmp_path / "cache" / "partnet" / "oven-0002" / "pieces").iterdir())
    assert Path(out / "summary.json").is_file()
