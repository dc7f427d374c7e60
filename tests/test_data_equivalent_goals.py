"""Equivalent goals of a symmetric object: exact answers and agreement with the symmetric metric."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from wpbench.data.equivalent_goals import equivalent_goals, nearest_goal
from wpbench.geometry import metrics
from wpbench.geometry.symmetry import Symmetry

CUBE = Symmetry.cube().discrete.numpy()
CORNERS = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))  # a cube's corners, object frame


def _pose(rng: np.random.Generator) -> np.ndarray:
    P = np.eye(4)
    P[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    P[:3, 3] = rng.normal(size=3)
    return P


def _apply(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ T[:3, :3].T + T[:3, 3]


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_every_equivalent_goal_puts_the_cube_where_the_goal_does(seed):
    rng = np.random.default_rng(seed)
    O, T = _pose(rng), _pose(rng)
    goals = equivalent_goals(T, O, CUBE)
    assert goals.shape == (24, 4, 4)
    corners_now = _apply(O, CORNERS)
    wanted = np.sort(np.round(_apply(T, corners_now), 9), axis=0)
    distinct = set()
    for G in goals:
        np.testing.assert_allclose(G[:3, :3] @ G[:3, :3].T, np.eye(3), atol=1e-9)
        # The same set of corners (the cube looks the same), reached by a different motion.
        np.testing.assert_allclose(np.sort(np.round(_apply(G, corners_now), 9), axis=0), wanted, atol=1e-6)
        distinct.add(tuple(np.round(G, 6).ravel()))
    assert len(distinct) == 24
    assert any(np.allclose(G, T) for G in goals)  # the identity symmetry gives T back


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_nearest_goal_error_matches_the_symmetric_rotation_metric(seed):
    rng = np.random.default_rng(seed)
    O, T = _pose(rng), _pose(rng)
    goals = torch.as_tensor(equivalent_goals(T, O, CUBE))[None]  # (1, 24, 4, 4)
    T_pred = torch.as_tensor(_pose(rng))[None]
    plain = metrics.rotation_error_deg(T_pred[:, :3, :3].expand(24, 3, 3), goals[0, :, :3, :3])
    symmetric = metrics.rotation_error_deg(T_pred[:, :3, :3], torch.as_tensor(T)[None, :3, :3],
                                           symmetry=Symmetry.cube(), object_rotation=torch.as_tensor(O[:3, :3])[None])
    torch.testing.assert_close(plain.min()[None], symmetric, atol=1e-6, rtol=0)
    chosen = nearest_goal(T_pred, goals)
    assert chosen.shape == (1, 4, 4)
    assert any(torch.equal(chosen[0], g) for g in goals[0])
    # The error against the chosen goal is the symmetric metric itself.
    torch.testing.assert_close(metrics.rotation_error_deg(T_pred[:, :3, :3], chosen[:, :3, :3]), symmetric, atol=1e-6, rtol=0)


def test_nearest_goal_picks_the_exact_match_and_survives_nan():
    rng = np.random.default_rng(3)
    O, T = _pose(rng), _pose(rng)
    goals = torch.as_tensor(equivalent_goals(T, O, CUBE))[None].repeat(2, 1, 1, 1)
    T_pred = torch.stack([goals[0, 7], torch.full((4, 4), float("nan"), dtype=torch.float64)])
    chosen = nearest_goal(T_pred, goals)
    torch.testing.assert_close(chosen[0], goals[0, 7])
    torch.testing.assert_close(chosen[1], goals[1, 0])  # NaN prediction: the stored goal


def test_shapes_are_checked():
    with pytest.raises(ValueError, match="discrete"):
        equivalent_goals(np.eye(4), np.eye(4), np.eye(3))
    with pytest.raises(ValueError, match="goals"):
        nearest_goal(torch.eye(4)[None], torch.eye(4)[None])


def test_a_gate_keeps_the_stored_goal_unless_the_prediction_is_close_to_another():
    rng = np.random.default_rng(5)
    O, T = _pose(rng), _pose(rng)
    goals = torch.as_tensor(equivalent_goals(T, O, CUBE))
    goals = torch.cat([torch.as_tensor(T)[None], goals[~torch.isclose(goals, torch.as_tensor(T)).all(-1).all(-1)]])[None]
    turn = np.eye(4)
    turn[:3, :3] = Rotation.from_euler("z", 8, degrees=True).as_matrix()
    near_other = torch.as_tensor(turn)[None] @ goals[:, 5]  # 8 deg from goal 5, far from the stored one
    torch.testing.assert_close(nearest_goal(near_other, goals, within_deg=15.0)[0], goals[0, 5])
    far_from_all = torch.as_tensor(_pose(rng))[None]
    gated = nearest_goal(far_from_all, goals, within_deg=1.0)
    torch.testing.assert_close(gated[0], goals[0, 0])
