"""scripts/door_cabinet_probe.py as a developer runs it: a library of door cabinets in the chosen split."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "door_cabinet_probe.py"


def _probe(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("split", ["val", "train"])
def test_writes_door_cabinets_into_the_chosen_split(tmp_path: Path, split: str) -> None:
    out = tmp_path / "probe"
    done = _probe("--out", str(out), "--count", "3", "--height", "0.9", "1.2", "--split", split)
    assert done.returncode == 0, done.stderr
    splits = json.loads((out / "split.json").read_text())
    assert sorted(splits[split]) == ["storage-0000", "storage-0001", "storage-0002"]
    assert all(not ids for name, ids in splits.items() if name != split)
    for object_id in splits[split]:
        spec = json.loads((out / object_id / "wpbench.json").read_text())
        assert spec["extra"]["style"] == "door_cabinet"
        assert spec["bounds_high"][2] >= 0.9  # the carcass alone is at least 0.9 m tall


def test_refuses_the_benchmark_seed_and_an_existing_folder(tmp_path: Path) -> None:
    seed_zero = _probe("--out", str(tmp_path / "a"), "--seed", "0")
    assert seed_zero.returncode == 2 and "--seed 0" in seed_zero.stderr
    (tmp_path / "b").mkdir()
    existing = _probe("--out", str(tmp_path / "b"))
    assert existing.returncode == 2 and "exists" in existing.stderr
