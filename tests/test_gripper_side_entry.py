"""The side-entry planner against made-up furniture whose answers are known: a cabinet
open at its front is entered through the front, a closed box is not entered at all, a
roof above the goal is seen, and every planned pose keeps the object and hand clear of
the observed cloud."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hypothesis import given, settings
from hypothesis import strategies as st

from wpbench.sim.side_entry import (FLOOR_GAP, PREGRASP, face_yaws, hand_box, held_box, is_roofed, path_poses,
                                    plan_side_entry, poses_hit, segment_poses, surface_clearance)

SPACING = 0.015


def _plane(origin, u, v, rng):
    """Points on the rectangle origin + a u + b v, a, b in [0, 1], about SPACING apart."""
    n_u = max(2, int(np.linalg.norm(u) / SPACING))
    n_v = max(2, int(np.linalg.norm(v) / SPACING))
    a, b = np.meshgrid(np.linspace(0, 1, n_u), np.linspace(0, 1, n_v))
    return np.asarray(origin) + a.reshape(-1, 1) * np.asarray(u) + b.reshape(-1, 1) * np.asarray(v)


def _cabinet(front_open=True, roof=True, rng=None):
    """A 0.5 x 0.6 x 0.4 m cavity, floor at z = 0.3, walls at x = -0.25 (back), y = +-0.3;
    the front is x = +0.25 (open unless ``front_open`` is False)."""
    rng = rng or np.random.default_rng(0)
    x0, x1, y0, y1, z0, z1 = -0.25, 0.25, -0.3, 0.3, 0.3, 0.7
    walls = [
        _plane([x0, y0, z0], [x1 - x0, 0, 0], [0, y1 - y0, 0], rng),         # floor
        _plane([x0, y0, z0], [0, y1 - y0, 0], [0, 0, z1 - z0], rng),         # back
        _plane([x0, y0, z0], [x1 - x0, 0, 0], [0, 0, z1 - z0], rng),         # side -y
        _plane([x0, y1, z0], [x1 - x0, 0, 0], [0, 0, z1 - z0], rng),         # side +y
        _plane([x0, y0, 0.0], [0, 0, z0], [0, y1 - y0, 0], rng),             # the base under the cavity
        _plane([x1, y0, 0.0], [0, 0, z0], [0, y1 - y0, 0], rng),             # its front
    ]
    if roof:
        walls.append(_plane([x0, y0, z1], [x1 - x0, 0, 0], [0, y1 - y0, 0], rng))
    if not front_open:
        walls.append(_plane([x1, y0, z0], [0, y1 - y0, 0], [0, 0, z1 - z0], rng))
    return np.concatenate(walls)


def _block(centre, side=0.1, yaw=0.0):
    """Surface samples of a cube of ``side`` standing on z = centre[2] - side / 2."""
    g = np.linspace(-side / 2, side / 2, 8)
    faces = []
    for axis in range(3):
        for sign in (-1, 1):
            a, b = np.meshgrid(g, g)
            f = np.zeros((a.size, 3))
            f[:, axis] = sign * side / 2
            f[:, [k for k in range(3) if k != axis]] = np.stack([a.ravel(), b.ravel()], 1)
            faces.append(f)
    pts = np.concatenate(faces) @ Rotation.from_rotvec([0, 0, yaw]).as_matrix().T
    return pts + np.asarray(centre)


def _move(start, goal, yaw):
    """The cross-pose taking a block centred at ``start`` to ``goal``, turned by ``yaw``."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0, 0, yaw]).as_matrix()
    T[:3, 3] = np.asarray(goal) - T[:3, :3] @ np.asarray(start)
    return T


def test_face_yaws_are_the_cube_faces():
    yaws = face_yaws(_block([0.0, 0.0, 0.05], yaw=np.radians(20)))
    got = np.sort(np.mod(np.degrees(yaws), 90.0))
    np.testing.assert_allclose(got, [20.0] * 4, atol=1.01)


def test_cabinet_is_entered_through_its_open_front():
    anchor = _cabinet()
    start, goal = np.array([1.0, 0.4, 0.05]), np.array([-0.05, 0.0, 0.352])
    obj = _block(start, yaw=0.3)
    T = _move(start, goal, -0.3)
    assert is_roofed(obj, anchor, T)
    plan = plan_side_entry(obj, anchor, T, viewpoint=np.array([2.0, 0.0, 1.5]))
    assert plan is not None
    np.testing.assert_allclose(plan.direction, [1.0, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(plan.goal, T @ plan.pick, atol=1e-9)
    # The cup sits on the block's outer face, level with the approach.
    assert plan.goal[0, 3] == pytest.approx(goal[0] + 0.05, abs=1e-3)
    carry = plan.carry_waypoints()
    boxes = [held_box(obj @ T[:3, :3].T + T[:3, 3], plan.goal)]
    # Every pose down to the slide's end keeps the object clear of the cabinet.
    assert not poses_hit(anchor, path_poses(carry[1:-1]), boxes, surface_clearance(anchor))


def test_a_closed_box_is_not_entered():
    anchor = _cabinet(front_open=False)
    start, goal = np.array([1.0, 0.4, 0.05]), np.array([-0.05, 0.0, 0.352])
    obj = _block(start)
    assert plan_side_entry(obj, anchor, _move(start, goal, 0.0), viewpoint=np.array([2.0, 0.0, 1.5])) is None


def test_open_top_is_not_roofed():
    anchor = _cabinet(roof=False)
    start, goal = np.array([1.0, 0.4, 0.05]), np.array([-0.05, 0.0, 0.352])
    obj = _block(start)
    assert not is_roofed(obj, anchor, _move(start, goal, 0.0))


def test_face_that_looks_at_the_furniture_is_reached_after_a_turn():
    """The face that must look out of the cabinet at the goal faces the cabinet at the start,
    with too little room for the hand: the plan turns the block first."""
    anchor = _cabinet()
    start, goal = np.array([0.42, 0.0, 0.05]), np.array([-0.05, 0.0, 0.352])
    obj = _block(start)
    plan = plan_side_entry(obj, anchor, _move(start, goal, np.pi), viewpoint=np.array([2.0, 0.0, 1.5]))
    assert plan is not None and plan.regrasp_turn != 0.0


def _lowest_hand_z_on_approach(pick):
    """The lowest any corner of the hand box gets while coming in to ``pick`` from PREGRASP back."""
    pre = pick.copy()
    pre[:3, 3] -= PREGRASP * pick[:3, 2]
    lo, hi = hand_box()
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return min(float((corners @ T[:3, :3].T + T[:3, 3])[:, 2].min()) for T in segment_poses(pre, pick))


@settings(max_examples=10, deadline=None)
@given(tilt_deg=st.floats(0.0, 6.0), axis_yaw=st.floats(0.0, 2 * np.pi))
def test_a_tilted_goal_still_gets_a_pick_whose_approach_clears_the_floor(tilt_deg, axis_yaw):
    """A predicted goal a few degrees off level tilts the hand at the pick by as much, so its
    approach from PREGRASP back dips towards the floor. The cup is raised on the face just
    enough: the plan exists for every small tilt, and its approach keeps FLOOR_GAP above the
    floor, not less (a pick decided by millimetres of the prediction flips between plans)."""
    anchor = _cabinet()
    tilt = np.radians(tilt_deg)
    # The tilted block's lowest corner stays 4 mm above the cavity's floor (z = 0.3).
    start, goal = np.array([1.0, 0.0, 0.05]), np.array([-0.05, 0.0, 0.304 + 0.05 * (np.cos(tilt) + np.sqrt(2) * np.sin(tilt))])
    obj = _block(start)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(tilt * np.array([np.cos(axis_yaw), np.sin(axis_yaw), 0.0])).as_matrix()
    T[:3, 3] = goal - T[:3, :3] @ start
    plan = plan_side_entry(obj, anchor, T, viewpoint=np.array([2.0, 0.0, 1.5]))
    assert plan is not None
    floor = float(obj[:, 2].min())
    assert _lowest_hand_z_on_approach(plan.pick) >= floor + FLOOR_GAP - 1e-6


def test_an_overhang_in_front_is_passed_under_from_a_lead_in():
    """An awning over the cabinet's front leaves nothing clear straight above any staging pose:
    the plan still finds a way in (under the awning), and stays clear of the cloud."""
    rng = np.random.default_rng(0)
    anchor = np.concatenate([_cabinet(rng=rng), _plane([0.25, -0.3, 1.0], [0.75, 0, 0], [0, 0.6, 0], rng)])
    start, goal = np.array([1.4, 0.5, 0.05]), np.array([-0.05, 0.0, 0.352])
    obj = _block(start)
    T = _move(start, goal, 0.0)
    plan = plan_side_entry(obj, anchor, T, viewpoint=np.array([2.0, 0.0, 1.5]))
    assert plan is not None
    np.testing.assert_allclose(plan.direction, [1.0, 0.0, 0.0], atol=1e-6)
    carry = plan.carry_waypoints()
    boxes = [held_box(obj @ T[:3, :3].T + T[:3, 3], plan.goal), hand_box()]
    assert not poses_hit(anchor, path_poses(carry[1:-1]), boxes, surface_clearance(anchor))


def test_bad_shapes_are_clear_errors():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        plan_side_entry(np.zeros((4, 2)), _cabinet(), np.eye(4))
