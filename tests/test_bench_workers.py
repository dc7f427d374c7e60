"""``wpbench bench workers``: the numbers derived from a schedule's timings, the scaling
model, and the command end to end on a few episodes."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from wpbench.bench.workers import SCHEDULES, derive, scaling_model


def schedule(workers: int, startup: float, episode: float, gap: float, n: int) -> dict:
    """Timings of ``n`` episodes of ``episode`` s each on ``workers`` workers that are ready
    after ``startup`` s and lose ``gap`` s per episode in transit."""
    arrivals = sorted(startup + (k + 1) * episode + k * gap for k in range(math.ceil(n / workers))
                      for _ in range(workers))[:n]
    records = [{"episode_s": episode, "ran_on": {"host": "h", "pid": i % workers}, "episode": i, "success": True}
               for i in range(n)]
    return {"schedule": "workers-2", "wall_s": arrivals[-1] + 0.5, "arrivals_s": arrivals, "records": records,
            "driver_cpu_at_arrivals_s": [0.01 * (i + 1) for i in range(n)], "success_rate": 1.0,
            "load_average_before": [0.0, 0.0, 0.0], "load_average_after": [0.0, 0.0, 0.0]}


def test_startup_cost_overhead_and_driver_cpu_come_back_from_the_timings():
    got = derive(schedule(workers=2, startup=5.0, episode=1.0, gap=0.25, n=20), workers=2)
    assert got["startup_s"] == pytest.approx(5.0)
    assert got["episode_cost_s"] == pytest.approx(1.0)
    assert got["per_episode_overhead_s"] == pytest.approx(0.25)
    assert got["finish_s"] == pytest.approx(0.5)
    assert got["driver_cpu_s_per_episode"] == pytest.approx(0.01)
    assert got["processes"] == 2
    assert got["steady_episodes_per_min"] == pytest.approx(60 * 2 / 1.25)


def test_a_run_with_no_episode_after_the_first_round_is_refused():
    with pytest.raises(ValueError, match="run more episodes"):
        derive(schedule(workers=2, startup=1.0, episode=1.0, gap=0.0, n=2), workers=2)


def test_the_model_adds_startup_shipping_and_finish_and_knows_when_the_driver_bounds_it():
    row = scaling_model(cost_s=1.0, overhead_s=0.1, startup_s=10.0, driver_s=0.001, ship_s=2.0, finish_s=3.0,
                        episodes=1000, cores=8)
    assert row["wall_s"] == pytest.approx(10 + 2 + 125 * 1.1 + 3) and row["bound"] == "workers"
    assert row["core_hours"] == pytest.approx(row["wall_s"] * 8 / 3600)
    busy_driver = scaling_model(cost_s=1.0, overhead_s=0.0, startup_s=0.0, driver_s=0.1, episodes=1000, cores=64)
    assert busy_driver["wall_s"] == pytest.approx(100.0) and busy_driver["bound"] == "driver"


@pytest.mark.slow
def test_the_command_measures_the_three_schedules_and_writes_the_json(tmp_path, wpbench_exe):
    out = tmp_path / "bench-workers.json"
    done = subprocess.run([str(wpbench_exe), "bench", "workers", "--episodes", "4", "--policy", "gt", "--task",
                           "open-door", "--json", str(out)], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "2 workers vs 1" in done.stdout and "Ray vs local workers" in done.stdout
    result = json.loads(out.read_text())
    assert set(result["schedules"]) == set(SCHEDULES)
    assert [result["schedules"][s]["processes"] for s in SCHEDULES] == [1, 2, 2]
    assert all(result["schedules"][s]["episodes"] == 4 for s in SCHEDULES)
    assert [row["cores"] for row in result["model"]] == [1, 8, 64]
    assert result["shipping"] is None  # gt has no weights to ship


def test_a_bad_name_is_one_line(wpbench_exe):
    done = subprocess.run([str(wpbench_exe), "bench", "workers", "--task", "no-such-task"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode != 0 and "unknown task 'no-such-task'" in done.stderr
