"""The gripper executor against physics on fixed val episodes: gt opens the door,
identity does not, a 30-degree rotated door fails, results repeat by seed, and every
failure reason is a documented code."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from wpbench import tasks  # noqa: F401
from wpbench.sim.failure import FAILURE_REASONS
from executor_helpers import rotated_30, step_with


@pytest.fixture(scope="module")
def door_env():
    env = gym.make("wpbench/OpenDoor-v0", obs_mode="mesh", assets="procedural", split="val",
                   executor="gripper", grasp="suction")
    yield env
    env.close()


@pytest.mark.parametrize("seed", [0, 3])
def test_gt_opens_identity_does_not(door_env, seed):
    r = step_with(door_env, seed, lambda T: T)
    assert r["success"] and r["executor"] == "gripper" and r["grasp"] == "suction", r["failure_reason"]
    r = step_with(door_env, seed, lambda T: np.eye(4))
    assert not r["success"] and r["failure_reason"] == "not_open_enough"


def test_unknown_executor_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown executor"):
        gym.make("wpbench/OpenDoor-v0", obs_mode="mesh", split="val", executor="teleport")


def test_same_seed_same_outcome(door_env):
    a = step_with(door_env, 5, lambda T: rotated_30(T, 5))
    b = step_with(door_env, 5, lambda T: rotated_30(T, 5))
    assert a["q_final"] == b["q_final"] and a["failure_reason"] == b["failure_reason"]
    assert a["failure_reason"] in ("",) + FAILURE_REASONS
