"""The Ravens objects: Ravens' sizes, convex collision pieces, scaling, symmetry groups."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from wpbench.assets.ravens import RAVENS_OBJECTS, get_ravens_object

NAMES = tuple(RAVENS_OBJECTS)


def test_the_five_ravens_objects_exist():
    assert set(NAMES) == {"block", "ell", "disk", "slimdisk", "bowl"}


def test_block_is_ravens_red_4cm_cube_of_100g():
    block = get_ravens_object("block")
    extents = block.visual_mesh(1.0).extents
    np.testing.assert_allclose(extents, [0.04, 0.04, 0.04], atol=1e-9)
    assert block.mass == pytest.approx(0.1)
    np.testing.assert_allclose(block.rgba[:3], np.array([255, 87, 89]) / 255, atol=1.5 / 255)
    assert block.scale_range == (2.0, 4.0)  # TAX-Pose: 8 to 16 cm
    assert block.half_height(4.0) == pytest.approx(0.08)


@pytest.mark.parametrize(
    "name, extents",
    [
        ("ell", (0.08, 0.08, 0.04)),  # arms 0.08 long, 0.03 wide, overlapping at the corner
        ("disk", (0.06, 0.06, 0.01)),
        ("slimdisk", (0.09, 0.09, 0.005)),
        ("bowl", (0.12, 0.12, 0.045)),
    ],
)
def test_sizes_follow_ravens(name, extents):
    obj = get_ravens_object(name)
    np.testing.assert_allclose(obj.visual_mesh(1.0).extents, extents, atol=2e-3)


@pytest.mark.parametrize("name", NAMES)
def test_collision_pieces_are_convex_and_fill_the_visual_shape(name):
    obj = get_ravens_object(name)
    visual = obj.visual_mesh(1.0)
    parts = obj.collision_parts(1.0)
    assert visual.is_watertight and visual.volume > 0
    for part in parts:
        assert part.is_convex and part.volume > 0
        assert np.all(part.bounds[0] >= visual.bounds[0] - 1e-6) and np.all(part.bounds[1] <= visual.bounds[1] + 1e-6)
    # The pieces tile the object: same volume within 3% (ring pieces slightly fill the hole).
    assert sum(p.volume for p in parts) == pytest.approx(visual.volume, rel=0.03)


@pytest.mark.parametrize("name", ["ell", "disk", "slimdisk", "bowl"])
def test_concave_objects_are_split_into_several_pieces(name):
    obj = get_ravens_object(name)
    parts = obj.collision_parts(1.0)
    assert len(parts) >= 2
    hull = trimesh.convex.convex_hull(obj.visual_mesh(1.0).vertices)
    assert hull.volume > obj.visual_mesh(1.0).volume * 1.1  # really concave: the hull is bigger


@settings(max_examples=25, deadline=None)
@given(name=st.sampled_from(NAMES), scale=st.floats(0.5, 5.0))
def test_scaling_scales_every_length(name, scale):
    obj = get_ravens_object(name)
    base = obj.visual_mesh(1.0)
    scaled = obj.visual_mesh(scale)
    np.testing.assert_allclose(scaled.extents, base.extents * scale, rtol=1e-9, atol=1e-12)
    assert sum(p.volume for p in obj.collision_parts(scale)) == pytest.approx(
        sum(p.volume for p in obj.collision_parts(1.0)) * scale**3, rel=1e-6)
    # resting on z = 0, the origin is rest_half_height * scale above the floor
    assert -scaled.bounds[0, 2] == pytest.approx(obj.half_height(scale), abs=1e-9)


def test_bad_scale_and_unknown_name_are_rejected():
    with pytest.raises(ValueError, match="positive"):
        get_ravens_object("block").visual_mesh(0.0)
    with pytest.raises(ValueError, match="valid names: block, ell, disk, slimdisk, bowl"):
        get_ravens_object("teapot")


def _maps_onto_itself(mesh: trimesh.Trimesh, rotation: np.ndarray) -> bool:
    """Does the rotation send every vertex onto a vertex (the meshes here are vertex-symmetric)?"""
    tree = cKDTree(mesh.vertices)
    distance, _ = tree.query(mesh.vertices @ rotation.T)
    return bool(distance.max() < 1e-6)


def _about_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("name", NAMES)
def test_symmetry_group_maps_the_object_onto_itself(name):
    pytest.importorskip("torch")
    obj = get_ravens_object(name)
    symmetry = obj.symmetry
    mesh = obj.visual_mesh(1.0)
    for rotation in np.asarray(symmetry.discrete, dtype=np.float64):
        assert _maps_onto_itself(mesh, rotation), f"{name}: {rotation} is not a symmetry"
    if symmetry.axis is not None:
        np.testing.assert_allclose(np.asarray(symmetry.axis), [0.0, 0.0, 1.0])
        assert _maps_onto_itself(mesh, _about_z(2 * np.pi / 48))  # one revolve section
    # and the groups are not too big: a quarter turn about x is never a symmetry, except for the cube
    quarter_x = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    assert _maps_onto_itself(mesh, quarter_x) == (name == "block")


def test_bowl_is_not_symmetric_upside_down_but_disks_are():
    pytest.importorskip("torch")
    flip = np.diag([1.0, -1.0, -1.0])
    assert not _maps_onto_itself(get_ravens_object("bowl").visual_mesh(), flip)
    assert get_ravens_object("bowl").symmetry.order == 1
    assert _maps_onto_itself(get_ravens_object("disk").visual_mesh(), flip)
    assert get_ravens_object("disk").symmetry.order == 2
    assert get_ravens_object("ell").symmetry.order == 2 and get_ravens_object("ell").symmetry.axis is None
