"""One's own objects as training data: split them, generate data from a split, and never train on test.

The objects are made up: procedural furniture written in PartNet-Mobility's layout
(with their own semantics.txt / meta.json), decomposed once by the fast exact
decomposer of ``test_assets_decompose`` into the cache the loader reads.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from test_assets_decompose import decomposers  # noqa: F401  (fixture)
from wpbench.assets.library import load_library
from wpbench.assets.object_split import (
    SPLIT_FILE_NAME,
    find_split_file,
    split_of_objects,
    stratified_split,
    write_split_file,
)
from wpbench.assets.prepare import prepare_folder
from wpbench.assets.procedural import generate_object
from wpbench.data.dataset import CrossPoseDataset
from wpbench.names import SPLITS


def _write_text_object(folder: Path, category: str) -> None:
    """The text files of a PartNet-Mobility object with one door (no meshes: enough to split)."""
    folder.mkdir(parents=True)
    (folder / "semantics.txt").write_text("link_0 hinge door\nlink_1 heavy body\n")
    (folder / "meta.json").write_text(json.dumps({"model_cat": category}))
    (folder / "mobility.urdf").write_text(
        '<robot name="x"><link name="base"/><link name="link_1"/><link name="link_0"/>'
        '<joint name="joint_0" type="revolute"><parent link="link_1"/><child link="link_0"/>'
        '<limit lower="0" upper="1.57"/></joint></robot>')


def test_stratified_split_keeps_whole_objects_per_category_and_is_reproducible():
    categories = {f"m{i}": "microwave" for i in range(10)} | {f"o{i}": "oven" for i in range(5)} | {"f0": "fridge"}
    split = stratified_split(categories, val_fraction=0.2, test_fraction=0.2, seed=3)
    everyone = [i for s in SPLITS for i in split[s]]
    assert sorted(everyone) == sorted(categories) and len(everyone) == len(set(everyone))
    count = {s: {c: sum(categories[i] == c for i in split[s]) for c in ("microwave", "oven", "fridge")} for s in SPLITS}
    assert count["test"] == {"microwave": 2, "oven": 1, "fridge": 0}  # round(10 * 0.2), round(5 * 0.2); a lone fridge trains
    assert count["val"] == {"microwave": 2, "oven": 1, "fridge": 0}
    assert split == stratified_split(categories, 0.2, 0.2, seed=3)
    assert any(split[s] != stratified_split(categories, 0.2, 0.2, seed=4)[s] for s in SPLITS)
    with pytest.raises(ValueError, match="leave some objects"):
        stratified_split(categories, 0.5, 0.5, seed=0)


def test_split_file_goes_beside_the_objects_or_to_the_cache_when_it_cannot(tmp_path, monkeypatch):
    monkeypatch.setenv("WPBENCH_CACHE", str(tmp_path / "cache"))
    objects = tmp_path / "objects"
    for i in range(4):
        _write_text_object(objects / f"{100 + i}", "Microwave")
    (objects / "broken").mkdir()
    path, data, skipped = write_split_file(objects, val_fraction=0.25, test_fraction=0.25, seed=0)
    assert path == objects / SPLIT_FILE_NAME and find_split_file(objects) == path
    assert list(skipped) == ["broken"] and "semantics.txt is missing" in skipped["broken"]
    assert [len(data["splits"][s]) for s in SPLITS] == [2, 1, 1]
    assert split_of_objects(objects) == {i: s for s in SPLITS for i in data["splits"][s]}
    # A folder one cannot write into (here: the name is taken by a directory) -> the cache.
    path.unlink()
    (objects / SPLIT_FILE_NAME).mkdir()
    cached, _, _ = write_split_file(objects, 0.25, 0.25, seed=1)
    assert cached.is_relative_to(tmp_path / "cache") and find_split_file(objects) == cached


def _wpbench(*args: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from wpbench.cli import main; main()", *args],
                          capture_output=True, text=True, env=env, timeout=900)


@pytest.fixture()
def own_objects(tmp_path, decomposers, monkeypatch):  # noqa: F811
    """(folder of 4 microwaves + 4 dishwashers with a split file, env for CLI processes)."""
    monkeypatch.setenv("WPBENCH_CACHE", str(tmp_path / "cache"))
    objects = tmp_path / "objects"
    for category in ("microwave", "dishwasher"):
        for index in range(4):
            generate_object(category, index, objects)
    for folder in objects.iterdir():
        (folder / "wpbench.json").unlink()  # as a download: no wpbench metadata
    prepared = prepare_folder(objects, workers=2, progress=False, cache_dir=tmp_path / "cache" / "partnet",
                              decomposer=f"{decomposers}:exact")
    assert all(r.error is None for r in prepared)
    write_split_file(objects, val_fraction=0.25, test_fraction=0.25, seed=0)
    env = {**os.environ, "WPBENCH_CACHE": str(tmp_path / "cache"), "OMP_NUM_THREADS": "1"}
    return objects, env


@pytest.mark.slow
def test_own_objects_split_library_data_and_the_guard_against_test_data(own_objects, tmp_path):
    objects, env = own_objects
    split = split_of_objects(objects)
    # The library honours the split file; without a split it keeps every object.
    test_assets = load_library(objects, split="test")
    assert sorted(a.object_id for a in test_assets) == sorted(i for i, s in split.items() if s == "test")
    assert {a.category for a in test_assets} == {"microwave", "dishwasher"} and {a.split for a in test_assets} == {"test"}
    assert len(load_library(objects)) == 8

    data = tmp_path / "data"
    common = ("data", "generate", "--assets", str(objects), "--obs", "mesh", "--kind", "articulated",
              "--samples-per-kind", "10", "--scene-reuse", "5", "--no-progress", "--out")
    done = _wpbench(*common, str(data), "--split", "train", env=env)
    assert done.returncode == 0, done.stderr
    train = CrossPoseDataset(data / "train", kinds=("articulated",))
    assert set(train.object_ids) <= {i for i, s in split.items() if s == "train"} and len(train) == 10
    assert train.manifest["asset_split"]["test"] == sorted(i for i, s in split.items() if s == "test")

    # Test data put where training reads it is refused, by the dataset and by `wpbench train`.
    done = _wpbench(*common, str(tmp_path / "scored"), "--split", "test", env=env)
    assert done.returncode == 0, done.stderr
    leak = tmp_path / "leak"
    shutil.copytree(tmp_path / "scored" / "test", leak / "train")
    shutil.copytree(data / "train", leak / "val")
    with pytest.raises(ValueError, match="generated from the 'test' split"):
        CrossPoseDataset(leak / "train", kinds=("articulated",))
    done = _wpbench("train", "--policy", "gf", "--data", str(leak), "--steps", "1", "--out", str(tmp_path / "run"),
                    env=env)
    assert done.returncode != 0 and "generated from the 'test' split" in done.stderr

    # A split rewritten after the data was made moves train objects to test: that data is refused too.
    for seed in range(1, 50):
        write_split_file(objects, 0.25, 0.25, seed=seed)
        if set(train.object_ids) & {i for i, s in split_of_objects(objects).items() if s == "test"}:
            break
    with pytest.raises(ValueError, match="held-out"):
        CrossPoseDataset(data / "train", kinds=("articulated",))


def test_data_from_own_objects_needs_a_split_file(tmp_path):
    objects = tmp_path / "objects"
    _write_text_object(objects / "100", "Microwave")
    env = {**os.environ, "WPBENCH_CACHE": str(tmp_path / "cache")}
    done = _wpbench("data", "generate", "--assets", str(objects), "--split", "train", "--out", str(tmp_path / "d"),
                    env=env)
    assert done.returncode == 2 and f"run `wpbench assets split {objects}` first" in done.stderr


def test_a_run_uses_the_split_file_only_when_there_is_one(tmp_path, monkeypatch):
    from wpbench.assets.library import run_split

    monkeypatch.setenv("WPBENCH_CACHE", str(tmp_path / "cache"))
    objects = tmp_path / "objects"
    for i in range(3):
        _write_text_object(objects / f"{100 + i}", "Oven")
    assert run_split(objects, "test") is None and run_split("procedural", "test") == "test"
    write_split_file(objects, 0.34, 0.34, seed=0)
    assert run_split(objects, "test") == "test" and run_split(str(objects), "all") is None
