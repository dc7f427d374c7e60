"""``wpbench run --workers N``: the same episodes, the same results, whatever N.

A run made by N worker processes must equal the serial run of the same seed (except
the timings and where each episode ran), in episode order; ``--resume`` works with
any N; a worker killed with SIGKILL costs nothing (its episode runs again), and an
episode that kills its worker twice is recorded as a failure with the reason.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from wpbench.evaluation.records import read_episodes

FAST = ("--policy", "identity", "--task", "open-then-place", "--obs", "mesh", "--no-progress")
# Fields that differ between schedules by nature: how long things took and where they ran.
SCHEDULE_FIELDS = ("timings", "ran_on")


def wpbench(exe: Path, *args: str, timeout: float = 900) -> subprocess.CompletedProcess:
    result = subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=timeout,
                            stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr[-3000:]
    return result


def content(run: Path) -> list[dict]:
    """The run's records without timings and placement, in file order."""
    records = []
    for line in (run / "episodes.jsonl").read_text().splitlines():
        record = {k: v for k, v in json.loads(line).items() if k not in SCHEDULE_FIELDS}
        record["stages"] = [{k: v for k, v in stage.items() if k != "exec_seconds"} for stage in record["stages"]]
        records.append(record)
    return records


@pytest.fixture(scope="module")
def serial_run(wpbench_exe, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("serial") / "run"
    wpbench(wpbench_exe, "run", *FAST, "--episodes", "4", "--workers", "1", "--out", str(out))
    return out


def test_schedule_fields_are_the_only_difference_the_comparison_ignores(serial_run):
    records = content(serial_run)
    assert [r["episode"] for r in records] == [0, 1, 2, 3]
    assert all("rot_err_deg" in r and r["stages"] for r in records)


@pytest.mark.slow
def test_two_workers_give_the_serial_run_and_resume_works_with_any_number(wpbench_exe, serial_run, tmp_path):
    out = tmp_path / "run"
    wpbench(wpbench_exe, "run", *FAST, "--episodes", "2", "--workers", "2", "--out", str(out))
    wpbench(wpbench_exe, "run", *FAST, "--episodes", "3", "--workers", "1", "--resume", "--out", str(out))
    wpbench(wpbench_exe, "run", *FAST, "--episodes", "4", "--workers", "2", "--resume", "--out", str(out))
    assert content(out) == content(serial_run)
    pids = {json.loads(line)["ran_on"]["pid"] for line in (out / "episodes.jsonl").read_text().splitlines()}
    assert len(pids) >= 3  # three sessions, two of them with two workers


def _worker_pids(driver: int) -> list[int]:
    """The spawned worker processes of ``driver`` (not multiprocessing's resource tracker)."""
    children = Path(f"/proc/{driver}/task/{driver}/children").read_text().split()
    return [int(pid) for pid in children
            if b"multiprocessing.spawn" in Path(f"/proc/{pid}/cmdline").read_bytes()]


@pytest.mark.slow
def test_a_worker_killed_mid_episode_costs_nothing(wpbench_exe, serial_run, tmp_path):
    out = tmp_path / "run"
    driver = subprocess.Popen([str(wpbench_exe), "run", *FAST, "--episodes", "4", "--workers", "2", "--out", str(out)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    episodes = out / "episodes.jsonl"
    deadline = time.monotonic() + 300
    while not (episodes.exists() and episodes.stat().st_size) and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(0.3)
    victims = _worker_pids(driver.pid)
    assert victims, "no worker process found"
    os.kill(victims[0], signal.SIGKILL)
    _, stderr = driver.communicate(timeout=600)
    assert driver.returncode == 0, stderr[-3000:]
    assert content(out) == content(serial_run)


class DyingSession:
    """Stands in for an EpisodeSession: episode 1 kills its worker the first time only,
    episode 2 every time; the others succeed at once."""

    def __init__(self, cfg) -> None:
        self.cfg = cfg

    def run(self, index: int) -> dict:
        from wpbench.evaluation.runner import failure_record, run_fields

        marker = Path(os.environ["WPBENCH_TEST_MARKERS"]) / f"episode-{index}"
        if index == 2 or (index == 1 and not marker.exists()):
            marker.touch()
            os.kill(os.getpid(), signal.SIGKILL)
        record = failure_record(self.cfg, index, "")
        record.update(run_fields(self.cfg, index), object_id=f"object-{index}", category="oven",
                      rot_err_deg=1.0, trans_err_m=0.01, point_err_m=0.01, point_mse=1e-4)
        record.pop("failure_reason")
        return record

    def close(self) -> None:
        pass


def test_an_episode_that_kills_its_worker_twice_is_a_failure_with_the_reason(tmp_path, monkeypatch):
    from wpbench.evaluation.driver import run_many
    from wpbench.evaluation.local_workers import LocalWorkerPool
    from wpbench.evaluation.runner import RunConfig

    monkeypatch.setenv("WPBENCH_TEST_MARKERS", str(tmp_path))
    pool = LocalWorkerPool(2, session_factory=DyingSession)
    summary, = run_many([RunConfig(policy="identity", task="open-door", episodes=4, out=tmp_path / "run")], pool,
                        progress=False)
    records = read_episodes(tmp_path / "run")
    assert [r["episode"] for r in records] == [0, 1, 2, 3]  # each once, in order
    assert "failure_reason" not in records[1]  # retried once, then ran
    assert records[2]["failure_reason"] == "worker process died (killed by signal 9) while running this episode, 2 times"
    assert summary["episodes"] == 4
    # A replacement for each death while episodes were still waiting: the first two deaths
    # always, the last one only if an episode was still unassigned then.
    assert 2 + 2 <= pool.started <= 2 + 3


@pytest.mark.slow
def test_a_learned_policy_answers_the_same_in_workers(wpbench_exe, tmp_path):
    """The learned policy seeds its own random subsets and runs with a different torch
    thread count in each worker: the poses must not change."""
    common = ("run", "--policy", "wp", "--task", "open-then-place", "--obs", "mesh", "--episodes", "2",
              "--no-progress")
    wpbench(wpbench_exe, *common, "--workers", "1", "--out", str(tmp_path / "serial"))
    wpbench(wpbench_exe, *common, "--workers", "2", "--out", str(tmp_path / "workers"))
    serial, workers = content(tmp_path / "serial"), content(tmp_path / "workers")
    assert [r["success"] for r in serial] == [r["success"] for r in workers]
    assert [[s["pred_cross_pose"] for s in r["stages"]] for r in serial] == \
        [[s["pred_cross_pose"] for s in r["stages"]] for r in workers]
    assert serial == workers
