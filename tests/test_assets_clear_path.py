"""A door's path through its collision pieces: overlap geometry, the load-time reach check and its fix.

Geometry is checked against exact answers (cubes). The loader cases are made up: a
procedural microwave in PartNet-Mobility's layout with one extra collision box added
to its body where the door swings through it (a piece a decomposition could leave in
the hinge gap), decomposed by the exact one-hull-per-connected-piece decomposer of
``test_assets_decompose``. The real fridge 12036 (../shared) is checked when present.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import trimesh

from test_assets_decompose import _add_link, decomposers  # noqa: F401  (decomposers: a fixture)
from test_assets_partnet import DATASET, needs_dataset
from wpbench.assets.clear_path import trim_overlaps, write_cleared_urdf
from wpbench.assets.convex_overlap import clip_convex, convex_volume, overlap_inradius, trim_away
from wpbench.assets.partnet import (
    PartNetLoadConfig,
    PartNetLoadError,
    link_pieces,
    load_collision_articulation,
    load_partnet_object,
)
from wpbench.assets.procedural import generate_object


def cube(low, high) -> np.ndarray:
    """(8, 3) corners of the axis-aligned box [low, high]."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    return np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])


# --------------------------------------------------------------------------- geometry


def test_overlap_inradius_of_boxes_is_half_the_thinnest_side_of_their_intersection():
    a = cube([0, 0, 0], [1, 1, 1])
    assert overlap_inradius(a, cube([0.6, 0, 0], [2, 1, 1])) == pytest.approx(0.2)
    assert overlap_inradius(a, cube([0.5, 0.5, 0.9], [2, 2, 2])) == pytest.approx(0.05)
    assert overlap_inradius(a, cube([1, 0, 0], [2, 1, 1])) == pytest.approx(0.0, abs=1e-9)  # touching
    assert overlap_inradius(a, cube([1.5, 0, 0], [2, 1, 1])) == 0.0  # apart
    with pytest.raises(ValueError, match="shape"):
        overlap_inradius(np.zeros((3, 3)), a)


def test_clip_keeps_the_exact_part_of_a_box_beyond_a_plane():
    box = cube([0, 0, 0], [1, 2, 3])
    half = clip_convex(box, np.array([1.0, 0, 0]), 0.25)
    assert convex_volume(half) == pytest.approx(0.75 * 6)
    assert half[:, 0].min() == pytest.approx(0.25)
    diagonal = clip_convex(cube([0, 0, 0], [1, 1, 1]), np.array([1.0, 1.0, 0]), np.sqrt(2) / 2)  # x + y >= 1
    assert convex_volume(diagonal) == pytest.approx(0.5)
    assert clip_convex(box, np.array([1.0, 0, 0]), 1.5) is None  # nothing left
    with pytest.raises(ValueError, match="normal"):
        clip_convex(box, np.zeros(3), 0.0)


def test_trim_away_cuts_along_the_face_that_keeps_most_and_leaves_no_overlap():
    body = cube([0, 0, 0], [1, 1, 0.52])  # reaches 2 cm into the door above it
    door = cube([0, 0, 0.5], [1, 1, 1])
    trimmed = trim_away(body, door, gap=0.001)
    assert trimmed[:, 2].max() == pytest.approx(0.499)
    assert convex_volume(trimmed) == pytest.approx(0.499)
    assert overlap_inradius(trimmed, door) == 0.0


def test_trim_overlaps_changes_only_pieces_of_links_that_do_not_move_with_the_door():
    pieces = {"door": [cube([0, 0, 0.5], [1, 1, 1])], "handle": [cube([0.2, 0.2, 0.45], [0.4, 0.4, 0.55])],
              "body": [cube([0, 0, 0], [1, 1, 0.52]), cube([2, 0, 0], [3, 1, 1])]}
    changed = trim_overlaps(pieces, moving={"door", "handle"})
    assert changed == ["body#0"]
    assert pieces["body"][0][:, 2].max() < 0.45  # below the handle too
    untouched = {"door": [cube([0, 0, 0.5], [1, 1, 1])], "body": [cube([0, 0, 0], [1, 1, 0.52])]}
    assert trim_overlaps(untouched, moving={"door"}, never_collide={frozenset(("door", "body"))}) == []
    assert np.array_equal(untouched["body"][0], cube([0, 0, 0], [1, 1, 0.52]))
    assert np.array_equal(pieces["body"][1], cube([2, 0, 0], [3, 1, 1]))
    assert np.array_equal(pieces["handle"][0], cube([0.2, 0.2, 0.45], [0.4, 0.4, 0.55]))


# --------------------------------------------------------------------------- the loader on a made-up door


BOX_SIDE_M = 0.04
BLOCKER_LINK = "hinge_cover_link"


@pytest.fixture()
def blocked_microwave(tmp_path, decomposers):  # noqa: F811
    """(folder, loader config, box centre): a microwave with an extra collision box, fixed to its
    body, where the door's centre passes at 35% of its range."""
    config = PartNetLoadConfig(decomposer=f"{decomposers}:exact", workers=1)
    asset = generate_object("microwave", 2, tmp_path / "objects")
    folder = tmp_path / "objects" / asset.object_id
    clean = load_partnet_object(folder, cache_dir=tmp_path / "clean", scale=1.0, config=config)
    assert clean.open_qpos == pytest.approx(clean.extra["open_qpos_limit"])
    scene, articulation = load_collision_articulation(clean.urdf, 1.0)
    names = [j.name for j in articulation.get_active_joints()]
    fraction = 0.35
    q = clean.closed_qpos + fraction * (clean.open_qpos - clean.closed_qpos)
    articulation.set_qpos(np.array([q if n == clean.target_joint else 0.0 for n in names], dtype=np.float32))
    door = np.concatenate(link_pieces(next(l for l in articulation.get_links() if l.name == clean.target_link)))
    centre = door.mean(0)
    box = trimesh.creation.box(extents=[BOX_SIDE_M] * 3)
    body_link = next(l.get("name") for l in ET.parse(folder / "mobility.urdf").getroot().findall("link")
                     if l.get("name") not in ("base", clean.target_link))
    # A separate link fixed to the body (physics never lets a door collide with the link it hangs on).
    _add_link(folder / "mobility.urdf", BLOCKER_LINK, body_link, box, centre)  # the body link sits at the root frame
    with open(folder / "semantics.txt", "a") as f:
        f.write(f"{BLOCKER_LINK} static hinge_cover\n")
    return folder, config, centre


ONE_LINK_URDF = """<robot name="box">
  <link name="body">
    <collision><geometry><mesh filename="body.obj"/></geometry></collision>
    <collision><geometry><mesh filename="body.obj"/></geometry></collision>
  </link>
</robot>
"""


def _clear_in_step(urdf: Path, barrier, results) -> None:
    """One of several processes clearing the same URDF at the same moment."""
    pieces = {"body": [cube([0, 0, 0], [1, 1, 0.5]), None]}
    barrier.wait()
    try:
        results.put(str(write_cleared_urdf(urdf, pieces, {"body#0", "body#1"}, {"body": (np.eye(4), 1.0)})))
    except BaseException as err:  # noqa: BLE001 - the parent reports it
        results.put(f"error: {type(err).__name__}: {err}")


def test_workers_clearing_the_same_object_at_once_all_get_the_same_complete_urdf(tmp_path):
    # A run's workers load (and so clear) the same object side by side on a fresh cache;
    # one that fails would silently leave the object out of its episode draws.
    import multiprocessing

    context = multiprocessing.get_context("fork")
    for attempt in range(4):
        urdf = tmp_path / f"try{attempt}" / "derived.urdf"
        urdf.parent.mkdir()
        urdf.write_text(ONE_LINK_URDF)
        barrier, results = context.Barrier(8), context.Queue()
        workers = [context.Process(target=_clear_in_step, args=(urdf, barrier, results)) for _ in range(8)]
        for w in workers:
            w.start()
        answers = {results.get(timeout=60) for _ in workers}
        for w in workers:
            w.join(60)
        assert len(answers) == 1 and not next(iter(answers)).startswith("error"), answers
        cleared = Path(next(iter(answers)))
        collisions = ET.parse(cleared).getroot().findall("link/collision")
        assert len(collisions) == 1  # the dropped piece is gone, the trimmed one points at its own file
        piece = trimesh.load(collisions[0].find("geometry/mesh").get("filename"), force="mesh")
        assert piece.bounds.tolist() == [[0, 0, 0], [1, 1, 0.5]]
        assert [f.name for f in urdf.parent.rglob(".*")] == []  # no temporary file left behind


@pytest.mark.slow
def test_the_check_names_a_piece_in_the_door_path_and_the_fix_clears_it(blocked_microwave, tmp_path):
    folder, config, centre = blocked_microwave
    unfixed = PartNetLoadConfig(decomposer=config.decomposer, workers=1, clear_path=False)
    with pytest.raises(PartNetLoadError, match=rf"opens only to q=.*held by {BLOCKER_LINK} piece 0 at ") as err:
        load_partnet_object(folder, cache_dir=tmp_path / "cache", scale=1.0, config=unfixed)
    assert "\n" not in str(err.value)

    fixed = load_partnet_object(folder, cache_dir=tmp_path / "cache", scale=1.0, config=config)
    assert fixed.open_qpos == pytest.approx(fixed.extra["open_qpos_limit"])  # the whole range again
    assert fixed.extra["collision_dropped"] == [f"{BLOCKER_LINK}#0"]
    assert fixed.extra["reach_blocked_by"] == ""
    # The dropped piece is the box: no collision piece of the cleared URDF is centred on it any more.
    scene, articulation = load_collision_articulation(fixed.urdf, 1.0)
    assert all(np.linalg.norm(p.mean(0) - centre) > BOX_SIDE_M
               for link in articulation.get_links() for p in link_pieces(link))


@needs_dataset
@pytest.mark.slow
def test_fridge_12036_is_held_only_by_its_own_handle_meeting_the_side_wall():
    asset = load_partnet_object(DATASET / "12036")
    # The lower door reached a few millimetres into the upper door, dragging it along until the
    # upper door's handle met the side wall: that piece of the upper door is cut back (and dropped, as
    # it still held the door and the cavity does not need it).
    assert any(name.startswith("link_1#") for name in asset.extra["collision_trimmed"])
    # What stops it now is real: its handle bar meets the fridge's side wall, which the cavity needs.
    assert asset.extra["reach_blocked_by"].startswith("held by link_2 piece")
    assert (asset.open_qpos - asset.closed_qpos) / asset.extra["open_qpos_limit"] > 0.71


KNOB_LINK = "knob_link_9"


@pytest.fixture()
def pushed_knob(tmp_path, decomposers):  # noqa: F811
    """(folder, loader config): a microwave with a panel fixed on top of its body and a knob,
    hinged on the body at its box's edge (a push turns it), whose box reaches 1 cm into the panel."""
    config = PartNetLoadConfig(decomposer=f"{decomposers}:exact", workers=1)
    asset = generate_object("microwave", 2, tmp_path / "objects")
    folder = tmp_path / "objects" / asset.object_id
    urdf = folder / "mobility.urdf"
    body_link = next(l.get("name") for l in ET.parse(urdf).getroot().findall("link")
                     if l.get("name") not in ("base", asset.target_link))
    top, y = asset.bounds_high[2], asset.bounds_low[1] + 0.1
    _add_link(urdf, "panel_link_9", body_link, trimesh.creation.box(extents=[0.1, 0.1, 0.02]), (0.0, y, top + 0.05))
    knob = trimesh.creation.box(extents=[0.04, 0.04, 0.04])
    knob.apply_translation([-0.02, 0.0, 0.0])  # in the knob's frame, the box beside its hinge
    _add_link(urdf, KNOB_LINK, body_link, knob, (0.02, y, top + 0.07))
    tree = ET.parse(urdf)
    joint = next(j for j in tree.getroot().findall("joint") if j.get("name") == f"{KNOB_LINK}_joint")
    joint.set("type", "revolute")
    ET.SubElement(joint, "axis", xyz="0 1 0")
    ET.SubElement(joint, "limit", lower="0", upper="5.76", effort="1", velocity="10")
    tree.write(urdf)
    with open(folder / "semantics.txt", "a") as f:
        f.write(f"panel_link_9 static panel\n{KNOB_LINK} hinge knob\n")
    return folder, config


def _peak_speed_at_rest(asset) -> float:
    from wpbench.assets.reach import restless_links

    scene, articulation = load_collision_articulation(asset.urdf, 1.0)
    moved = restless_links(articulation, asset.extra["closed_qpos_by_joint"], set())
    return max(moved.values(), default=0.0)


@pytest.mark.slow
def test_a_knob_its_neighbour_pushes_at_rest_loses_its_collision(pushed_knob, tmp_path):
    folder, config = pushed_knob
    unfixed = load_partnet_object(folder, cache_dir=tmp_path / "cache", scale=1.0,
                                  config=PartNetLoadConfig(decomposer=config.decomposer, workers=1, clear_path=False))
    assert _peak_speed_at_rest(unfixed) > 1.0  # the knob moves while everything is held still

    fixed = load_partnet_object(folder, cache_dir=tmp_path / "cache", scale=1.0, config=config)
    assert list(fixed.extra["collision_restless"]) == [KNOB_LINK]
    assert fixed.extra["collision_dropped"] == [f"{KNOB_LINK}#0"]
    assert _peak_speed_at_rest(fixed) == 0.0
    assert fixed.open_qpos == pytest.approx(fixed.extra["open_qpos_limit"])


def test_probe_scenes_use_sapiens_defaults_whatever_an_env_has_set(tmp_path):
    """ManiSkill sets PhysX's process-wide defaults when it builds a scene; the load-time probe
    scenes must not inherit them (or one object gets two open limits, by process history)."""
    import sapien.physx as px

    asset = generate_object("microwave", 2, tmp_path / "objects")
    urdf = tmp_path / "objects" / asset.object_id / "mobility.urdf"

    def shapes_and_bodies():
        scene, articulation = load_collision_articulation(urdf, 1.0)
        shapes = [s for link in articulation.get_links() for s in link.get_collision_shapes()]
        assert shapes
        return ({(round(s.contact_offset, 6), round(s.physical_material.static_friction, 6),
                  round(s.physical_material.restitution, 6)) for s in shapes},
                articulation.solver_position_iterations)

    before = shapes_and_bodies()
    px.set_shape_config(contact_offset=0.02, rest_offset=0.0)
    px.set_body_config(solver_position_iterations=15, solver_velocity_iterations=1, sleep_threshold=0.005)
    px.set_default_material(1.0, 0.8, 0.0)
    try:
        assert shapes_and_bodies() == before
        assert before == ({(0.01, 0.3, 0.1)}, 10)
        # The process's own defaults are left as they were set.
        assert px.get_shape_config().contact_offset == pytest.approx(0.02)
        assert px.get_body_config().solver_position_iterations == 15
        assert px.get_default_material().static_friction == pytest.approx(1.0)
    finally:
        px.set_shape_config(px.PhysxShapeConfig())
        px.set_body_config(px.PhysxBodyConfig())
        px.set_default_material(0.3, 0.3, 0.1)
