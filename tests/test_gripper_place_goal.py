"""The place goal the gripper aims for (wpbench.sim.place_goal) on made-up clouds: a
cube's tumble becomes the upright turn that fills the same space, a long block's does
not, a goal sunk a little into the observed floor is raised onto it and one sunk deep is
left alone."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wpbench.sim import place_goal
from wpbench.sim.place_goal import MAX_SUPPORT_RAISE, box_symmetries, rest_on_support, upright_equivalent


def _box(size, centre, yaw=0.0, n=9):
    """Surface samples of a box of ``size`` (3,) centred at ``centre``, turned by ``yaw``."""
    size = np.asarray(size, float)
    faces = []
    for axis in range(3):
        others = [k for k in range(3) if k != axis]
        a, b = np.meshgrid(np.linspace(-0.5, 0.5, n), np.linspace(-0.5, 0.5, n))
        for sign in (-0.5, 0.5):
            f = np.zeros((a.size, 3))
            f[:, axis] = sign
            f[:, others[0]], f[:, others[1]] = a.ravel(), b.ravel()
            faces.append(f * size)
    pts = np.concatenate(faces) @ Rotation.from_rotvec([0, 0, yaw]).as_matrix().T
    return pts + np.asarray(centre, float)


def _about(rotvec, centre, then=(0.0, 0.0, 0.0)):
    """Rotate by ``rotvec`` about ``centre``, then translate by ``then``."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = np.asarray(centre) - T[:3, :3] @ np.asarray(centre) + np.asarray(then)
    return T


def _apply(T, p):
    return p @ T[:3, :3].T + T[:3, 3]


def _floor(z, half=0.4, step=0.01):
    g = np.arange(-half, half + 1e-9, step)
    x, y = np.meshgrid(g, g)
    return np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], 1)


def test_a_tumbled_cube_is_put_upright_where_the_prediction_puts_it():
    cube = _box([0.1, 0.1, 0.1], [0.3, 0.2, 0.05], yaw=0.4)
    # A quarter turn about the cube's own horizontal axis (it lands on a side face).
    tumble = _about(np.pi / 2 * np.array([np.cos(0.4), np.sin(0.4), 0.0]), [0.3, 0.2, 0.05], then=[-0.3, 0.1, 0.2])
    upright = upright_equivalent(cube, tumble)
    assert upright[2, 2] > np.cos(np.radians(1.0))                 # no tilt left
    # The cube takes up the same space: same box, same centre.
    a, b = _apply(tumble, cube), _apply(upright, cube)
    np.testing.assert_allclose(a.min(0), b.min(0), atol=0.02)
    np.testing.assert_allclose(a.max(0), b.max(0), atol=0.02)
    # An upright prediction is kept as it is.
    level = _about([0.0, 0.0, 0.7], [0.3, 0.2, 0.05], then=[0.1, 0.0, 0.3])
    np.testing.assert_array_equal(upright_equivalent(cube, level), level)


def test_equally_good_upright_turns_are_chosen_whatever_the_order_of_the_turns(monkeypatch):
    cube = _box([0.1, 0.1, 0.1], [0.0, 0.0, 0.05])
    # On its side, then a yaw of 45 deg: upright turns of +45 and -45 deg tie on tilt and angle.
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0, 0, np.pi / 4]).as_matrix() @ Rotation.from_rotvec([np.pi / 2, 0, 0]).as_matrix()
    T[:3, 3] = [0.4, 0.1, 0.2]
    chosen = upright_equivalent(cube, T)
    assert chosen[2, 2] > 1 - 1e-9
    assert np.degrees(np.arccos((np.trace(chosen[:3, :3]) - 1) / 2)) == pytest.approx(45.0)
    turns = place_goal.BOX_ROTATIONS
    monkeypatch.setattr(place_goal, "BOX_ROTATIONS", np.concatenate([turns[:1], turns[1:][::-1]]))
    np.testing.assert_allclose(upright_equivalent(cube, T), chosen, atol=1e-12)


def test_a_long_block_keeps_its_tumble():
    block = _box([0.2, 0.08, 0.08], [0.0, 0.0, 0.04])
    assert len(box_symmetries(block)) == 8      # half turns, and quarter turns about its long axis
    tumble = _about([0.0, np.pi / 2, 0.0], [0.0, 0.0, 0.04])   # stands it on its end
    np.testing.assert_array_equal(upright_equivalent(block, tumble), tumble)


def test_a_goal_a_little_in_the_floor_is_raised_onto_it_a_deep_one_is_not():
    cube = _box([0.1, 0.1, 0.1], [0.0, 0.0, 0.05])
    floor = _floor(0.3)
    for sunk in (0.005, 0.02, MAX_SUPPORT_RAISE - 0.005):
        T = _about([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], then=[0.0, 0.0, 0.3 - sunk])
        raised = rest_on_support(cube, floor, T)
        assert abs(_apply(raised, cube)[:, 2].min() - 0.3) < 0.005
        np.testing.assert_array_equal(raised[:3], np.c_[T[:3, :3], raised[:3, 3]])   # only z changed
        np.testing.assert_allclose(raised[:2, 3], T[:2, 3])
    deep = _about([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], then=[0.0, 0.0, 0.3 - MAX_SUPPORT_RAISE - 0.02])
    np.testing.assert_array_equal(rest_on_support(cube, floor, deep), deep)
    above = _about([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], then=[0.0, 0.0, 0.32])
    np.testing.assert_array_equal(rest_on_support(cube, floor, above), above)
