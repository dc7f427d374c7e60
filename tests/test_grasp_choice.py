"""The cup's point on a door kept clear of a handle (wpbench.sim.grasp_choice.clear_suction_point)
on made-up door clouds: exact geometry, no simulator."""

from __future__ import annotations

import numpy as np
import pytest

from wpbench.sim.grasp_choice import (CUP_FOOTPRINT, CUP_PROUD, MIN_CLEAR_POINTS, clear_suction_point, proud_near,
                                      suction_point)

HANDLE_OFF = 0.04    # m, the handle bar stands this far off the door's face


def _door_opening(angle: float) -> np.ndarray:
    """(4, 4) turn by ``angle`` about the vertical hinge x = y = 0 that swings the door's free edge (+y) out to +x."""
    c, s = np.cos(-angle), np.sin(-angle)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    return T


def _door(rng: np.random.Generator, handle: bool) -> tuple[np.ndarray, np.ndarray]:
    """A fridge door's outer face (x = 0, facing +x, 0.5 m wide from its hinge at y = 0, z 0.2-1.2 m)
    and, with ``handle``, a vertical bar as tall as the door standing HANDLE_OFF off it near the free edge."""
    face = np.column_stack([np.zeros(4000), rng.uniform(0.0, 0.5, 4000), rng.uniform(0.2, 1.2, 4000)])
    bar = np.column_stack([np.full(150 if handle else 0, HANDLE_OFF), rng.uniform(0.40, 0.42, 150 if handle else 0),
                           rng.uniform(0.2, 1.2, 150 if handle else 0)])
    return face, bar


def _across(grasp, points: np.ndarray) -> float:
    """Distance (m) from the grasp's TCP to the nearest of ``points`` across its approach (the door's y-z plane)."""
    return float(np.min(np.linalg.norm((points - grasp.tcp[:3, 3])[:, 1:], axis=1)))


def test_the_cup_keeps_the_hands_footprint_clear_of_a_handle():
    face, bar = _door(np.random.default_rng(0), handle=True)
    door = np.concatenate([face, bar])
    T = _door_opening(1.0)
    first = suction_point(door, T)
    assert _across(first, bar) < CUP_FOOTPRINT          # the plain face choice is beside the handle
    grasp, moved = clear_suction_point(door, T)
    assert moved
    assert _across(grasp, bar) >= CUP_FOOTPRINT         # no part of the handle under the hand
    assert abs(grasp.tcp[0, 3]) < 0.005                 # still on the face, not on the handle
    assert np.allclose(grasp.approach, first.approach, atol=0.02)
    assert grasp.tcp[1, 3] > 0.25                       # and on the door's outer half, where it moves
    assert not proud_near(door, grasp, grasp.tcp[None, :3, 3])[0]


def test_without_a_handle_the_choice_is_the_plain_face_choice():
    face, _ = _door(np.random.default_rng(1), handle=False)
    T = _door_opening(1.0)
    grasp, moved = clear_suction_point(face, T)
    assert not moved
    assert np.array_equal(grasp.tcp, suction_point(face, T).tcp)


def test_protrusions_are_looked_for_on_the_whole_door():
    # The choice among the lower part of the door only (a reach limit), the handle seen on the whole.
    face, bar = _door(np.random.default_rng(2), handle=True)
    door = np.concatenate([face, bar])
    T = _door_opening(1.0)
    lower = face[face[:, 2] < 0.6]
    assert _across(suction_point(lower, T), bar) < CUP_FOOTPRINT
    grasp, moved = clear_suction_point(lower, T, door)
    assert moved and _across(grasp, bar) >= CUP_FOOTPRINT
    unseen, moved = clear_suction_point(lower, T)      # the handle not among the points: not avoided
    assert not moved and np.array_equal(unseen.tcp, suction_point(lower, T).tcp)


def test_a_door_with_too_little_clear_face_keeps_the_plain_choice():
    # A narrow door whose whole face lies within the footprint of its handle.
    rng = np.random.default_rng(3)
    face = np.column_stack([np.zeros(400), rng.uniform(0.4, 0.5, 400), rng.uniform(0.6, 0.8, 400)])
    bar = np.column_stack([np.full(40, HANDLE_OFF), rng.uniform(0.44, 0.46, 40), rng.uniform(0.62, 0.78, 40)])
    door = np.concatenate([face, bar])
    T = _door_opening(1.0)
    assert np.sum(~proud_near(door, suction_point(door, T), door)) < MIN_CLEAR_POINTS
    grasp, moved = clear_suction_point(door, T)
    assert not moved and np.array_equal(grasp.tcp, suction_point(door, T).tcp)


def test_proud_near_marks_the_footprint_about_a_protrusion():
    face, bar = _door(np.random.default_rng(4), handle=True)
    door = np.concatenate([face, bar])
    grasp = suction_point(door, _door_opening(1.0))
    candidates = np.array([[0.0, 0.40 - CUP_FOOTPRINT + 0.015, 0.7],    # beside the bar, within the footprint
                           [0.0, 0.40 - CUP_FOOTPRINT - 0.02, 0.7],     # beside it, outside
                           [0.0, 0.42 + CUP_FOOTPRINT + 0.02, 0.7],     # beside it on the door's edge side, outside
                           [CUP_PROUD + 0.005, 0.1, 0.3]])              # itself standing out of the face
    assert proud_near(door, grasp, candidates).tolist() == [True, False, False, True]


def test_bad_shapes_are_clear_errors():
    face, _ = _door(np.random.default_rng(5), handle=False)
    T = _door_opening(1.0)
    with pytest.raises(ValueError, match="action_points"):
        clear_suction_point(face[:, :2], T)
    with pytest.raises(ValueError, match="door_points"):
        clear_suction_point(face, T, face[:, :2])
    with pytest.raises(ValueError, match="cross_pose"):
        clear_suction_point(face, T[:3])
    with pytest.raises(ValueError, match="candidates"):
        proud_near(face, suction_point(face, T), face[0])
