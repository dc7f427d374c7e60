"""The procedural furniture generator, the library cache and the ``wpbench assets`` commands."""

from __future__ import annotations

import hashlib
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wpbench.assets import library
from wpbench.assets.procedural import (
    CATEGORIES,
    GENERATOR_VERSION,
    TEST_PER_CATEGORY,
    build_blueprint,
    generate_library,
    generate_object,
)
from wpbench.assets.procedural.blueprint import MIN_CAVITY_EXTENT
from wpbench.assets.procedural.fridge import FridgeRanges
from wpbench.assets.procedural.generate import split_of
from wpbench.assets.procedural.parts import boxes_overlap
from wpbench.assets.procedural.storage import StorageRanges
from wpbench.assets.spec import FurnitureAsset
from wpbench.tasks.base import OPEN_TOLERANCE

# Outer size ranges a person would call realistic (width = y, depth = x, height = z), metres.
REALISTIC = {
    "oven": dict(width=(0.5, 0.8), height=(0.6, 1.2)),
    "microwave": dict(width=(0.4, 0.65), height=(0.25, 0.42)),
    "dishwasher": dict(width=(0.5, 0.65), height=(0.75, 0.92)),
    "fridge": dict(width=(0.55, 0.95), height=(1.2, 1.9)),
    "safe": dict(width=(0.3, 0.65), height=(0.35, 0.9)),
    "storage": dict(width=(0.45, 1.05), height=(0.5, 1.4)),
}


@pytest.fixture(scope="module")
def small_library(tmp_path_factory) -> tuple[Path, list[FurnitureAsset]]:
    out = tmp_path_factory.mktemp("lib")
    return out, generate_library(out, per_category=4, val_per_category=1, seed=3)


def _tree_digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


# ---------------------------------------------------------------- file layout
def test_every_object_folder_has_the_partnet_layout(small_library):
    out, assets = small_library
    assert len(assets) == 4 * len(CATEGORIES)
    for a in assets:
        folder = out / a.object_id
        for name in ("mobility.urdf", "semantics.txt", "meta.json", "wpbench.json"):
            assert (folder / name).is_file(), f"{a.object_id} lacks {name}"
        root = ET.parse(folder / "mobility.urdf").getroot()
        links = [l.get("name") for l in root.findall("link")]
        assert links[0] == "base" and links[1] == "link_0"
        assert links[2:] == [f"link_{k}" for k in range(1, len(links) - 1)]
        joints = root.findall("joint")
        assert [j.get("name") for j in joints] == [f"joint_{k}" for k in range(len(joints))]
        assert joints[0].get("type") == "fixed" and joints[0].find("parent").get("link") == "base"
        for j in joints[1:]:
            assert j.find("parent").get("link") == "link_0"
            assert float(j.find("limit").get("lower")) == 0.0
        # every mesh the URDF names exists; every link but base has collision pieces
        for mesh in root.iter("mesh"):
            assert (folder / mesh.get("filename")).is_file()
        for link in root.findall("link")[1:]:
            assert len(link.findall("collision")) >= 1 and len(link.findall("visual")) >= 1
        semantics = [line.split() for line in (folder / "semantics.txt").read_text().splitlines()]
        assert semantics[-1][:2] == ["link_0", "heavy"]
        kinds = {"revolute": ("hinge", "door"), "prismatic": ("slider", "drawer")}
        for link_name, joint_kind, part in semantics[:-1]:
            joint = next(j for j in joints if j.find("child").get("link") == link_name)
            assert (joint_kind, part) == kinds[joint.get("type")]
        meta = json.loads((folder / "meta.json").read_text())
        assert meta == {**meta, "category": a.category, "id": a.object_id, "seed": 3, "generator_version": GENERATOR_VERSION}
        assert FurnitureAsset.load(folder / "wpbench.json") == a


def test_target_joint_in_the_urdf_matches_the_asset(small_library):
    out, assets = small_library
    for a in assets:
        root = ET.parse(a.urdf).getroot()
        joint = next(j for j in root.findall("joint") if j.get("name") == a.target_joint)
        assert joint.get("type") == a.joint_type
        assert joint.find("child").get("link") == a.target_link
        assert float(joint.find("limit").get("upper")) == pytest.approx(a.open_qpos, abs=1e-9)
        assert a.closed_qpos == 0.0 and a.scale == 1.0 and a.front == (1.0, 0.0, 0.0)
        assert a.bounds_low[2] == 0.0


def test_split_json_is_disjoint_and_complete(small_library):
    out, assets = small_library
    split = json.loads((out / "split.json").read_text())
    assert set(split["train"]).isdisjoint(split["val"])
    assert sorted(split["train"] + split["val"]) == sorted(a.object_id for a in assets)
    for c in CATEGORIES:
        assert sum(i.startswith(c + "-") for i in split["val"]) == 1
    assert split["seed"] == 3


def test_default_split_has_12_train_and_4_val_per_category():
    splits = [split_of(i, 16, 4) for i in range(16)]
    assert splits.count("train") == 12 and splits.count("val") == 4


# ---------------------------------------------------------------- determinism
def test_same_seed_gives_byte_identical_files(tmp_path):
    a = generate_library(tmp_path / "a", per_category=2, val_per_category=1, seed=7, categories=["fridge", "storage"])
    b = generate_library(tmp_path / "b", per_category=2, val_per_category=1, seed=7, categories=["fridge", "storage"])
    assert [x.object_id for x in a] == [x.object_id for x in b]
    digest_a, digest_b = _tree_digest(tmp_path / "a"), _tree_digest(tmp_path / "b")
    assert digest_a == digest_b and len(digest_a) > 20
    c = generate_library(tmp_path / "c", per_category=2, val_per_category=1, seed=8, categories=["fridge", "storage"])
    assert _tree_digest(tmp_path / "c")["fridge-0000/mobility.urdf"] != digest_a["fridge-0000/mobility.urdf"]
    assert [x.in_region for x in c] != [x.in_region for x in a]


def test_an_instance_does_not_depend_on_library_size(tmp_path):
    alone = generate_object("oven", 1, tmp_path / "alone", seed=5)
    in_library = generate_library(tmp_path / "lib", per_category=3, val_per_category=1, seed=5, categories=["oven"])[1]
    assert alone.in_region == in_library.in_region
    assert alone.urdf.read_bytes() == in_library.urdf.read_bytes()


def test_extra_train_instances_keep_the_val_split_and_its_files(tmp_path):
    """Training furniture can grow without ever touching (or training on) the val instances."""
    base = generate_library(tmp_path / "base", per_category=4, val_per_category=1, seed=3, categories=["safe"])
    grown = generate_library(tmp_path / "grown", per_category=4, val_per_category=1, seed=3, categories=["safe"],
                             extra_train=3)
    base_split = json.loads((tmp_path / "base" / "split.json").read_text())
    grown_split = json.loads((tmp_path / "grown" / "split.json").read_text())
    assert grown_split["val"] == base_split["val"] == ["safe-0003"]
    assert grown_split["train"] == base_split["train"] + ["safe-0004", "safe-0005", "safe-0006"]
    assert grown_split["extra_train"] == 3
    for a, b in zip(base, grown):
        assert a.object_id == b.object_id and a.urdf.read_bytes() == b.urdf.read_bytes()


# ---------------------------------------------------------------- geometry invariants
def _door_transform(joint, q: float) -> np.ndarray:
    """4x4 body-frame motion of a child link's points when its joint goes from 0 to q."""
    origin, axis = np.asarray(joint.origin), np.asarray(joint.axis)
    T = np.eye(4)
    if joint.kind == "prismatic":
        T[:3, 3] = axis * q
        return T
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(q) * k + (1 - np.cos(q)) * k @ k
    T[:3, :3] = R
    T[:3, 3] = origin - R @ origin
    return T


def _corners(bounds: np.ndarray) -> np.ndarray:
    return np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(category=st.sampled_from(CATEGORIES), index=st.integers(0, 10_000), seed=st.integers(0, 2**31 - 1))
def test_any_instance_keeps_its_promises(category, index, seed):
    bp = build_blueprint(category, index, seed)
    low, high = bp.model.bounds()
    region = bp.in_region
    # the cavity fits a 16 cm block with margin, and lies within the object
    assert np.all(region[1] - region[0] >= MIN_CAVITY_EXTENT - 1e-9)
    body = [p.bounds() for p in bp.model.links[0].parts if p.collide]
    for b in body:
        assert not boxes_overlap(region, b, tol=1e-6), f"in-region cuts into a body part {b.round(3)}"
    joint = next(j for j in bp.model.joints if j.name == bp.target_joint)
    target = bp.model.link(bp.target_link)
    if bp.joint_type == "prismatic":
        moved = _door_transform(joint, bp.open_qpos)
        for part in target.parts:
            if part.collide:  # the open drawer's own walls are around, not inside, the region
                assert not boxes_overlap(region, part.bounds() + moved[:3, 3], tol=1e-6)
    else:
        assert np.all(region[0] >= low - 1e-9) and np.all(region[1] <= high + 1e-9)
    # size is realistic
    width, height = high[1] - low[1], high[2] - low[2]
    w_range, h_range = REALISTIC[category]["width"], REALISTIC[category]["height"]
    assert w_range[0] <= width <= w_range[1] and h_range[0] <= height <= h_range[1], (width, height)
    # sweeping every moving part from closed to open never puts a corner inside the body,
    # and opening moves the part towards the front (+x)
    for link in bp.model.links[1:]:
        j = next(j for j in bp.model.joints if j.child == link.name)
        corners = np.concatenate([_corners(p.bounds()) for p in link.parts if p.collide])
        for q in np.linspace(0.0, j.upper, 13):
            T = _door_transform(j, q)
            moved = corners @ T[:3, :3].T + T[:3, 3]
            for b in body:
                inside = np.all((moved > b[0] + 1e-4) & (moved < b[1] - 1e-4), axis=1)
                assert not inside.any(), f"{link.name} at q={q:.2f} enters the body"
        # (a door opened 180 degrees lies flat again, so look at the start of the motion)
        T = _door_transform(j, min(0.3, j.upper))
        opened_x = (corners @ T[:3, :3].T + T[:3, 3])[:, 0].mean()
        assert opened_x > corners[:, 0].mean() + 0.01, f"{link.name}: increasing q does not open towards +x"


def test_instances_vary_in_shape_handles_and_hinges():
    for c in CATEGORIES:
        bps = [build_blueprint(c, i, 0) for i in range(16)]
        sizes = np.array([bp.model.bounds()[1] - bp.model.bounds()[0] for bp in bps])
        assert np.all(sizes.std(axis=0) > 0.005), f"{c}: sizes hardly vary {sizes.std(axis=0)}"
        assert len({bp.extra["handle_type"] for bp in bps}) >= 2, c
        assert len({bp.extra["wall_thickness"] for bp in bps}) >= 8, c
        if c in ("microwave", "fridge", "safe"):
            assert {bp.extra["hinge"] for bp in bps} == {"left", "right"}, c
    assert len({build_blueprint("fridge", i, 0).extra["style"] for i in range(16)}) == 3
    fridge_stops = np.rad2deg([build_blueprint("fridge", i, 0).open_qpos for i in range(16)])
    assert fridge_stops.min() >= 137 and fridge_stops.max() <= 150 and fridge_stops.std() > 3
    _middle_passes_every_stop(FridgeRanges().open_angle_deg)


def _middle_passes_every_stop(stop_range_deg):
    """A policy that cannot see a hidden stop predicts the range's middle; that angle must
    pass the success tolerance (1 - OPEN_TOLERANCE of the way) for the highest stop, with
    at least 5 deg to spare."""
    lower, upper = stop_range_deg
    assert upper / lower <= 1.1
    assert (lower + upper) / 2 >= (1 - OPEN_TOLERANCE) * upper + 5


def test_storage_is_drawer_chests_and_door_cabinets_with_both_hinge_sides():
    bps = [build_blueprint("storage", i, 0) for i in range(40)]
    chests = [bp for bp in bps if bp.extra["style"] == "drawer_chest"]
    cabinets = [bp for bp in bps if bp.extra["style"] == "door_cabinet"]
    assert len(chests) >= 10 and len(cabinets) >= 10
    assert {bp.joint_type for bp in chests} == {"prismatic"} and {bp.joint_type for bp in cabinets} == {"revolute"}
    assert {bp.extra["hinge"] for bp in cabinets} == {"left", "right"}
    assert {bp.extra["doors"] for bp in cabinets} == {1, 2}
    stops = np.rad2deg([bp.open_qpos for bp in cabinets])
    assert stops.min() >= 119 and stops.max() <= 130 and stops.std() > 2
    _middle_passes_every_stop(StorageRanges().door_open_deg)


def test_unknown_category_is_rejected_with_the_valid_names(tmp_path):
    with pytest.raises(ValueError, match="valid categories: oven, microwave"):
        build_blueprint("bathtub", 0)
    with pytest.raises(ValueError, match="bathtub"):
        generate_library(tmp_path, per_category=2, val_per_category=1, categories=["bathtub"])
    with pytest.raises(ValueError, match="val_per_category"):
        generate_library(tmp_path, per_category=2, val_per_category=2)


# ---------------------------------------------------------------- library / cache
def test_load_library_filters_by_split_and_category(small_library):
    out, _ = small_library
    val = library.load_library(out, split="val")
    assert len(val) == len(CATEGORIES) and all(a.split == "val" for a in val)
    assert len(library.load_library(out)) == 4 * len(CATEGORIES)
    ovens = library.load_library(out, split="train", categories=["oven"])
    assert [a.object_id for a in ovens] == ["oven-0000", "oven-0001", "oven-0002"]
    with pytest.raises(ValueError, match="has no test instances"):
        library.load_library(out, split="test")
    with pytest.raises(ValueError, match="valid splits: train, val, test"):
        library.load_library(out, split="holdout")
    with pytest.raises(ValueError, match="valid categorys: .*microwave"):
        library.load_library(out, categories=["bathtub"])
    with pytest.raises(ValueError, match="neither 'procedural' nor an existing folder"):
        library.load_library(out / "missing")


def test_the_furniture_pool_hash_changes_with_a_missing_object_or_another_order(small_library):
    out, _ = small_library
    pool = library.load_library(out, split="train")
    digest = library.furniture_pool_digest(pool)
    assert digest == library.furniture_pool_digest(library.load_library(out, split="train"))  # same folder, same hash
    assert library.furniture_pool_digest(pool[:-1]) != digest  # one object skipped
    assert library.furniture_pool_digest(pool[::-1]) != digest  # same objects, other draws
    assert library.furniture_pool_digest(library.load_library(out, split="val")) != digest


def test_procedural_library_is_generated_once_into_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("WPBENCH_CACHE", str(tmp_path))
    folder = library.procedural_library(seed=2, per_category=2)
    assert folder == tmp_path / "procedural" / f"seed-2-n2-v{GENERATOR_VERSION}-t{TEST_PER_CATEGORY}"
    assert (folder / "split.json").is_file()
    stamp = (folder / "split.json").stat().st_mtime_ns
    assert library.procedural_library(seed=2, per_category=2) == folder
    assert (folder / "split.json").stat().st_mtime_ns == stamp  # not regenerated
    assert [p.name for p in folder.parent.iterdir()] == [folder.name]  # no temporary folder left
    assets = library.load_library("procedural", split="val", seed=2, per_category=2)
    assert len(assets) == len(CATEGORIES) and {a.split for a in assets} == {"val"}


def test_a_crash_during_generation_leaves_nothing_behind(tmp_path, monkeypatch):
    import wpbench.assets.procedural as procedural

    def explode(out, **kwargs):
        Path(out, "half-written").write_text("x")
        raise RuntimeError("disk full")

    monkeypatch.setattr(procedural, "generate_library", explode)
    with pytest.raises(RuntimeError, match="disk full"):
        library.procedural_library(seed=0, per_category=2, cache_dir=tmp_path)
    assert list((tmp_path / "procedural").iterdir()) == []


# ---------------------------------------------------------------- CLI
def test_cli_generate_and_list(tmp_path):
    from typer.testing import CliRunner

    from wpbench.cli.assets_cmd import app

    runner = CliRunner()
    out = tmp_path / "lib"
    result = runner.invoke(app, ["generate", "--out", str(out), "--per-category", "2", "--seed", "4", "--category", "safe", "--category", "oven"])
    assert result.exit_code == 0, result.output
    assert "wrote 20 objects (2 train, 2 val, 16 test)" in result.output
    assert json.loads((out / "split.json").read_text())["val"] == ["safe-0001", "oven-0001"]
    result = runner.invoke(app, ["list", "--assets", str(out), "--split", "train"])
    assert result.exit_code == 0, result.output
    assert "safe-0000" in result.output and "oven-0000" in result.output and "2 assets" in result.output
    result = runner.invoke(app, ["generate", "--out", str(out), "--category", "bathtub"])
    assert result.exit_code == 2 and "valid: oven, microwave" in result.output
    result = runner.invoke(app, ["show", "nothing-0000", "--out", str(tmp_path / "x.png"), "--assets", str(out)])
    assert result.exit_code == 2 and "no asset 'nothing-0000'" in result.output


@pytest.mark.render
@pytest.mark.slow
def test_cli_show_renders_closed_and_open(tmp_path):
    from PIL import Image
    from typer.testing import CliRunner

    from wpbench.cli.assets_cmd import app

    out = tmp_path / "lib"
    generate_library(out, per_category=2, val_per_category=1, seed=0, categories=["microwave"])
    png = tmp_path / "mw.png"
    result = CliRunner().invoke(app, ["show", "microwave-0000", "--out", str(png), "--assets", str(out), "--width", "160"])
    assert result.exit_code == 0, result.output
    image = np.asarray(Image.open(png).convert("RGB")).astype(float)
    assert image.shape == (160 + 24, 320, 3)
    closed, opened = image[24:, :160], image[24:, 160:]
    assert closed.std() > 10 and opened.std() > 10  # something was drawn
    assert np.abs(closed - opened).mean() > 3  # the door moved between the two views


@pytest.mark.parametrize("front", [(1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.6, -0.8, 0.0)])
def test_render_camera_looks_at_the_front_whatever_way_it_faces(front):
    """PartNet-Mobility doors face -x: the camera must follow ``asset.front``, not assume +x."""
    from wpbench.assets.render import RenderConfig, camera_direction

    config = RenderConfig(azimuth_deg=35.0, elevation_deg=25.0)
    direction = camera_direction(front, config)
    assert np.linalg.norm(direction) == pytest.approx(1.0)
    horizontal = direction[:2] / np.linalg.norm(direction[:2])
    cos_to_front = float(horizontal @ np.asarray(front[:2]) / np.linalg.norm(front[:2]))
    assert cos_to_front == pytest.approx(np.cos(np.radians(35.0)))
    assert direction[2] == pytest.approx(np.sin(np.radians(25.0)))


def test_render_camera_rejects_a_vertical_front():
    from wpbench.assets.render import camera_direction

    with pytest.raises(ValueError, match="horizontal direction"):
        camera_direction((0.0, 0.0, 1.0))
