"""Every documented failure reason is reachable: each situation is built on a fixed val
episode (or, for the settling loop, with a made-up physics step), and the stage reports
that reason instead of crashing."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wpbench import tasks  # noqa: F401
from wpbench.sim import failure
from wpbench.sim.executor import simulate_until_still
from wpbench.sim.screw_path import screw_at, screw_of

SEEN: set[str] = set()


def _env(task, **kw):
    return gym.make(f"wpbench/{task}-v0", obs_mode="mesh", assets="procedural", split="val", **kw)


@pytest.fixture(scope="module")
def door():
    env = _env("OpenDoor", executor="gripper", grasp="suction")
    yield env
    env.close()


@pytest.fixture(scope="module")
def place():
    env = _env("PlaceIn", executor="gripper", grasp="suction")
    yield env
    env.close()


def _reason(env, seed, make_T, before_step=None, options=None):
    env.reset(seed=seed, options=options)
    T = make_T(env.unwrapped.ground_truth()["cross_pose"], env.unwrapped)
    if before_step is not None:
        before_step(env.unwrapped)
    _, _, _, _, info = env.step(T)
    r = info["stage_result"]
    assert not r["success"]
    SEEN.add(r["failure_reason"])
    return r


def test_invalid_prediction(place):
    assert _reason(place, 0, lambda T, b: np.full((4, 4), np.nan))["failure_reason"] == failure.INVALID_PREDICTION


def test_not_open_enough_for_identity(door):
    assert _reason(door, 0, lambda T, b: np.eye(4))["failure_reason"] == failure.NOT_OPEN_ENOUGH


def test_grasp_missed_when_the_cloud_floats_in_the_air(door):
    """A cloud 2 m above the door (a bad segmentation): the cup meets nothing."""
    def lift_cloud(base):
        obs = base.get_obs()
        obs["action_points"] = obs["action_points"] + np.array([0.0, 0.0, 2.0], dtype=np.float32)
    r = _reason(door, 0, lambda T, b: T, before_step=lift_cloud)
    assert r["failure_reason"] == failure.GRASP_MISSED


def test_slipped_when_the_door_is_pulled_along_its_hinge(door):
    """Pulling the door up 20 cm: the hinge holds, the cup lets go."""
    def up(T, base):
        out = T.copy()
        out[2, 3] += 0.2
        return out
    assert _reason(door, 0, up)["failure_reason"] == failure.SLIPPED


def test_stalled_when_a_closed_door_is_pushed_shut():
    """Fingers on a handle (friction holds harder than the arm pulls), the door 30% open, and
    the prediction turns it 30% of its range past closed: the frame stops the hand."""
    env = _env("OpenDoor", executor="gripper", grasp="friction")

    def shut(T, base):
        g = base.furniture.target_link_pose_at(np.array([base.joint_fraction(-0.3)]))[0]
        return g @ np.linalg.inv(base.furniture.target_link_pose())
    try:
        r = _reason(env, 0, shut, options={"start_fraction": 0.3})
    finally:
        env.close()
    assert r["failure_reason"] == failure.STALLED_AGAINST_HINGE


def test_unreachable_when_the_path_goes_under_the_floor(door):
    def down(T, base):
        out = T.copy()
        out[2, 3] -= 2.0
        return out
    assert _reason(door, 0, down)["failure_reason"] == failure.UNREACHABLE


def test_planning_failed_is_a_failure_with_a_reason_not_a_crash():
    """Friction cannot hold a block wider than the fingers open: no grasp, no path."""
    env = _env("PlaceIn", executor="gripper", grasp="friction")
    try:
        r = _reason(env, 0, lambda T, b: T)
    finally:
        env.close()
    assert r["failure_reason"] == failure.PLANNING_FAILED and r["failure_detail"]


def test_collision_when_the_furniture_was_not_seen(place):
    """An anchor cloud that missed the furniture (all of it 5 m away): the hand plans
    straight through the cabinet and is stopped by it."""
    def blind(base):
        obs = base.get_obs()
        obs["anchor_points"] = obs["anchor_points"] + np.array([5.0, 5.0, 0.0], dtype=np.float32)
    assert _reason(place, 2, lambda T, b: T, before_step=blind)["failure_reason"] == failure.COLLISION


def test_not_in_region_when_the_goal_is_beside_the_furniture():
    env = _env("PlaceIn")
    try:
        def aside(T, base):
            out = T.copy()
            out[:3, 3] += base.root_pose[:3, :3] @ np.array([0.0, 1.5, 0.0])
            return out
        assert _reason(env, 0, aside)["failure_reason"] == failure.NOT_IN_REGION
    finally:
        env.close()


def test_not_at_rest_and_blow_up_from_the_settling_loop():
    """A body that keeps moving slowly never settles; one that runs away blows up."""
    slow = simulate_until_still(lambda: None, 0.01, lambda: [np.ones(3)], lambda: False, max_seconds=0.1)
    assert slow.ok and slow.reason == failure.NOT_AT_REST
    runaway = simulate_until_still(lambda: None, 0.01, lambda: [np.full(3, 1e3)], lambda: False, max_seconds=0.1)
    assert not runaway.ok and runaway.reason == failure.BLOW_UP
    SEEN.update({slow.reason, runaway.reason})


def test_every_documented_reason_was_reached():
    """Runs last in this file: the tests above reached every code of wpbench.sim.failure."""
    assert SEEN == set(failure.FAILURE_REASONS), sorted(set(failure.FAILURE_REASONS) - SEEN)
