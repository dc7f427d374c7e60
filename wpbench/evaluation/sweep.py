"""A sweep: every combination of policies, tasks, executors, asset sources and splits,
all their episodes scheduled at once on one pool, each run in its own resumable folder
(``<results>/runs/<run name>``), the leaderboard of ``results`` rebuilt at the end."""

from __future__ import annotations

from itertools import product
from pathlib import Path
from typing import Any, Sequence

from wpbench.evaluation.runner import RunConfig

__all__ = ["sweep_configs", "run_sweep"]


def sweep_configs(policies: Sequence[str], tasks: Sequence[str], episodes: int, results: Path | str = "results",
                  assets: Sequence[str] = ("procedural",), splits: Sequence[str] = ("val",),
                  executors: Sequence[str] = ("ideal",), obs: str = "camera", seed: int = 0) -> list[RunConfig]:
    """One resumable RunConfig per combination, in a stable order."""
    configs = []
    for policy, task, executor, source, split in product(policies, tasks, executors, assets, splits):
        cfg = RunConfig(policy=policy, task=task, split=split, episodes=episodes, seed=seed, assets=source, obs=obs,
                        resume=True, executor=executor)
        cfg.out = cfg.default_out(results)
        configs.append(cfg)
    return configs


def run_sweep(configs: Sequence[RunConfig], results: Path | str = "results", workers: int | None = 1,
              use_ray: bool = False, ray_address: str | None = None, progress: bool = True,
              leaderboard: bool = True) -> list[dict[str, Any]]:
    """Run every missing episode of ``configs`` on one pool (one progress bar); the summaries."""
    from wpbench.evaluation.driver import run_many
    from wpbench.evaluation.pools import make_pool

    pool = make_pool(workers=workers, use_ray=use_ray, ray_address=ray_address)
    summaries = run_many(list(configs), pool, progress=progress, description="sweep")
    if leaderboard:
        from wpbench.evaluation.leaderboard import write_leaderboard

        write_leaderboard(results)
    return summaries
