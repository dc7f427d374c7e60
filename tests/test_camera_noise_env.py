"""Camera noise as a user meets it: in the env's observation and through `wpbench run`."""

from __future__ import annotations

import json
import subprocess

import gymnasium as gym
import numpy as np
import pytest

from wpbench import names


def observe(seed: int, **kwargs) -> dict:
    names.import_task("open-door")
    env = gym.make(names.TASKS["open-door"].env_id, obs_mode="camera", assets="procedural", split="val",
                   camera_resolution=128, **kwargs)
    try:
        obs, _ = env.reset(seed=seed)
        return {key: obs[key][0].numpy().copy() for key in ("action_points", "anchor_points")}
    finally:
        env.close()


@pytest.fixture(scope="module")
def clean():
    return observe(3)


def test_clean_settings_give_the_default_observation(clean):
    again = observe(3, camera_noise={})
    for key in clean:
        np.testing.assert_array_equal(again[key], clean[key])


def test_depth_noise_moves_the_points_and_is_the_same_for_the_same_seed(clean):
    noisy = observe(3, camera_noise={"depth_std": 0.01})
    repeat = observe(3, camera_noise={"depth_std": 0.01})
    for key in clean:
        np.testing.assert_array_equal(noisy[key], repeat[key])
    # Depth noise at 1-2 m is 1-4 cm: the anchor cloud's nearest-neighbour distance to the
    # clean cloud grows well beyond the clean cloud's own resampling jitter.
    from scipy.spatial import cKDTree

    gap = cKDTree(clean["anchor_points"]).query(noisy["anchor_points"])[0]
    assert np.median(gap) > 0.005


def test_mesh_observations_refuse_camera_noise():
    names.import_task("open-door")
    with pytest.raises(ValueError, match="camera noise needs obs_mode='camera'"):
        gym.make(names.TASKS["open-door"].env_id, obs_mode="mesh", camera_noise={"depth_std": 0.01})


def run_wpbench(exe, *args, timeout=300):
    return subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


def test_a_noisy_run_records_its_settings_and_cannot_be_resumed_clean(wpbench_exe, tmp_path):
    out = tmp_path / "noisy"
    common = ["run", "--policy", "gt", "--task", "place-in", "--episodes", "1", "--workers", "1",
              "--no-progress", "--out", str(out)]
    result = run_wpbench(wpbench_exe, *common, "--depth-noise", "0.003", "--seg-noise-px", "1")
    assert result.returncode == 0, result.stderr
    assert json.loads((out / "run.json").read_text())["camera_noise"] == {"depth_std": 0.003, "boundary_px": 1}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["meta"]["camera_noise"] == {"depth_std": 0.003, "boundary_px": 1}
    again = run_wpbench(wpbench_exe, *common, "--episodes", "2", "--resume")
    assert again.returncode != 0 and "camera_noise" in again.stderr
    assert len((out / "episodes.jsonl").read_text().splitlines()) == 1


def test_noise_options_without_a_camera_are_one_line_errors(wpbench_exe, tmp_path):
    result = run_wpbench(wpbench_exe, "run", "--policy", "gt", "--obs", "mesh", "--depth-noise", "0.01",
                         "--episodes", "1", "--out", str(tmp_path / "x"))
    assert result.returncode == 2 and "need --obs camera" in result.stderr
    assert not (tmp_path / "x").exists()
