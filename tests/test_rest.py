"""Rest is judged from the pose a body shows over its physics steps, not from the velocity
PhysX reports: a block wedged between two held drawers (storage 45332, docs/experiment-log.md)
keeps a reported 0.1 m/s and 2 rad/s while its pose does not move for 4 s. A body whose pose
moves is still not at rest, whatever velocity is reported."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import sapien

from wpbench import tasks  # noqa: F401
from wpbench.sim import failure
from wpbench.sim.executor import execute_free

TIMESTEP = 1 / 200
HALF = 0.03


def _block_scene(floor: bool, slope_deg: float = 0.0):
    """A SAPIEN scene with a 0.1 kg cube, on a frictionless floor tilted by ``slope_deg`` (or none)."""
    scene = sapien.Scene([sapien.physx.PhysxCpuSystem()])
    scene.set_timestep(TIMESTEP)
    if floor:
        ice = sapien.physx.PhysxMaterial(0.0, 0.0, 0.0)
        ground = scene.create_actor_builder()
        tilt = np.radians(slope_deg)
        ground.add_box_collision(half_size=[2.0, 2.0, 0.05], material=ice)
        ground.initial_pose = sapien.Pose([0, 0, -0.05], [np.cos(tilt / 2), 0, np.sin(tilt / 2), 0])
        ground.build_static(name="ground")
    builder = scene.create_actor_builder()
    builder.add_box_collision(half_size=[HALF] * 3, density=0.1 / (2 * HALF) ** 3,
                              material=sapien.physx.PhysxMaterial(0.0, 0.0, 0.0))
    builder.initial_pose = sapien.Pose([0, 0, 0.5])
    block = builder.build(name="block")
    return scene, block.find_component_by_type(sapien.physx.PhysxRigidDynamicComponent)


def _drop(scene, seconds: float = 2.0) -> None:
    """Let the block drop onto the floor and settle there."""
    for _ in range(int(seconds / TIMESTEP)):
        scene.step()


def test_stale_velocity_with_a_still_pose_is_at_rest():
    """The wedged block: each "step" reports 0.1 m/s and 2 rad/s and moves nothing (it stands in
    for PhysX's report on the pinched block of storage 45332)."""
    scene, body = _block_scene(floor=True)
    _drop(scene)

    def wedged_step():
        body.set_linear_velocity([-0.009, 0.008, -0.1])
        body.set_angular_velocity([1.9, 0.3, 0.2])

    result = execute_free(body, np.eye(4), wedged_step, TIMESTEP)
    assert result.ok and result.at_rest and result.reason == "", result
    assert result.sim_seconds < 0.5


def test_sliding_block_is_not_at_rest():
    """A block sliding down a frictionless 3-degree slope moves for the whole window."""
    scene, body = _block_scene(floor=True, slope_deg=3.0)
    body.entity.set_pose(sapien.Pose([0, 0, HALF + 0.001]))
    start = np.asarray(body.entity_pose.p).copy()
    result = execute_free(body, np.eye(4), scene.step, TIMESTEP)
    assert result.ok and not result.at_rest and result.reason == failure.NOT_AT_REST
    assert np.linalg.norm(np.asarray(body.entity_pose.p) - start) > 0.5


def test_falling_block_is_not_at_rest():
    """A block falling through air thick enough to hold it at a few dm/s never comes to rest."""
    scene, body = _block_scene(floor=False)
    body.set_linear_damping(50.0)
    start = np.asarray(body.entity_pose.p).copy()
    result = execute_free(body, np.eye(4), scene.step, TIMESTEP)
    assert result.ok and not result.at_rest and result.reason == failure.NOT_AT_REST
    assert start[2] - body.entity_pose.p[2] > 0.1


def test_a_moving_pose_with_zero_reported_velocity_is_not_at_rest():
    """The pose decides both ways: a block carried 1 mm a step while PhysX reports 0 m/s moves."""
    scene, body = _block_scene(floor=True)
    _drop(scene)

    def dragged_step():
        pose = body.entity_pose
        body.entity.set_pose(sapien.Pose(np.asarray(pose.p) + [0.001, 0, 0], pose.q))
        body.set_linear_velocity(np.zeros(3))
        body.set_angular_velocity(np.zeros(3))

    result = execute_free(body, np.eye(4), dragged_step, TIMESTEP)
    assert not result.at_rest and result.reason == failure.NOT_AT_REST


@pytest.fixture(scope="module")
def place_env():
    env = gym.make("wpbench/PlaceIn-v0", obs_mode="mesh", assets="procedural", split="val")
    yield env
    env.close()


def _pressed_into_its_floor(env) -> None:
    """After every step PhysX's velocity reads 0.1 m/s down, into the surface the block rests
    on: the contact holds it, the pose does not move (the wedged block's report)."""
    env.free_body.set_linear_velocity([0.0, 0.0, -0.1])


def _kicked_up(env) -> None:
    """Every 15 steps (75 ms) the block is tossed up at 0.37 m/s, the speed it falls back
    with 75 ms later: it bobs in place and never lands."""
    if env.physics_steps % 15 == 0:
        env.free_body.set_linear_velocity([0.0, 0.0, 0.37])


@pytest.mark.parametrize("hook, at_rest", [(_pressed_into_its_floor, True), (_kicked_up, False)])
def test_stage_verdict_follows_the_observed_pose(place_env, hook, at_rest):
    """At the true goal a reported velocity the block does not move with leaves the stage a
    success; a block that really keeps moving fails it as not at rest."""
    place_env.reset(seed=0)
    base = place_env.unwrapped
    base.on_physics_step = hook
    try:
        _, _, _, _, info = place_env.step(base.ground_truth()["cross_pose"])
    finally:
        base.on_physics_step = None
    r = info["stage_result"]
    assert r["success"] == at_rest and r["at_rest"] == at_rest, (r["failure_reason"], r["sim_seconds"])
    if not at_rest:
        assert r["failure_reason"] == failure.NOT_AT_REST and r["sim_seconds"] >= 4.0
