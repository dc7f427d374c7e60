"""Run a policy on a task for N episodes and write the results (``wpbench run``).

Read top to bottom: make the env, make the policy, then for each episode
reset -> (observe -> predict -> step) per stage -> one record appended to
``episodes.jsonl``; at the end ``summary.json`` and a table.

Episode records carry the public keys of ``wpbench.evaluation.records`` plus
``stages`` (one dict per stage with its own metrics and the executor's report).
For a two-stage episode the top-level errors are the mean over its stages and
``articulated_*`` / ``free_*`` keys hold each stage's own numbers.
"""

from __future__ import annotations

import json
import resource
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

OBSERVATION_KEYS = ("action_points", "anchor_points")
ERROR_FIELDS = ("rot_err_deg", "trans_err_m", "trans_err_raw_m", "point_err_m", "point_mse")
KIND_PREFIX = {"articulated": "articulated", "free-floating": "free"}


@dataclass
class RunConfig:
    policy: str
    task: str = "open-then-place"
    split: str = "val"
    episodes: int = 50
    seed: int = 0
    assets: str = "procedural"
    obs: str = "camera"
    out: Path | None = None
    resume: bool = False
    record: Path | None = None
    num_action_points: int = 256
    num_anchor_points: int = 1024
    policy_kwargs: dict = field(default_factory=dict)

    def default_out(self) -> Path:
        source = "procedural" if self.assets == "procedural" else Path(self.assets).name
        return Path("results") / "runs" / f"{self.policy}__{self.task}__{self.split}__{source}__{self.obs}"


def episode_seed(base_seed: int, episode: int) -> int:
    """Distinct, reproducible seeds for (run seed, episode index)."""
    return int((base_seed * 1_000_003 + episode) % (2**31 - 1))


def make_env(cfg: RunConfig):
    """The task's gymnasium env for this run (ManiSkill3 BaseEnv on the CPU)."""
    import gymnasium as gym

    from wpbench.names import import_task

    info = import_task(cfg.task)  # registers the task's env with gymnasium
    # Real PartNet-Mobility folders have no split: every object is unseen furniture.
    split = None if cfg.assets != "procedural" or cfg.split in ("all", None) else cfg.split
    return gym.make(
        info.env_id,
        obs_mode=cfg.obs,
        assets=cfg.assets,
        split=split,
        num_action_points=cfg.num_action_points,
        num_anchor_points=cfg.num_anchor_points,
    )


def policy_inputs(policy, obs: dict, ground_truth) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """What ``policy.predict`` is given: (observation, info).

    Every policy gets the segmented clouds of the batched torch observation ``obs`` as
    unbatched numpy arrays, ``{"action_points": (NA, 3), "anchor_points": (NB, 3)}``, and
    nothing else. Only a privileged policy (``uses_ground_truth``) also gets ``info``, the
    env's ``ground_truth()``; ``ground_truth`` is that method, called only for them.
    """
    observation = {key: obs[key][0].cpu().numpy() for key in OBSERVATION_KEYS}
    return observation, (ground_truth() if policy.uses_ground_truth else None)


def run_episode(env, policy, seed: int, observer=None) -> dict[str, Any]:
    """One episode: every stage observed, predicted and executed. Returns the raw record."""
    base = env.unwrapped
    t0 = time.perf_counter()
    obs, info = env.reset(seed=seed)
    t_reset = time.perf_counter() - t0
    stages, t_policy = [], 0.0
    if observer is not None:
        observer.begin_episode(base, seed)
    for _ in range(len(base.STAGES)):
        np_obs, info = policy_inputs(policy, obs, base.ground_truth)
        t1 = time.perf_counter()
        try:
            out = policy.predict(np_obs, info)
            transform, diagnostics, error = out.transform, out.diagnostics, ""
        except ValueError as err:  # a policy that cannot answer fails the stage, the run goes on
            transform, diagnostics, error = np.full((4, 4), np.nan), {}, f"policy error: {err}"
        t_policy += time.perf_counter() - t1
        if observer is not None:
            observer.log_prediction(base, np_obs, transform, diagnostics)
        t2 = time.perf_counter()
        obs, _, terminated, _, info = env.step(transform)
        result = dict(info["stage_result"])
        result["exec_seconds"] = time.perf_counter() - t2
        if error:
            result["failure_reason"] = error
        if "w" in diagnostics:
            result["w"] = float(np.mean(np.asarray(diagnostics["w"])))
        stages.append(result)
        if observer is not None:
            observer.log_stage_result(base, result)
    record = {
        "seed": seed,
        "object_id": base.asset.object_id,
        "category": base.asset.category,
        "asset_source": base.asset.source,
        "success": bool(info["success"][0]),
        "stages": stages,
        "timings": {"reset_s": t_reset, "policy_s": t_policy, "episode_s": time.perf_counter() - t0,
                    "sim_s": sum(s["exec_seconds"] for s in stages)},
    }
    for key in ERROR_FIELDS:
        values = [s[key] for s in stages]
        record[key] = float(np.mean(values)) if values else float("nan")
        for s in stages:
            record[f"{KIND_PREFIX[s['kind']]}_{key}"] = s[key]
    for s in stages:
        record[f"{KIND_PREFIX[s['kind']]}_success"] = s["success"]
    # success_at_end: judged on the final state; success_once: every stage's condition held
    # at some moment of its simulation (ManiSkill3's definitions, per stage).
    record["success_at_end"] = record["success"]
    record["success_once"] = all(s["success_once"] for s in stages)
    if base.free_spec is not None:
        record["object"] = base.free_spec.name
    if observer is not None:
        observer.end_episode(base, record)
    return record


def produced_by(cfg: RunConfig, policy) -> dict[str, Any]:
    """What decides an episode beside the run's settings: the trained weights the policy
    loaded (their ``model_hash``es, none for ``gt`` / ``identity``) and the version of the
    furniture generator (built-in assets only). ``run.json`` stores these, so ``--resume``
    refuses to append episodes of retrained weights or rebuilt furniture to an old run."""
    hashes: set[str] = set()

    def collect(value: Any) -> None:
        if isinstance(value, dict):
            if value.get("model_hash"):
                hashes.add(str(value["model_hash"]))
            for item in value.values():
                collect(item)

    collect(policy.describe())
    generator = None
    if cfg.assets == "procedural":
        from wpbench.assets.procedural.generate import GENERATOR_VERSION

        generator = GENERATOR_VERSION
    return {"policy_weights": sorted(hashes), "furniture_generator": generator}


def run_benchmark(
    cfg: RunConfig,
    progress: bool = True,
    policy=None,
    observer=None,
    on_episode: Callable[[dict], None] | None = None,
) -> dict[str, Any]:
    """Run ``cfg`` and return its summary (also written to ``out/summary.json``)."""
    from tqdm import tqdm

    from wpbench.policies.registry import make_policy
    from wpbench.evaluation.records import EpisodeWriter
    from wpbench.evaluation.summary import summarize, write_summary

    out = Path(cfg.out) if cfg.out is not None else cfg.default_out()
    policy = policy or make_policy(cfg.policy, **cfg.policy_kwargs)
    run_config = {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()}
    run_config["out"] = str(out)
    run_config.update(produced_by(cfg, policy))
    started = time.perf_counter()
    with EpisodeWriter(out, run_config, resume=cfg.resume) as writer:
        done = writer.completed_episodes()
        todo = [i for i in range(cfg.episodes) if i not in done]
        env = make_env(cfg) if todo else None
        successes = sum(bool(r.get("success")) for r in writer.records)
        bar = tqdm(total=cfg.episodes, initial=len(done), disable=not progress, desc=f"{cfg.policy} {cfg.task}",
                   unit="ep", dynamic_ncols=True)
        for i in todo:
            record = run_episode(env, policy, episode_seed(cfg.seed, i), observer=observer)
            record.update(episode=i, task=cfg.task, policy=cfg.policy, split=cfg.split, obs=cfg.obs)
            writer.write(record)
            successes += record["success"]
            finished = len(writer.completed_episodes())
            bar.update(1)
            bar.set_postfix(success=f"{successes / finished:.0%}")
            if on_episode is not None:
                on_episode(record)
        bar.close()
        if env is not None:
            env.close()
        records = list(writer.records)
    meta = {
        "policy": cfg.policy, "task": cfg.task, "split": cfg.split, "asset_source": cfg.assets,
        "obs": cfg.obs, "seed": cfg.seed,
        # Episode times come from the records, so a resumed run reports the whole run;
        # peak memory is this process's (a resumed run's is the last session's).
        "timings": {"wall_s": float(sum(r.get("timings", {}).get("episode_s", 0.0) for r in records)),
                    "session_wall_s": time.perf_counter() - started,
                    "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024},
        "policy_info": policy.describe(),
    }
    previous = out / "summary.json"
    if previous.is_file():  # a resumed run: memory peaked in whichever session was largest
        try:
            before = json.loads(previous.read_text())["timings"]["run"]["peak_rss_mib"]
            meta["timings"]["peak_rss_mib"] = max(meta["timings"]["peak_rss_mib"], float(before))
        except (KeyError, TypeError, ValueError):
            pass
    summary = summarize(records, meta)
    write_summary(out, summary)
    summary["_out_dir"] = str(out)
    return summary
