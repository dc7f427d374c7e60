"""The held-out test split of the built-in procedural library.

Test instances are new furniture, numbered apart from train and val; adding them must
leave every train and val instance byte for byte as it was (the published val numbers
were measured on those files).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from wpbench.assets import library
from wpbench.assets.procedural import CATEGORIES, GENERATOR_VERSION, TEST_FIRST_INDEX, TEST_PER_CATEGORY, generate_library
from wpbench.assets.procedural.generate import split_of
from wpbench.names import SPLITS

# sha256 over "<relative path> <sha256 of the file>" lines of every file of the 24 val
# instances of the built-in library (seed 0, 16 per category), per generator version: 2 as
# written before the test split existed; 3 and 4 as the weights of releases 3 and 4 were trained
# and scored on.
VAL_DIGEST = {
    2: "8eaac29e26255f5fb8bff8b831d47a72f1654ddaa50baf7c2d08f7a4864b09f1",
    3: "3356fc9596311446b50a7ab8b239d16a424356a60e21f188f6520ab8f0fd1451",
    4: "db8f68d77fa577ea7a719e44fb4908c70d377eb3b7e0d7ba704c75c97d64c696",
}


def _files_digest(root: Path, object_ids: list[str]) -> str:
    lines = []
    for object_id in sorted(object_ids):
        for path in sorted((root / object_id).rglob("*")):
            if path.is_file():
                lines.append(f"{path.relative_to(root)} {hashlib.sha256(path.read_bytes()).hexdigest()}")
    return hashlib.sha256("\n".join(lines).encode()).hexdigest()


def _geometry_digest(folder: Path) -> str:
    """Digest of an object's URDF and meshes, without its id (two objects of equal shape match)."""
    h = hashlib.sha256()
    for path in sorted(folder.rglob("*")):
        if path.is_file() and path.suffix in (".urdf", ".obj"):
            h.update(path.read_bytes().replace(folder.name.encode(), b""))
    return h.hexdigest()


@pytest.fixture(scope="module")
def builtin(tmp_path_factory) -> Path:
    cache = tmp_path_factory.mktemp("cache")
    return library.procedural_library(seed=0, per_category=16, cache_dir=cache)


def test_test_is_a_split_of_the_library():
    assert "test" in SPLITS


def test_builtin_library_has_eight_or_more_test_instances_per_category(builtin):
    split = json.loads((builtin / "split.json").read_text())
    assert TEST_PER_CATEGORY >= 8
    for category in CATEGORIES:
        ids = [i for i in split["test"] if i.startswith(category + "-")]
        assert len(ids) == TEST_PER_CATEGORY, category
    assert len(split["train"]) == 12 * len(CATEGORIES) and len(split["val"]) == 4 * len(CATEGORIES)


def test_test_instances_share_no_id_and_no_geometry_with_train_or_val(builtin):
    split = json.loads((builtin / "split.json").read_text())
    test, seen = set(split["test"]), set(split["train"]) | set(split["val"])
    assert test.isdisjoint(seen)
    test_shapes = {_geometry_digest(builtin / i) for i in test}
    seen_shapes = {_geometry_digest(builtin / i) for i in seen}
    assert len(test_shapes) == len(test)  # every test instance is a shape of its own
    assert test_shapes.isdisjoint(seen_shapes)


def test_val_instances_are_the_files_published_numbers_were_measured_on(builtin, tmp_path):
    split = json.loads((builtin / "split.json").read_text())
    without_test = tmp_path / "without-test"
    generate_library(without_test, per_category=16, val_per_category=4, seed=0)
    for s in ("train", "val"):
        assert _files_digest(builtin, split[s]) == _files_digest(without_test, split[s]), s
    if GENERATOR_VERSION not in VAL_DIGEST:
        pytest.skip(f"no recorded val digest for generator version {GENERATOR_VERSION}")
    assert _files_digest(builtin, split["val"]) == VAL_DIGEST[GENERATOR_VERSION]


def test_load_library_returns_the_test_split(tmp_path, monkeypatch):
    monkeypatch.setenv("WPBENCH_CACHE", str(tmp_path))
    test = library.load_library("procedural", split="test", seed=1, per_category=2)
    assert len(test) == TEST_PER_CATEGORY * len(CATEGORIES)
    assert {a.split for a in test} == {"test"}
    everything = library.load_library("procedural", seed=1, per_category=2)
    assert {a.split for a in everything} == {"train", "val", "test"}
    fridges = library.load_library("procedural", split="test", seed=1, per_category=2, categories=["fridge"])
    assert [a.object_id for a in fridges] == [f"fridge-{TEST_FIRST_INDEX + k:04d}" for k in range(TEST_PER_CATEGORY)]


def test_extra_training_instances_never_reach_a_test_or_val_instance(tmp_path):
    grown = generate_library(tmp_path / "grown", per_category=4, val_per_category=1, seed=0, categories=["safe"],
                             extra_train=5, test_per_category=2)
    by_split = {s: [a.object_id for a in grown if a.split == s] for s in SPLITS}
    assert by_split["val"] == ["safe-0003"]
    assert by_split["test"] == [f"safe-{TEST_FIRST_INDEX:04d}", f"safe-{TEST_FIRST_INDEX + 1:04d}"]
    assert by_split["train"] == ["safe-0000", "safe-0001", "safe-0002"] + [f"safe-{i:04d}" for i in range(4, 9)]
    with pytest.raises(ValueError, match=f"at most {TEST_FIRST_INDEX}"):
        generate_library(tmp_path / "too-many", per_category=16, extra_train=TEST_FIRST_INDEX - 15, categories=["safe"])
    # Whatever the library size, an index below TEST_FIRST_INDEX is never test, and none from it is anything else.
    for per_category, val in ((16, 4), (2, 1), (TEST_FIRST_INDEX, 10)):
        assert all(split_of(i, per_category, val) != "test" for i in range(0, TEST_FIRST_INDEX, 97))
        assert split_of(TEST_FIRST_INDEX, per_category, val) == "test"


def test_extra_train_library_has_the_same_val_and_test_instances(tmp_path, monkeypatch):
    monkeypatch.setenv("WPBENCH_CACHE", str(tmp_path))
    plain = library.procedural_library(seed=0, per_category=2)
    grown = library.procedural_library(seed=0, per_category=2, extra_train=3)
    assert plain != grown
    plain_split = json.loads((plain / "split.json").read_text())
    grown_split = json.loads((grown / "split.json").read_text())
    for s in ("val", "test"):
        assert grown_split[s] == plain_split[s]
        assert _files_digest(grown, grown_split[s]) == _files_digest(plain, plain_split[s])
