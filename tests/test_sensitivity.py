"""The sensitivity harness: its perturbations against exact answers (the nearest wall and
the into-wall move on a made-up room), a door turned 30 deg that the gripper cannot open,
a block goal 10 cm into a wall that it cannot place, and ``wpbench sensitivity`` end to
end as a real process (a two-stage task, the side-by-side figure)."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from wpbench import tasks  # noqa: F401
from wpbench.evaluation.runner import run_episode
from wpbench.evaluation.sensitivity import (CSV_COLUMNS, PerturbedTruth, PerturbedTruthConfig, hinge_tilted,
                                            motion_scaled, nearest_wall, perturb, plot_task, rotated_about,
                                            translated)
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


def _room():
    """A floor slab under the origin, a wall whose face is at x = 0.3 and one at y = -0.5."""
    floor = trimesh.creation.box(extents=[2.0, 2.0, 0.02])
    floor.apply_translation([0.0, 0.0, -0.01])
    near = trimesh.creation.box(extents=[0.02, 2.0, 1.0])
    near.apply_translation([0.31, 0.0, 0.5])
    far = trimesh.creation.box(extents=[2.0, 0.02, 1.0])
    far.apply_translation([0.0, -0.51, 0.5])
    return trimesh.util.concatenate([floor, near, far])


def _block(half=0.05, centre=(0.0, 0.0, 0.05)):
    """Surface samples of a cube of half-width ``half`` resting on the floor."""
    return trimesh.creation.box(extents=[2 * half] * 3).sample(2000, seed=0) + np.asarray(centre)


def test_nearest_wall_is_beside_the_object_not_under_it():
    # The floor touches the block (gap 0) but lies under it; the wall at x = 0.3 is 0.25 from its side.
    direction, gap = nearest_wall(_block(), _room())
    np.testing.assert_allclose(direction, [1.0, 0.0, 0.0], atol=1e-12)
    assert gap == pytest.approx(0.25, abs=1e-3)


@pytest.mark.parametrize("overlap", [0.0, 0.1, 0.2])
def test_into_wall_lands_the_goal_exactly_the_overlap_past_the_wall(overlap):
    room, block = _room(), _block()
    T = np.eye(4)
    T[:3, 3] = [0.05, 0.02, 0.0]     # the true goal: still 0.2 from the wall
    out = perturb("into_wall", overlap, T, "free-floating", block, np.random.default_rng(0), lambda: room)
    goal = block @ out[:3, :3].T + out[:3, 3]
    assert goal[:, 0].max() == pytest.approx(0.3 + overlap, abs=1e-3)
    np.testing.assert_allclose(out[1:3, 3], T[1:3, 3], atol=1e-12)
    np.testing.assert_allclose(out[:3, :3], np.eye(3), atol=1e-12)
    toward = perturb("translation_wall", 0.1, T, "free-floating", block, np.random.default_rng(0), lambda: room)
    np.testing.assert_allclose(toward[:3, 3], [0.15, 0.02, 0.0], atol=1e-12)


def test_a_stage_keeps_its_truth_under_the_other_kinds_perturbations():
    T = _hinge(0.3, [0.1, 0.0, 0.0])
    for kind, stage in (("hinge_tilt", "free-floating"), ("motion_scale", "free-floating"), ("into_wall", "articulated")):
        out = perturb(kind, 0.2, T, stage, _block(), np.random.default_rng(0), _room)
        np.testing.assert_array_equal(out, T)


def _place_in_outcomes(kind, sizes, seed):
    env = gym.make("wpbench/PlaceIn-v0", obs_mode="mesh", assets="procedural", split="val",
                   executor="gripper", grasp="suction")
    try:
        outcomes = {}
        for size in sizes:
            policy = PerturbedTruth(PerturbedTruthConfig(perturbation=kind, size=size), env.unwrapped)
            policy.seed = seed
            outcomes[size] = run_episode(env, policy, seed)
    finally:
        env.close()
    return outcomes


def test_block_goal_10cm_into_a_wall_fails_under_the_gripper():
    # Episode 0 is a storage cabinet whose nearest wall is 14 cm from the block: touching it
    # the gripper still places the block; 10 cm into it, the block hits the wall.
    outcomes = _place_in_outcomes("into_wall", (0.0, 0.10), 0)
    assert outcomes[0.0]["success"]
    assert not outcomes[0.10]["success"] and outcomes[0.10]["stages"][0]["failure_reason"]


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
    # A two-stage task: each point counts each stage's successes too.
    cmd = [WPBENCH, "sensitivity", "--executor", "ideal", "--task", "open-then-place",
           "--episodes", "1", "--perturbation", "rotation", "--perturbation", "into_wall", "--out", str(tmp_path)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    with open(tmp_path / "open-then-place_ideal.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == CSV_COLUMNS
    assert [r["perturbation"] for r in rows] == ["rotation"] * 5 + ["into_wall"] * 5
    assert all(r["episodes"] == "1" and 0 <= float(r["ci_low"]) <= float(r["success_rate"]) <= float(r["ci_high"]) <= 1
               for r in rows)
    stages = [tuple(int(n) for n in r["stage_successes"].split(";")) for r in rows]
    assert all(len(st) == 2 and min(st) >= int(r["successes"]) for st, r in zip(stages, rows))
    assert rows[0]["successes"] == "1" and rows[5]["successes"] == "1"   # unperturbed; touching the wall
    assert rows[7]["successes"] == "0"                                     # 10 cm into the wall
    assert (tmp_path / "open-then-place_ideal.png").stat().st_size > 1000
    assert (tmp_path / "open-then-place.png").stat().st_size > 1000


def test_side_by_side_figure_has_one_line_per_executor(tmp_path):
    header = ",".join(CSV_COLUMNS)
    for executor, grasp, wins in (("ideal", "", 4), ("gripper", "suction", 1)):
        lines = [header] + [f"place-in,{executor},{grasp},{kind},{size},{unit},4,{wins},{wins / 4},0.0,1.0,{wins},0"
                            for kind, unit in (("rotation", "deg"), ("into_wall", "m")) for size in (0.0, 0.1)]
        stem = f"place-in_{executor}" + (f"_{grasp}" if grasp else "")
        (tmp_path / f"{stem}.csv").write_text("\n".join(lines) + "\n")
    import matplotlib.pyplot as plt

    drawn = []
    real_savefig = plt.Figure.savefig

    def spy(fig, *args, **kwargs):
        drawn.append([[line.get_label() for line in ax.get_lines()] for ax in fig.axes if ax.get_visible()])
        return real_savefig(fig, *args, **kwargs)

    plt.Figure.savefig = spy
    try:
        path = plot_task(tmp_path, "place-in")
    finally:
        plt.Figure.savefig = real_savefig
    assert path == tmp_path / "place-in.png" and path.stat().st_size > 1000
    assert drawn == [[["ideal", "gripper (suction)"]] * 2]
    done = subprocess.run([WPBENCH, "sensitivity", "--task", "open-door", "--plot-only", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2 and "no open-door_*.csv" in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_unknown_task_is_a_one_line_error(tmp_path):
    done = subprocess.run([WPBENCH, "sensitivity", "--executor", "ideal", "--task", "nope",
                           "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert done.returncode != 0 and "unknown task 'nope'" in done.stderr
