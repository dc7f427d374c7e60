"""The point z-buffer against scenes whose visible part is known exactly."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from wpbench.sim.observation import sample_mesh_surface
from wpbench.sim.visibility import look_at_frame, visible_mask

FOV, RES = 1.0, 128
EYE, TARGET = np.array([3.0, 0.0, 0.0]), np.zeros(3)


def square(x: float, half: float, n: int, rng) -> np.ndarray:
    """n samples of the square x = const, |y|, |z| <= half (facing the camera on +x)."""
    yz = rng.uniform(-half, half, size=(n, 2))
    return np.column_stack([np.full(n, x), yz])


def test_a_wall_hides_what_is_behind_it_and_only_that():
    rng = np.random.default_rng(0)
    front = square(0.5, 0.3, 20000, rng)
    back = square(0.0, 0.6, 20000, rng)
    seen = visible_mask(np.vstack([front, back]), EYE, TARGET, FOV, RES)
    assert seen[:len(front)].mean() > 0.99
    behind = seen[len(front):]
    # Seen from x = 3, the front square (half 0.3 at x = 0.5) shadows |y|, |z| < 0.3 * 3 / 2.5 = 0.36 at x = 0;
    # a pixel there is 3 * 2 tan(0.5) / 128 = 2.6 cm wide.
    shadow = np.all(np.abs(back[:, 1:]) < 0.36 - 0.03, axis=1)
    clear = np.any(np.abs(back[:, 1:]) > 0.36 + 0.03, axis=1)
    assert not behind[shadow].any()
    assert behind[clear].mean() > 0.99


def test_a_closed_box_shows_only_the_faces_that_face_the_camera():
    rng = np.random.default_rng(1)
    box = trimesh.creation.box((0.4, 0.4, 0.4))
    points = sample_mesh_surface(box, 40000, rng)
    eye = np.array([2.0, 0.0, 1.0])   # in front (+x) and above (+z)
    seen = visible_mask(points, eye, np.zeros(3), FOV, RES)
    on_front = points[:, 0] > 0.2 - 1e-9
    on_top = points[:, 2] > 0.2 - 1e-9
    assert seen[on_front].mean() > 0.97 and seen[on_top].mean() > 0.97
    hidden = (points[:, 0] < -0.2 + 1e-9) | (points[:, 2] < -0.2 + 1e-9) | (np.abs(points[:, 1]) > 0.2 - 1e-9)
    # Within a few pixel footprints (1.7 cm here) of a visible face's edge, depth cannot tell the faces apart.
    away_from_the_visible_faces = (points[:, 0] < 0.2 - 0.05) & (points[:, 2] < 0.2 - 0.05)
    assert not seen[hidden & away_from_the_visible_faces].any()
    assert seen[hidden].mean() < 0.08


def test_points_behind_the_camera_or_outside_the_picture_are_not_seen():
    points = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 5.0, 0.0]])
    assert visible_mask(points, EYE, TARGET, FOV, RES).tolist() == [True, False, False]


def test_look_at_frame_is_a_rotation_pointing_at_the_target():
    axes = look_at_frame(np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(axes.T @ axes, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(axes), 1.0)
    np.testing.assert_allclose(axes[:, 0], -np.array([1.0, 2.0, 2.0]) / 3.0)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.1, 1.0))
def test_adding_an_occluder_never_reveals_anything(seed, x):
    rng = np.random.default_rng(seed)
    scene = rng.uniform(-0.5, 0.5, size=(3000, 3))
    occluder = square(x, 0.2, 5000, rng)
    alone = visible_mask(scene, EYE, TARGET, FOV, RES)
    together = visible_mask(np.vstack([scene, occluder]), EYE, TARGET, FOV, RES)[:len(scene)]
    assert not (together & ~alone).any()


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match=r"\(M, 3\)"):
        visible_mask(np.zeros((4, 2)), EYE, TARGET, FOV, RES)
    with pytest.raises(ValueError, match="coincide"):
        visible_mask(np.zeros((4, 3)), EYE, EYE, FOV, RES)
