"""``wpbench bench episodes``: episodes per minute and peak memory of each task
and observation mode on this machine.

Each (task, obs) cell runs in a fresh subprocess so its peak RSS is its own, with
the ``gt`` policy (the cheapest policy: what is measured is the simulator, the
camera and the executor). The peak memory of the ``panda`` executor includes its mplib
planner process.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

from wpbench.names import BUILTIN_TASKS as TASKS
from wpbench.names import OBS_MODES as OBS

_CHILD = r"""
import json, resource, sys, time
from pathlib import Path
from wpbench.evaluation.runner import RunConfig, run_benchmark
task, obs, episodes, out, executor = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5]


def helper_peak_mib():
    # The panda executor's mplib planner runs in a child process that is still alive: its own peak counts too.
    from wpbench.sim.arm_planner import ArmPlanner
    helper = ArmPlanner._shared
    if helper is None:
        return 0.0
    for line in Path(f"/proc/{helper._proc.pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return 0.0


t0 = time.perf_counter()
summary = run_benchmark(RunConfig(policy="gt", task=task, split="val", episodes=episodes, obs=obs, out=Path(out),
                                  executor=executor), progress=False)
wall = time.perf_counter() - t0
print(json.dumps({"task": task, "obs": obs, "executor": executor, "episodes": episodes, "wall_s": wall,
                  "episodes_per_min": 60.0 * episodes / wall, "success_rate": summary["success_rate"],
                  "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 + helper_peak_mib()}))
"""


def measure(task: str, obs: str, episodes: int, executor: str = "ideal") -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        proc = subprocess.run([sys.executable, "-c", _CHILD, task, obs, str(episodes), str(Path(tmp) / "run"), executor],
                              capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"benchmark of {task}/{obs}/{executor} failed:\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run(episodes: int = 10, tasks: tuple[str, ...] = TASKS, obs_modes: tuple[str, ...] = OBS,
        json_path: Path | None = None, executor: str = "ideal") -> list[dict]:
    """Time every (task, obs) cell with the ``gt`` policy and ``executor``; print a table."""
    from tabulate import tabulate

    from wpbench.names import EXECUTORS

    if executor not in EXECUTORS:
        raise ValueError(f"unknown executor {executor!r}; valid: {', '.join(EXECUTORS)}")
    rows = [measure(task, obs, episodes, executor) for task in tasks for obs in obs_modes]
    print(tabulate(
        [[r["task"], r["obs"], r["executor"], r["episodes"], f"{r['episodes_per_min']:.1f}", f"{r['peak_rss_mib']:.0f}",
          f"{r['success_rate']:.0%}"] for r in rows],
        headers=["task", "obs", "executor", "episodes", "episodes/min", "peak RSS (MiB)", "gt success"],
    ))
    if json_path is not None:
        Path(json_path).write_text(json.dumps(rows, indent=2) + "\n")
    return rows
