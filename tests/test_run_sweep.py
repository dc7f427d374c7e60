"""``wpbench sweep``: one resumable folder per combination, all episodes on one pool, a leaderboard."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from wpbench.evaluation.sweep import sweep_configs
from wpbench.names import DEFAULT_EXECUTOR


def test_every_combination_gets_its_own_resumable_folder(tmp_path):
    configs = sweep_configs(["gt", "identity"], ["open-door", "place-in"], 3, tmp_path,
                            executors=["ideal", "gripper"], obs="mesh")
    assert len(configs) == 8 and all(c.resume and c.episodes == 3 for c in configs)
    folders = {c.out for c in configs}
    assert len(folders) == 8 and all(f.parent == tmp_path / "runs" for f in folders)
    assert tmp_path / "runs" / "gt__open-door__val__procedural__mesh" in folders  # ideal keeps the old names
    assert tmp_path / "runs" / "gt__open-door__val__procedural__mesh__gripper" in folders


@pytest.mark.slow
def test_a_sweep_with_two_workers_writes_the_leaderboard_and_resumes(wpbench_exe, tmp_path):
    args = [str(wpbench_exe), "sweep", "--policies", "gt,identity", "--tasks", "open-door", "--episodes", "2",
            "--obs", "mesh", "--workers", "2", "--results", str(tmp_path), "--no-progress"]
    first = subprocess.run(args, capture_output=True, text=True, timeout=900)
    assert first.returncode == 0, first.stderr
    board = (tmp_path / "leaderboard.md").read_text()
    assert "`gt`" in board and "`identity`" in board and "100.0%" in board
    again = subprocess.run(args, capture_output=True, text=True, timeout=900)  # all done: resumes, runs nothing
    assert again.returncode == 0, again.stderr
    # No --executors: the default executor's runs, in folders named after it.
    run = tmp_path / "runs" / f"gt__open-door__val__procedural__mesh__{DEFAULT_EXECUTOR}"
    assert len((run / "episodes.jsonl").read_text().splitlines()) == 2
