"""The sensitivity harness: its perturbations against exact answers, a door turned 30 deg
that the gripper cannot open, and ``wpbench sensitivity`` end to end as a real process."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wpbench import tasks  # noqa: F401
from wpbench.evaluation.runner import run_episode
from wpbench.evaluation.sensitivity import (PerturbedTruth, PerturbedTruthConfig, hinge_tilted, motion_scaled,
                                            nearest_wall_direction, rotated_about, translated)
from wpbench.sim.screw_path import screw_of

WPBENCH = str(Path(sys.executable).with_name("wpbench"))


def _hinge(angle, point, axis=(0.0, 0.0, 1.0)):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(angle * np.asarray(axis)).as_matrix()
    T[:3, 3] = np.asarray(point) - T[:3, :3] @ np.asarray(point)
    return T


def test_rotation_keeps_its_centre_and_turns_by_the_size():
    T = _hinge(0.7, [1.0, 0.0, 0.0])
    centre = np.array([0.3, -0.2, 0.5])
    out = rotated_about(T, 30.0, [1.0, 1.0, 0.0], centre)
    extra = out @ np.linalg.inv(T)
    np.testing.assert_allclose(extra[:3, :3] @ centre + extra[:3, 3], centre, atol=1e-12)
    assert np.degrees(np.linalg.norm(Rotation.from_matrix(extra[:3, :3]).as_rotvec())) == pytest.approx(30.0)


def test_translation_moves_by_the_offset():
    np.testing.assert_allclose(translated(np.eye(4), [0.1, 0, 0])[:3, 3], [0.1, 0, 0])


def test_hinge_tilt_tilts_the_axis_and_keeps_the_angle():
    T = _hinge(np.pi / 3, [0.5, 0.2, 0.0])
    out = screw_of(hinge_tilted(T, 20.0, [1.0, 0.0, 0.0]))
    assert out.angle == pytest.approx(np.pi / 3)
    assert np.degrees(np.arccos(out.axis @ [0.0, 0.0, 1.0])) == pytest.approx(20.0)


def test_motion_scale_is_a_power_of_T():
    T = _hinge(0.8, [0.4, 0.1, 0.0])
    np.testing.assert_allclose(motion_scaled(T, 1.0), T, atol=1e-12)
    half = motion_scaled(T, 0.5)
    np.testing.assert_allclose(half @ half, T, atol=1e-12)
    assert screw_of(motion_scaled(T, 1.5)).angle == pytest.approx(1.2)


def test_nearest_wall_is_beside_the_object_not_under_it():
    floor = np.array([[x, y, 0.0] for x in np.linspace(-1, 1, 21) for y in np.linspace(-1, 1, 21)])
    wall = np.array([[0.3, y, z] for y in np.linspace(-1, 1, 21) for z in np.linspace(0, 1, 101)])
    d = nearest_wall_direction(np.array([0.0, 0.0, 0.05]), (0.0, 0.1), np.concatenate([floor, wall]))
    np.testing.assert_allclose(d, [1.0, 0.0, 0.0], atol=1e-12)


def test_door_turned_30_degrees_fails_under_the_gripper():
    # Episode 3 is a safe's side-hinged door: turned 30 deg about its random axis, the hand
    # pulls against the hinge. (A drawer turned about an axis near its rail may still open.)
    env = gym.make("wpbench/OpenDoor-v0", obs_mode="mesh", assets="procedural", split="val",
                   executor="gripper", grasp="suction")
    try:
        outcomes = {}
        for size in (0.0, 30.0):
            policy = PerturbedTruth(PerturbedTruthConfig(perturbation="rotation", size=size), env.unwrapped)
            policy.seed = 3
            outcomes[size] = run_episode(env, policy, 3)
    finally:
        env.close()
    assert outcomes[0.0]["success"]
    assert not outcomes[30.0]["success"] and outcomes[30.0]["stages"][0]["failure_reason"]


def test_command_runs_end_to_end(tmp_path):
    cmd = [WPBENCH, "sensitivity", "--executor", "ideal", "--task", "place-in",
           "--episodes", "2", "--perturbation", "rotation", "--perturbation", "translation_wall", "--out", str(tmp_path)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    with open(tmp_path / "place-in_ideal.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["perturbation"] for r in rows] == ["rotation"] * 5 + ["translation_wall"] * 5
    assert all(r["episodes"] == "2" and 0 <= float(r["ci_low"]) <= float(r["success_rate"]) <= float(r["ci_high"]) <= 1
               for r in rows)
    assert (tmp_path / "place-in_ideal.png").stat().st_size > 1000


def test_unknown_task_is_a_one_line_error(tmp_path):
    done = subprocess.run([WPBENCH, "sensitivity", "--executor", "ideal", "--task", "nope",
                           "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert done.returncode != 0 and "unknown task 'nope'" in done.stderr
