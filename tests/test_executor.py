"""The scripted executor against physics: it realises a reachable pose, physics
pushes an impossible one out, and a bad prediction fails the stage, never the run."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from wpbench import tasks  # noqa: F401
from wpbench.sim.executor import best_joint_value
from wpbench.sim.observation import sample_mesh_surface
from executor_helpers import step_with, turned_about_hinge


@pytest.fixture(scope="module")
def door_env():
    env = gym.make("wpbench/OpenDoor-v0", obs_mode="mesh", assets="procedural", split="val")
    yield env
    env.close()


@pytest.fixture(scope="module")
def place_env():
    env = gym.make("wpbench/PlaceIn-v0", obs_mode="mesh", assets="procedural", split="val")
    yield env
    env.close()


@pytest.mark.parametrize("fraction", [0.3, 0.6, 1.0])
def test_best_joint_value_recovers_the_joint(door_env, fraction):
    door_env.reset(seed=1)
    base = door_env.unwrapped
    f = base.furniture
    q_goal = base.joint_fraction(fraction)
    now = f.target_link_pose()
    goal = f.target_link_pose_at(np.array([q_goal]))[0]
    surface = sample_mesh_surface(f.world_mesh([f.target_link]), 512, np.random.default_rng(0))
    q = best_joint_value(f, goal @ np.linalg.inv(now), surface)
    assert abs(q - q_goal) < 1e-3


@pytest.mark.parametrize("seed", [1, 2, 3])   # a cabinet door, a dishwasher's, a safe's
def test_a_door_driven_past_its_stop_is_held_there_and_one_left_short_is_not_open(door_env, seed):
    past = step_with(door_env, seed, lambda T: turned_about_hinge(T, 20.0))
    assert past["success"] and past["open_distance"] < 1e-3, past["failure_reason"]
    short = step_with(door_env, seed, lambda T: turned_about_hinge(T, -20.0))
    assert not short["success"] and short["failure_reason"] == "not_open_enough" and short["open_distance"] > 0.15


def test_half_open_prediction_is_not_a_success(door_env):
    door_env.reset(seed=2)
    base = door_env.unwrapped
    f = base.furniture
    half = f.target_link_pose_at(np.array([base.joint_fraction(0.5)]))[0] @ np.linalg.inv(f.target_link_pose())
    _, _, _, _, info = door_env.step(half)
    r = info["stage_result"]
    assert not r["success"] and 0.3 < r["open_distance"] < 0.8


@pytest.mark.parametrize("bad", [np.full((4, 4), np.nan), np.zeros((4, 4)) + np.inf])
def test_non_finite_prediction_fails_with_reason(place_env, bad):
    place_env.reset(seed=0)
    _, _, terminated, _, info = place_env.step(bad)
    r = info["stage_result"]
    assert bool(terminated[0]) and not r["success"]
    assert r["failure_reason"] == "invalid_prediction" and "invalid cross-pose" in r["failure_detail"]
    assert np.isnan(r["rot_err_deg"]) and np.isnan(r["trans_err_m"])


def test_pose_inside_a_wall_is_pushed_out(place_env):
    """Put the block's centre inside the furniture's top wall: physics must not leave it there."""
    place_env.reset(seed=3)
    base = place_env.unwrapped
    center, rotation, half = base.furniture.in_region_world(base.root_pose)
    goal = np.eye(4)
    goal[:3, :3] = base.root_pose[:3, :3]
    goal[:3, 3] = center + rotation @ np.array([0, 0, half[2] + 0.01])  # straddling the ceiling
    from wpbench.sim.poses import pose_to_matrix

    T = goal @ np.linalg.inv(pose_to_matrix(base.free_body.entity_pose))
    _, _, _, _, info = place_env.step(T)
    final = np.asarray(base.free_body.entity_pose.p)
    assert np.linalg.norm(final - goal[:3, 3]) > 1e-3  # it moved: the wall pushed it
    assert info["stage_result"]["executed"]


def test_runaway_simulation_is_a_failure_not_a_crash(place_env):
    place_env.reset(seed=4)
    base = place_env.unwrapped
    base.free_body.set_linear_velocity(np.array([0.0, 0.0, 100.0]))
    from wpbench.sim.executor import simulate_until_still

    result = simulate_until_still(base.advance_physics, 1 / 200, lambda: [np.asarray(base.free_body.linear_velocity)],
                                  lambda: False, max_seconds=0.2)
    assert not result.ok and result.reason == "blow_up" and "blow-up" in result.detail


def test_ideal_door_swings_at_a_bounded_speed_and_arrives(door_env):
    """The joint's target runs to the goal at IDEAL_JOINT_SPEED: no jolt through the whole range at once."""
    from wpbench.tasks.base import SIM_FREQ
    from wpbench.sim.executor import IDEAL_JOINT_SPEED, execute_articulated

    door_env.reset(seed=1, options={"start_fraction": 0.0})
    base = door_env.unwrapped
    f = base.furniture
    q_open = base.joint_fraction(1.0)
    T = f.target_link_pose_at(np.array([q_open]))[0] @ np.linalg.inv(f.target_link_pose())
    surface = sample_mesh_surface(f.world_mesh([f.target_link]), 512, np.random.default_rng(0))
    q_start = f.qpos
    speeds = []

    def step():
        f.hold()  # gravity compensation, as the task's own physics step does
        base.scene.px.step()
        speeds.append(abs(f.qvel))

    result = execute_articulated(f, T, surface, step, 1.0 / SIM_FREQ)
    assert result.ok and result.at_rest
    assert abs(f.qpos - q_open) < 0.02
    limit = IDEAL_JOINT_SPEED[f.asset.joint_type]
    assert max(speeds) < 1.3 * limit, f"peak joint speed {max(speeds):.2f} for a target moving at {limit}"
    assert result.sim_seconds >= abs(q_open - q_start) / limit
