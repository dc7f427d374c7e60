"""Executor versions (wpbench.evaluation.executor_version): which (executor, task) pairs a listed
change touches, the reason a run carried out by an older version gets, run.json recording the
version, --resume refusing to mix versions, and the leaderboard and paper table leaving such runs
out the way a user meets them."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from wpbench.evaluation.executor_version import EXECUTOR_CHANGES, executor_version, older_executor_reason
from wpbench.evaluation.leaderboard import collect_summaries, leaderboard_markdown
from wpbench.names import ARTICULATED, FREE


def _changes(executor: str, kind: str | None = None) -> int:
    return sum(1 for name, touched, _ in EXECUTOR_CHANGES if name == executor and (kind is None or touched == kind))


def test_a_change_moves_only_the_tasks_with_a_stage_of_the_kind_it_touches():
    assert _changes("gripper", FREE) >= 1 and _changes("panda", FREE) >= 1 and _changes("panda", ARTICULATED) >= 1
    for executor in ("gripper", "panda"):
        assert executor_version(executor, "open-door") == 1 + _changes(executor, ARTICULATED)
        assert executor_version(executor, "place-in") == 1 + _changes(executor, FREE)
        assert executor_version(executor, "open-then-place") == 1 + _changes(executor)
        assert executor_version(executor, "a-task-nobody-registered") == 1 + _changes(executor)
    assert executor_version("ideal", "open-then-place") == 1 + _changes("ideal")
    # The panda's door change moved open-door, not place-in.
    assert executor_version("panda", "open-door") > 1 and executor_version("panda", "place-in") == 1 + _changes("panda", FREE)


def _run(tmp_path: Path, name: str, **stored) -> Path:
    run = tmp_path / name
    run.mkdir(parents=True)
    (run / "run.json").write_text(json.dumps(stored))
    return run


def test_only_a_run_of_an_older_version_gets_a_reason(tmp_path):
    current = executor_version("gripper", "place-in")
    old = _run(tmp_path, "old", task="place-in", executor="gripper")     # made before run.json recorded it
    assert older_executor_reason(old) == (
        f"{old} was carried out by version 1 of the gripper executor for place-in, and today's is version "
        f"{current}; score it again")
    assert older_executor_reason(_run(tmp_path, "new", task="place-in", executor="gripper", executor_version=current)) is None
    assert older_executor_reason(_run(tmp_path, "door", task="open-door", executor="gripper")) is None
    assert older_executor_reason(_run(tmp_path, "ideal", task="place-in")) is None
    assert older_executor_reason(tmp_path / "missing") is None
    (tmp_path / "corrupt").mkdir()
    (tmp_path / "corrupt" / "run.json").write_text("{not json")
    assert older_executor_reason(tmp_path / "corrupt") is None


def test_a_run_records_its_executor_version():
    from wpbench.evaluation.runner import RunConfig, produced_by
    from wpbench.policies.registry import make_policy

    made = produced_by(RunConfig(policy="gt", task="open-then-place", executor="panda"), make_policy("gt"))
    assert made["executor_version"] == executor_version("panda", "open-then-place") > 1


def test_the_leaderboard_leaves_out_a_run_of_an_older_executor_version_with_the_reason(tmp_path):
    from test_leaderboard import add_run

    old = add_run(tmp_path, "place/old-wp", "wp", "place-in", 3, 10).parent
    (old / "run.json").write_text(json.dumps({"task": "place-in", "executor": "gripper"}))
    new = add_run(tmp_path, "place/new-wp", "wp", "place-in", 7, 10).parent
    (new / "run.json").write_text(json.dumps({"task": "place-in", "executor": "gripper",
                                              "executor_version": executor_version("gripper", "place-in")}))
    door = add_run(tmp_path, "open/old-wp", "wp", "open-door", 5, 10).parent
    (door / "run.json").write_text(json.dumps({"task": "open-door", "executor": "gripper"}))
    with pytest.warns(UserWarning, match="version 1 of the gripper executor for place-in"):
        frame, skipped = collect_summaries(tmp_path)
    assert skipped == [old / "summary.json"]
    assert set(frame.run) == {"place/new-wp", "open/old-wp"}
    text = leaderboard_markdown(frame, skipped)
    assert "older version of their executor left out" in text and "place/old-wp" in text
    assert "Unreadable" not in text


def test_the_paper_table_refuses_a_run_of_an_older_executor_version_before_any_work(tmp_path: Path, wpbench_exe):
    from wpbench.evaluation.paper_table import PaperTableConfig, run_dir

    data = tmp_path / "data"
    (data / "train").mkdir(parents=True)
    (data / "val").mkdir()
    results = tmp_path / "results"
    old = run_dir(PaperTableConfig(results=results), "wp-postsvd-t", "place-in", split="test", executor="gripper")
    old.mkdir(parents=True)
    (old / "run.json").write_text(json.dumps({"assets": "procedural", "task": "place-in", "executor": "gripper"}))
    (old / "summary.json").write_text(json.dumps({"success_rate": 0.5}))
    out = tmp_path / "table.md"
    done = subprocess.run([str(wpbench_exe), "paper-table", "--data", str(data), "--results", str(results),
                           "--no-run-missing", "--executors", "ideal,gripper", "--out", str(out)],
                          capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("Error: ") and old.name in line and "version 1 of the gripper executor" in line
    assert "Traceback" not in done.stderr
    assert not out.exists()
