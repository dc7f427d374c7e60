"""Screw interpolation against exact answers: a door's arc, a drawer's line, and T itself at s = 1."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wpbench.sim.screw_path import interpolate, path_length, screw_of, velocity_at_start


def _hinge(angle, point):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0, 0, angle]).as_matrix()
    T[:3, 3] = np.asarray(point) - T[:3, :3] @ np.asarray(point)
    return T


def test_door_arc_stays_on_its_circle():
    T = _hinge(np.pi / 2, [1.0, 2.0, 0.0])
    p = np.array([1.5, 2.0, 0.3])
    for s in np.linspace(0, 1, 7):
        q = interpolate(T, s)[:3, :3] @ p + interpolate(T, s)[:3, 3]
        assert np.hypot(q[0] - 1.0, q[1] - 2.0) == pytest.approx(0.5, abs=1e-12) and q[2] == pytest.approx(0.3)
    screw = screw_of(T)
    np.testing.assert_allclose(screw.point[:2], [1.0, 2.0], atol=1e-12)
    assert screw.angle == pytest.approx(np.pi / 2) and screw.slide == pytest.approx(0.0, abs=1e-12)
    assert path_length(T, p) == pytest.approx(0.5 * np.pi / 2)
    np.testing.assert_allclose(velocity_at_start(T, p), [0.0, 0.5 * np.pi / 2, 0.0], atol=1e-12)


def test_drawer_is_a_line():
    T = np.eye(4)
    T[:3, 3] = [0.3, -0.4, 0.0]
    np.testing.assert_allclose(interpolate(T, np.array([0.5]))[0][:3, 3], [0.15, -0.2, 0.0])
    assert path_length(T, np.zeros(3)) == pytest.approx(0.5)


@pytest.mark.parametrize("seed", range(4))
def test_ends_and_halves(seed):
    rng = np.random.default_rng(seed)
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=seed).as_matrix()
    T[:3, 3] = rng.normal(size=3)
    np.testing.assert_allclose(interpolate(T, 0.0), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(interpolate(T, 1.0), T, atol=1e-12)
    half = interpolate(T, 0.5)
    np.testing.assert_allclose(half @ half, T, atol=1e-12)


def test_bad_shape_is_a_clear_error():
    with pytest.raises(ValueError, match="4, 4"):
        screw_of(np.eye(3))
