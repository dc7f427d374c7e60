"""The PartNet-Mobility loader on the real objects in ../shared/partnet-mobility (skipped if absent).

Objects without a dataset convex decomposition need CoACD (~1 min per object on
2 cores, computed once into the default cache, so later runs are fast); their
tests are marked ``slow``. Oven 101773 ships ``mobility_cvx.urdf`` and is fast.
"""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wpbench.assets import collision as collision_module
from wpbench.assets.cavity import VoxelGrid, door_cavity, drawer_inner_volume, largest_box, occupancy
from wpbench.assets.partnet import (
    CATEGORY_TYPICAL_SIZE_M,
    DEFAULT_TYPICAL_SIZE_M,
    PartNetLoadConfig,
    PartNetLoadError,
    category_scale,
    link_pieces,
    load_collision_articulation,
    load_partnet_folder,
    load_partnet_object,
    normalise_category,
    typical_size,
)

DATASET = Path(os.environ.get("WPBENCH_PARTNET_DIR", Path(__file__).parents[1].parent / "shared" / "partnet-mobility"))
needs_dataset = pytest.mark.skipif(
    not DATASET.is_dir(), reason=f"PartNet-Mobility objects not found at {DATASET} (set WPBENCH_PARTNET_DIR)"
)

# Target per object, read off each folder's semantics.txt / mobility.urdf:
# (link, joint, joint type, (closed, open) limits). 12036 has two doors: link_0 is the bigger one.
EXPECTED = {
    "101773": ("link_0", "joint_0", "revolute", (0.0, math.pi / 2)),  # oven: door; knobs/buttons ignored
    "7310": ("link_0", "joint_0", "revolute", (0.0, math.pi / 2)),  # microwave
    "11700": ("link_0", "joint_0", "revolute", (0.0, math.pi / 2)),  # dishwasher: rotation_door
    "12036": ("link_0", "joint_0", "revolute", (0.0, math.pi)),  # fridge: two doors
    "45213": ("link_0", "joint_0", "revolute", (0.0, 2.261946710584651)),  # storage: door beats drawers
}
FAST = {"101773"}  # ships mobility_cvx.urdf: no CoACD
OBJECT_IDS = [oid if oid in FAST else pytest.param(oid, marks=pytest.mark.slow) for oid in EXPECTED]


@pytest.fixture(scope="session")
def load_asset():
    """Loads each object once per session (collision cache: the default one, reused across runs)."""
    cache: dict = {}

    def load(object_id: str):
        if object_id not in cache:
            cache[object_id] = load_partnet_object(DATASET / object_id)
        return cache[object_id]

    return load


def _set_closed(articulation, asset, overrides=None):
    values = {**asset.extra["closed_qpos_by_joint"], **(overrides or {})}
    names = [j.name for j in articulation.get_active_joints()]
    qpos = np.array([values[n] for n in names], dtype=np.float32)
    articulation.set_qpos(qpos)
    return qpos


# --------------------------------------------------------------------------- real objects


@needs_dataset
@pytest.mark.parametrize("object_id", OBJECT_IDS)
def test_target_joint_and_limits(load_asset, object_id):
    asset = load_asset(object_id)
    link, joint, joint_type, (closed, opened) = EXPECTED[object_id]
    assert (asset.target_link, asset.target_joint, asset.joint_type) == (link, joint, joint_type)
    assert asset.closed_qpos == pytest.approx(closed, abs=1e-5)
    assert asset.extra["open_qpos_limit"] == pytest.approx(opened, abs=1e-5)
    if object_id == "12036":
        # The fridge's handle meets its side wall before the pi limit: the goal is where
        # physics stops the door, backed off a little, and well past a right angle.
        assert math.pi / 2 < asset.open_qpos < opened - 0.1
    else:
        assert asset.open_qpos == pytest.approx(opened, abs=1e-5)
    assert asset.source == "partnet-mobility"
    assert asset.urdf.is_file() and DATASET not in asset.urdf.parents  # cache lives outside the dataset


@needs_dataset
@pytest.mark.parametrize("object_id", OBJECT_IDS)
def test_scaled_to_category_size_and_front_is_door_normal(load_asset, object_id):
    asset = load_asset(object_id)
    sides = np.asarray(asset.bounds_high) - np.asarray(asset.bounds_low)
    assert sides.max() == pytest.approx(typical_size(asset.category), rel=1e-3)
    front = np.asarray(asset.front)
    assert np.linalg.norm(front) == pytest.approx(1.0) and front[2] == 0.0
    # The closed door sits on the front face of the object: its outer side is near the
    # object's extreme along `front` (handles attached as extra links may stick out further).
    scene, articulation = load_collision_articulation(asset.urdf, asset.scale)
    _set_closed(articulation, asset)
    door = np.concatenate(link_pieces(next(l for l in articulation.get_links() if l.name == asset.target_link)))
    corners = np.array([[x, y, z] for x in (asset.bounds_low[0], asset.bounds_high[0])
                        for y in (asset.bounds_low[1], asset.bounds_high[1])
                        for z in (asset.bounds_low[2], asset.bounds_high[2])])
    assert (door @ front).max() >= (corners @ front).max() - 0.05 * sides.max()
    assert (door @ front).max() > (corners @ front).min() + 0.9 * np.ptp(corners @ front)


@needs_dataset
@pytest.mark.parametrize("object_id", OBJECT_IDS)
def test_in_region_inside_bounds_and_behind_door(load_asset, object_id):
    asset = load_asset(object_id)
    region = asset.in_region
    corners = region.corners()
    assert np.all(corners >= np.asarray(asset.bounds_low) - 1e-9)
    assert np.all(corners <= np.asarray(asset.bounds_high) + 1e-9)
    assert min(region.half_extents) >= 0.03  # holds a 6 cm block
    scene, articulation = load_collision_articulation(asset.urdf, asset.scale)
    _set_closed(articulation, asset)
    door = np.concatenate(link_pieces(next(l for l in articulation.get_links() if l.name == asset.target_link)))
    front = np.asarray(asset.front)
    # Behind the door: the whole region is on the inner side of the door's outer face,
    # and its centre behind the door's inner face.
    assert (corners @ front).max() <= (door @ front).max()
    assert np.asarray(region.center) @ front < (door @ front).min()


@needs_dataset
@pytest.mark.parametrize("object_id", OBJECT_IDS)
def test_block_dropped_in_open_cavity_stays_inside(load_asset, object_id):
    import sapien

    asset = load_asset(object_id)
    scene, articulation = load_collision_articulation(asset.urdf, asset.scale)
    scene.set_timestep(1 / 240)
    qpos = _set_closed(articulation, asset, {asset.target_joint: asset.open_qpos})
    for joint, target in zip(articulation.get_active_joints(), qpos):
        joint.set_drive_property(stiffness=1e5, damping=1e3)
        joint.set_drive_target(float(target))
    builder = scene.create_actor_builder()
    builder.add_box_collision(half_size=[0.03, 0.03, 0.03], density=0.1 / 0.06**3)  # 6 cm, 0.1 kg
    block = builder.build()
    block.set_pose(sapien.Pose(p=list(asset.in_region.center)))
    for _ in range(480):  # 2 s
        scene.step()
    assert asset.in_region.contains(block.pose.p), f"block rests at {block.pose.p}, region {asset.in_region}"
    body = block.find_component_by_type(sapien.physx.PhysxRigidDynamicComponent)
    assert np.linalg.norm(body.linear_velocity) < 0.05  # at rest, not passing through


@needs_dataset
def test_broken_folders_are_reported_and_others_still_load(tmp_path):
    root = tmp_path / "objects"
    root.mkdir()
    (root / "101773").symlink_to(DATASET / "101773", target_is_directory=True)
    corrupt = root / "corrupt_urdf"
    shutil.copytree(DATASET / "7310", corrupt)
    (corrupt / "mobility.urdf").write_text("<robot name='x'><link name='base'>")  # truncated XML
    no_semantics = root / "no_semantics"
    shutil.copytree(DATASET / "7310", no_semantics)
    (no_semantics / "semantics.txt").unlink()
    no_door = root / "no_door"
    shutil.copytree(DATASET / "7310", no_door)
    (no_door / "semantics.txt").write_text("link_0 hinge knob\nlink_1 heavy microwave_body\n")

    assets, failures = load_partnet_folder(root, cache_dir=tmp_path / "cache")

    assert [a.object_id for a in assets] == ["101773"]
    assert set(failures) == {"corrupt_urdf", "no_semantics", "no_door"}
    assert "mobility.urdf" in failures["corrupt_urdf"] and "restore" in failures["corrupt_urdf"]
    assert "semantics.txt is missing" in failures["no_semantics"]
    assert "no door" in failures["no_door"]
    with pytest.raises(PartNetLoadError, match="semantics.txt"):
        load_partnet_object(no_semantics)


@needs_dataset
def test_single_object_folder_and_scale_override(load_asset, tmp_path):
    default = load_asset("101773")
    assets, failures = load_partnet_folder(DATASET / "101773", scale_override={"oven": 1.0})
    assert failures == {} and len(assets) == 1
    assert assets[0].scale == 1.0 and assets[0].extra["scale_source"] == "override"
    ratio = (np.asarray(assets[0].bounds_high) - np.asarray(assets[0].bounds_low)) / (
        np.asarray(default.bounds_high) - np.asarray(default.bounds_low))
    assert np.allclose(ratio, 1.0 / default.scale, rtol=1e-4)
    by_id = load_partnet_object(DATASET / "101773", scale={"101773": 0.5, "oven": 2.0})
    assert by_id.scale == 0.5  # the object id wins over the category
    with pytest.raises(PartNetLoadError, match="positive"):
        load_partnet_object(DATASET / "101773", scale=-1.0)


@needs_dataset
@pytest.mark.slow
def test_drawer_target_region_is_the_open_drawer_inside(tmp_path):
    # 45213's drawers are shallow (~3 cm inside at a realistic size): enlarged, the
    # drawer path must find the drawer's inner volume in the open state.
    # Its coacd pieces jam the drawer's slide, so the reach probe would refuse it: off here,
    # this test is about the drawer geometry.
    asset = load_partnet_object(DATASET / "45213", target_link="link_1", scale=1.5,
                                config=PartNetLoadConfig(probe_reach=False))
    assert (asset.target_joint, asset.joint_type) == ("joint_1", "prismatic")
    assert asset.closed_qpos == pytest.approx(0.0) and asset.open_qpos == pytest.approx(0.88 * 1.5, rel=1e-5)
    assert asset.extra["in_region_state"] == "open"
    scene, articulation = load_collision_articulation(asset.urdf, asset.scale)
    _set_closed(articulation, asset, {asset.target_joint: asset.open_qpos})
    drawer = np.concatenate(link_pieces(next(l for l in articulation.get_links() if l.name == "link_1")))
    corners = asset.in_region.corners()
    assert np.all(corners >= drawer.min(0) - 1e-6) and np.all(corners <= drawer.max(0) + 1e-6)
    with pytest.raises(PartNetLoadError, match="not a door or drawer"):
        load_partnet_object(DATASET / "45213", target_link="link_3")


# --------------------------------------------------------------------------- cache behaviour


@needs_dataset
def test_collision_cache_is_reused(tmp_path):
    first = collision_module.build_hollow_collision_urdf(DATASET / "101773", tmp_path / "cvx")
    again = collision_module.build_hollow_collision_urdf(DATASET / "101773", tmp_path / "cvx")
    assert first.source == "dataset-cvx" and first.computed_now and again.computed_now == ()
    assert again.urdf == first.urdf and first.fallbacks == {}


# --------------------------------------------------------------------------- category table


def test_category_names_and_scale_table():
    assert normalise_category("Refrigerator") == "fridge"
    assert normalise_category("StorageFurniture") == "storage"
    assert normalise_category("Microwave") == "microwave"
    assert typical_size("Refrigerator") == CATEGORY_TYPICAL_SIZE_M["fridge"]
    assert typical_size("spaceship") == DEFAULT_TYPICAL_SIZE_M
    assert category_scale("microwave", 1.3) == pytest.approx(CATEGORY_TYPICAL_SIZE_M["microwave"] / 1.3)
    with pytest.raises(PartNetLoadError):
        category_scale("microwave", 0.0)


# --------------------------------------------------------------------------- cavity search (synthetic)


def _slab(low, high):
    low, high = np.asarray(low, float), np.asarray(high, float)
    return np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])


def test_door_cavity_of_a_hollow_box_is_its_inside():
    t = 0.02  # wall thickness; inside is [-0.2, 0.2] x [-0.15, 0.15] x [0, 0.3]
    walls = [
        _slab([-0.22, -0.17, -t], [0.2, 0.17, 0.0]),  # floor
        _slab([-0.22, -0.17, 0.3], [0.2, 0.17, 0.3 + t]),  # roof
        _slab([-0.22, -0.17, 0.0], [-0.2, 0.17, 0.3]),  # back
        _slab([-0.2, -0.17, 0.0], [0.2, -0.15, 0.3]),  # sides
        _slab([-0.2, 0.15, 0.0], [0.2, 0.17, 0.3]),
    ]
    door = [_slab([0.2, -0.17, -t], [0.22, 0.17, 0.3 + t])]
    box = door_cavity(walls, door, np.array([-0.22, -0.17, -t]), np.array([0.22, 0.17, 0.3 + t]))
    low = np.asarray(box.center) - box.half_extents
    high = np.asarray(box.center) + box.half_extents
    assert np.all(low >= [-0.2, -0.15, 0.0 - 1e-9]) and np.all(high <= [0.2, 0.15, 0.3])
    assert low[2] == pytest.approx(0.0, abs=1e-6)  # bottom dropped onto the floor
    assert np.all(high - low >= [0.3, 0.22, 0.22])  # most of the inside, not a sliver
    # Without the door nothing is "closed by it": no cavity.
    assert door_cavity(walls + door, [], np.array([-0.22, -0.17, -t]), np.array([0.22, 0.17, 0.3 + t])) is None


def test_drawer_inner_volume_of_an_open_tray():
    tray = [
        _slab([-0.2, -0.15, 0.0], [0.2, 0.15, 0.01]),
        _slab([-0.2, -0.15, 0.0], [-0.19, 0.15, 0.1]),
        _slab([0.19, -0.15, 0.0], [0.2, 0.15, 0.1]),
        _slab([-0.2, -0.15, 0.0], [0.2, -0.14, 0.1]),
        _slab([-0.2, 0.14, 0.0], [0.2, 0.15, 0.1]),
    ]
    box = drawer_inner_volume(tray)
    low = np.asarray(box.center) - box.half_extents
    high = np.asarray(box.center) + box.half_extents
    assert np.all(low >= [-0.19, -0.14, 0.01 - 1e-6]) and np.all(high <= [0.19, 0.14, 0.1])
    assert np.all(high - low >= [0.3, 0.2, 0.06])


def test_occupancy_never_misses_a_wall_thinner_than_a_voxel():
    grid = VoxelGrid.covering(np.zeros(3), np.ones(3), 10)
    occ = occupancy([_slab([0.0, 0.0, 0.503], [1.0, 1.0, 0.506])], grid)
    assert occ[:, :, 5].all()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), min_size=48, max_size=48))
def test_largest_box_matches_brute_force(bits):
    mask = np.array(bits).reshape(4, 3, 4)
    found = largest_box(mask)
    best = 0
    for lo in np.ndindex(*mask.shape):
        for hi in np.ndindex(*mask.shape):
            if all(h >= l for l, h in zip(lo, hi)):
                sub = mask[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1, lo[2]:hi[2] + 1]
                if sub.all():
                    best = max(best, sub.size)
    if best == 0:
        assert found is None
    else:
        lo, hi = found
        assert mask[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]].all()
        assert int(np.prod(hi - lo)) == best
