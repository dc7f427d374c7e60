"""``wpbench bench workers``: how episodes scale with workers, what Ray adds, and what
1,000 episodes would cost on more cores.

Three schedules of the same run (one policy, one task, one observation mode, the same
episodes) each in a fresh subprocess, so nothing is warm from the one before:

* ``workers-1``: ``--workers 1`` (the episodes in the driver process), torch on one
  thread: one core's worth;
* ``workers-2``: ``--workers 2`` (two local worker processes, one thread each);
* ``ray-2``: ``--ray`` on a local cluster of 2 CPUs started by the run (two actors).

From each schedule's wall clock ``T``, the arrival time of every record at the driver
and each record's own ``timings.episode_s`` (the episode inside its worker), with
``W`` workers and ``n`` episodes:

* startup ``S``: the arrival of the ``W``-th record minus that episode's own time, i.e.
  when the last worker was ready (processes or cluster started, imports, env and policy
  built, weights shipped);
* per-episode cost ``c``: mean ``episode_s``;
* per-episode wall ``p = W * (t_n - t_W) / (n - W)`` from the arrivals ``t`` after every
  worker's first episode, and overhead ``o = p - c``: what a worker spends per episode
  beyond the episode itself (the job and the record in transit, waiting for the driver);
* finish ``F``: from the last arrival to the end (summary written, workers stopped);
* driver CPU ``d``: the driver process's CPU seconds per episode in the steady state
  (the ceiling of any pool is ``1 / d`` episodes per second);
* shipping: packing the weights folder into one archive and unpacking it, and its size
  (what a Ray node receives once per run).

The model (:func:`scaling_model`) puts them together for ``N`` cores:
``T(n, N) = S + ship + max(ceil(n / N) * (c + o), n * d) + F``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

__all__ = ["SCHEDULES", "measure", "derive", "scaling_model", "shipping_cost", "run"]

SCHEDULES = ("workers-1", "workers-2", "ray-2")
MODEL_CORES = (1, 8, 64)
MODEL_EPISODES = 1000
TARGET_SPEEDUP = 1.7
TARGET_RAY_OVERHEAD = 0.10

_CHILD = r"""
import json, os, resource, sys, time
schedule, policy, task, obs, episodes, out = sys.argv[1:7]
episodes = int(episodes)
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
from wpbench.evaluation.local_workers import set_thread_count
set_thread_count(1)
from wpbench.evaluation.driver import InProcessPool, run_many
from wpbench.evaluation.runner import RunConfig
arrivals, records = [], []
driver_cpu = []
def on_episode(record):
    arrivals.append(time.perf_counter() - t0)
    usage = resource.getrusage(resource.RUSAGE_SELF)
    driver_cpu.append(usage.ru_utime + usage.ru_stime)
    records.append({"episode_s": record.get("timings", {}).get("episode_s"), "ran_on": record.get("ran_on", {}),
                    "episode": record["episode"], "success": bool(record.get("success"))})
cfg = RunConfig(policy=policy, task=task, split="val", episodes=episodes, obs=obs, out=os.path.join(out, "run"))
t0 = time.perf_counter()
if schedule == "workers-1":
    pool = InProcessPool()
elif schedule == "workers-2":
    from wpbench.evaluation.local_workers import LocalWorkerPool
    pool = LocalWorkerPool(2)
else:
    from wpbench.evaluation.ray_workers import RayPool
    pool = RayPool(address=None, workers=2, num_cpus=2)
summary = run_many([cfg], pool, progress=False, on_episode=on_episode)[0]
wall = time.perf_counter() - t0
print(json.dumps({"schedule": schedule, "wall_s": wall, "arrivals_s": arrivals, "records": records,
                  "driver_cpu_at_arrivals_s": driver_cpu,
                  "success_rate": summary["success_rate"]}))
"""


def _load() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


def measure(schedule: str, policy: str, task: str, obs: str, episodes: int) -> dict[str, Any]:
    """One schedule's raw timings (see the module docstring), from a fresh subprocess."""
    if schedule not in SCHEDULES:
        raise ValueError(f"unknown schedule {schedule!r}; valid: {', '.join(SCHEDULES)}")
    load_before = _load()
    with tempfile.TemporaryDirectory() as tmp:
        proc = subprocess.run([sys.executable, "-c", _CHILD, schedule, policy, task, obs, str(episodes), tmp],
                              capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"benchmark schedule {schedule} failed:\n{proc.stderr[-2000:]}")
    raw = json.loads(proc.stdout.strip().splitlines()[-1])
    raw["load_average_before"], raw["load_average_after"] = load_before, _load()
    return raw


def derive(raw: dict[str, Any], workers: int) -> dict[str, Any]:
    """Startup, per-episode cost and overhead, finish, driver CPU and rates from one schedule's
    timings. Episodes ``W..n-1`` (after every worker has delivered its first) are the steady state."""
    records, arrivals, cpu = raw["records"], raw["arrivals_s"], raw["driver_cpu_at_arrivals_s"]
    n, wall = len(records), raw["wall_s"]
    if n <= workers:
        raise ValueError(f"{n} episodes for {workers} workers leave no steady state; run more episodes")
    first_round = workers - 1  # the arrival by which every worker has run one episode
    startup = arrivals[first_round] - records[first_round]["episode_s"]
    steady = arrivals[-1] - arrivals[first_round]
    cost = sum(r["episode_s"] for r in records) / n
    per_episode_wall = workers * steady / (n - workers)  # one worker's wall time per episode
    where = {(r["ran_on"].get("host"), r["ran_on"].get("pid")) for r in records}
    return {
        "schedule": raw["schedule"], "workers": workers, "episodes": n, "wall_s": wall,
        "episodes_per_min": 60.0 * n / wall,
        "steady_episodes_per_min": 60.0 * (n - workers) / steady,
        "startup_s": startup, "finish_s": wall - arrivals[-1], "episode_cost_s": cost,
        "per_episode_wall_s": per_episode_wall,
        "per_episode_overhead_s": per_episode_wall - cost,
        "driver_cpu_s_per_episode": (cpu[-1] - cpu[first_round]) / (n - workers),
        "processes": len(where), "success_rate": raw["success_rate"],
        "load_average_before": raw["load_average_before"], "load_average_after": raw["load_average_after"],
    }


def shipping_cost(policy: str, repeats: int = 3) -> dict[str, Any] | None:
    """Packing and unpacking the policy's weights folder (what travels to each Ray node once per
    run); None for a policy without trained weights."""
    from wpbench import names

    if policy not in names.WEIGHTED_POLICIES:
        return None
    from wpbench.evaluation.ray_workers import pack_folder, unpack_folder
    from wpbench.weights import weights_root_or_shipped

    folder = weights_root_or_shipped(None)
    pack, unpack = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        digest, data = pack_folder(folder)
        pack.append(time.perf_counter() - t0)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            unpack_folder(digest, data, Path(tmp))
            unpack.append(time.perf_counter() - t0)
    return {"folder": str(folder), "bytes": len(data), "pack_s": min(pack), "unpack_s": min(unpack)}


def scaling_model(cost_s: float, overhead_s: float, startup_s: float, driver_s: float, ship_s: float = 0.0,
                  finish_s: float = 0.0, episodes: int = MODEL_EPISODES, cores: int = 1) -> dict[str, float]:
    """``T = S + ship + max(ceil(n / N) * (c + o), n * d) + F`` seconds for ``episodes`` on
    ``cores`` (one worker per core); also its core-hours and which term bounds it."""
    workers_term = math.ceil(episodes / cores) * (cost_s + overhead_s)
    driver_term = episodes * driver_s
    total = startup_s + ship_s + max(workers_term, driver_term) + finish_s
    return {"cores": cores, "episodes": episodes, "wall_s": total, "core_hours": total * cores / 3600.0,
            "bound": "workers" if workers_term >= driver_term else "driver"}


def _model_rows(measured: dict[str, dict[str, Any]], ship: dict[str, Any] | None) -> list[dict[str, Any]]:
    """The model for 1, 8 and 64 cores: 1 core from ``workers-1``; more from the loaded machine
    (``workers-2``'s per-episode cost), local workers' startup and overhead for 8 cores on one
    machine, Ray's for 64 cores on several machines (plus unpacking the weights on each)."""
    one, local, ray = measured["workers-1"], measured["workers-2"], measured["ray-2"]
    ship_s = (ship["pack_s"] + ship["unpack_s"]) if ship else 0.0
    rows = []
    for cores in MODEL_CORES:
        if cores == 1:
            source = one
            row = scaling_model(one["episode_cost_s"], max(one["per_episode_overhead_s"], 0.0), one["startup_s"],
                                0.0, finish_s=one["finish_s"], cores=1)
        else:
            source = local if cores <= 8 else ray
            row = scaling_model(local["episode_cost_s"], max(source["per_episode_overhead_s"], 0.0),
                                source["startup_s"], source["driver_cpu_s_per_episode"],
                                ship_s if source is ray else 0.0, finish_s=source["finish_s"], cores=cores)
        row["from"] = source["schedule"]
        rows.append(row)
    return rows


def run(episodes: int = 100, policy: str = "wp", task: str = "open-then-place", obs: str = "mesh",
        json_path: Path | None = None) -> dict[str, Any]:
    """Measure the three schedules, print the tables, write ``json_path``; the measurements."""
    from tabulate import tabulate

    if episodes < 4:
        raise ValueError("--episodes must be at least 4 (the steady state starts after each worker's first)")
    workers = {"workers-1": 1, "workers-2": 2, "ray-2": 2}
    measured = {s: derive(measure(s, policy, task, obs, episodes), workers[s]) for s in SCHEDULES}
    ship = shipping_cost(policy)
    one, local, ray = measured["workers-1"], measured["workers-2"], measured["ray-2"]
    speedup = local["episodes_per_min"] / one["episodes_per_min"]
    steady_speedup = local["steady_episodes_per_min"] / one["steady_episodes_per_min"]
    ray_overhead = ray["per_episode_wall_s"] / local["per_episode_wall_s"] - 1.0
    ray_overhead_total = ray["wall_s"] / local["wall_s"] - 1.0
    print(f"{policy} on {task}, obs {obs}, {episodes} episodes per schedule, {os.cpu_count()} cores, "
          f"load average before {one['load_average_before']}")
    print(tabulate(
        [[m["schedule"], m["workers"], f"{m['episodes_per_min']:.1f}", f"{m['steady_episodes_per_min']:.1f}",
          f"{m['startup_s']:.1f}", f"{m['finish_s']:.1f}", f"{m['episode_cost_s']:.2f}",
          f"{m['per_episode_overhead_s'] * 1000:.0f}",
          f"{m['driver_cpu_s_per_episode'] * 1000:.0f}", f"{m['success_rate']:.0%}", m["load_average_after"][0]]
         for m in measured.values()],
        headers=["schedule", "workers", "episodes/min", "after startup", "startup s", "finish s", "episode s",
                 "overhead ms/ep", "driver CPU ms/ep", "success", "load after"],
    ))
    print(f"\n2 workers vs 1: {speedup:.2f}x ({steady_speedup:.2f}x after startup; target >= {TARGET_SPEEDUP}x)")
    print(f"Ray vs local workers, per episode after startup: {ray_overhead:+.1%} (target <= "
          f"{TARGET_RAY_OVERHEAD:.0%}); whole run with startup: {ray_overhead_total:+.1%}")
    if ship:
        print(f"weights shipped to each Ray node: {ship['bytes'] / 2**20:.1f} MiB, pack {ship['pack_s']:.2f} s, "
              f"unpack {ship['unpack_s']:.2f} s")
    model = _model_rows(measured, ship)
    print(f"\nModel: {MODEL_EPISODES} episodes, T = S + ship + max(ceil(n/N) * (c + o), n * d) + F")
    print(tabulate([[r["cores"], r["from"], f"{r['wall_s'] / 60:.1f}", f"{r['core_hours']:.2f}", r["bound"]]
                    for r in model], headers=["cores", "measured on", "minutes", "core-hours", "bound by"]))
    result = {
        "policy": policy, "task": task, "obs": obs, "episodes_per_schedule": episodes,
        "cores": os.cpu_count(), "schedules": measured, "speedup_2_vs_1": speedup,
        "steady_speedup_2_vs_1": steady_speedup, "ray_overhead_per_episode": ray_overhead,
        "ray_overhead_whole_run": ray_overhead_total, "shipping": ship, "model": model,
        "targets": {"speedup_2_vs_1": TARGET_SPEEDUP, "ray_overhead_per_episode": TARGET_RAY_OVERHEAD},
        "load_average": {"before": one["load_average_before"], "after": ray["load_average_after"]},
        "measured_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    if json_path is not None:
        Path(json_path).write_text(json.dumps(result, indent=2) + "\n")
    return result
