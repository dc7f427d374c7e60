"""Run a policy on a task for N episodes and write the results (``wpbench run``).

Read top to bottom: make the env, make the policy, then for each episode
reset -> (observe -> predict -> step) per stage -> one record. :class:`EpisodeSession`
holds one run's env and policy and turns every episode into a record, a failed one
too; :func:`run_benchmark` hands the episodes to a pool (this process, worker
processes or Ray) through :mod:`wpbench.evaluation.driver`, which alone writes
``episodes.jsonl`` and, at the end, ``summary.json``.

An episode is a function of its seed alone (whatever the env ran before it), so any
worker may run any episode and the records do not depend on the schedule; only
``timings`` and ``ran_on`` (host and process) do.

Episode records carry the public keys of ``wpbench.evaluation.records`` plus
``stages`` (one dict per stage with its own metrics and the executor's report).
For a two-stage episode the top-level errors are the mean over its stages and
``articulated_*`` / ``free_*`` keys hold each stage's own numbers.
"""

from __future__ import annotations

import json
import os
import resource
import socket
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
    executor: str = "ideal"
    shard: str | None = None  # "i/N": only the episodes whose index is i modulo N
    camera_noise: dict = field(default_factory=dict)  # wpbench.sim.camera_noise.CameraNoise fields; {}: clean

    def default_out(self, results: Path | str = "results") -> Path:
        """``<results>/runs/<policy>__<task>__<split>__<assets>__<obs>`` (the obs with the camera
        noise's tag, e.g. ``camera-depth0.002``, for a noisy camera; plus ``__<executor>`` for
        another executor than the ideal one, ``__shard<i>of<N>`` for a shard)."""
        from wpbench.sim.camera_noise import CameraNoise

        source = "procedural" if self.assets == "procedural" else Path(self.assets).name
        noise = CameraNoise.from_settings(self.camera_noise).tag()
        name = f"{self.policy}__{self.task}__{self.split}__{source}__{self.obs}" + (f"-{noise}" if noise else "")
        if self.executor != "ideal":
            name += f"__{self.executor}"
        if self.shard is not None:
            index, count = parse_shard(self.shard)
            name += f"__shard{index}of{count}"
        return Path(results) / "runs" / name

    def episode_indices(self) -> list[int]:
        """The episodes of this run (of its shard, if it is one), in order."""
        if self.shard is None:
            return list(range(self.episodes))
        index, count = parse_shard(self.shard)
        return [i for i in range(self.episodes) if i % count == index]


def parse_shard(text: str) -> tuple[int, int]:
    """``"i/N"`` -> ``(i, N)`` with 0 <= i < N; ValueError saying the form otherwise."""
    try:
        index, count = (int(part) for part in str(text).split("/"))
    except ValueError:
        raise ValueError(f"--shard must look like i/N (e.g. 0/4), got {text!r}") from None
    if count < 1 or not 0 <= index < count:
        raise ValueError(f"--shard i/N needs 0 <= i < N, got {text!r}")
    return index, count


def episode_seed(base_seed: int, episode: int) -> int:
    """Distinct, reproducible seeds for (run seed, episode index)."""
    return int((base_seed * 1_000_003 + episode) % (2**31 - 1))


def make_env(cfg: RunConfig):
    """The task's gymnasium env for this run (ManiSkill3 BaseEnv on the CPU)."""
    import gymnasium as gym

    from wpbench.names import import_task

    info = import_task(cfg.task)  # registers the task's env with gymnasium
    from wpbench.assets.library import run_split

    # A folder of real objects without a split file: every object is unseen furniture.
    split = run_split(cfg.assets, cfg.split)
    # The ideal executor is the env's own default: naming it keeps envs that take no
    # executor argument working.
    # So do a clean camera's settings (envs of plugins may not know camera noise).
    executor = {} if cfg.executor == "ideal" else {"executor": cfg.executor}
    noise = {"camera_noise": dict(cfg.camera_noise)} if cfg.camera_noise else {}
    return gym.make(
        info.env_id,
        obs_mode=cfg.obs,
        assets=cfg.assets,
        split=split,
        num_action_points=cfg.num_action_points,
        num_anchor_points=cfg.num_anchor_points,
        **executor,
        **noise,
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


class PolicyAnswerError(ValueError):
    """A policy's answer cannot be carried out: it is that stage's failure."""


# A cross-pose moves an object within a tabletop scene; a translation beyond this is no pose.
MAX_TRANSLATION_M = 1e3


def checked_answer(out: Any) -> tuple[np.ndarray, dict[str, Any]]:
    """``(transform (4, 4) float64, diagnostics)`` of a policy's answer, or
    :class:`PolicyAnswerError` saying what is wrong with it."""
    if out is None:
        raise PolicyAnswerError("policy returned None instead of a PolicyOutput")
    transform = getattr(out, "transform", None)
    if transform is None:
        raise PolicyAnswerError(f"policy returned {type(out).__name__}, not a PolicyOutput with a transform")
    try:
        transform = np.asarray(transform, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise PolicyAnswerError(f"policy transform is not a numeric array ({err})") from None
    if transform.shape != (4, 4):
        raise PolicyAnswerError(f"policy transform has shape {transform.shape}, expected (4, 4)")
    if not np.all(np.isfinite(transform)):
        raise PolicyAnswerError("policy transform has non-finite entries")
    distance = float(np.linalg.norm(transform[:3, 3]))
    if distance > MAX_TRANSLATION_M:
        raise PolicyAnswerError(f"policy translation of {distance:.3g} m is beyond {MAX_TRANSLATION_M:g} m")
    diagnostics = getattr(out, "diagnostics", None)
    return transform, diagnostics if isinstance(diagnostics, dict) else {}


def _describe_error(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0]}" if text else type(err).__name__


def run_episode(env, policy, seed: int, observer=None) -> dict[str, Any]:
    """One episode: every stage observed, predicted and executed. Returns the raw record.

    A policy that raises, or answers something that is not a usable (4, 4) cross-pose,
    fails that stage (``failure_reason`` says why; the simulator is given a NaN pose,
    which it refuses to execute); errors of the simulator itself propagate.
    """
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
            transform, diagnostics = checked_answer(policy.predict(np_obs, info))
            error = ""
        except Exception as err:  # noqa: BLE001 - any policy failure fails the stage, the run goes on
            error = f"policy error: {_describe_error(err)}"
            transform, diagnostics = np.full((4, 4), np.nan), {}
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
        "furniture_pool": base.furniture_pool,
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


def run_fields(cfg: RunConfig, index: int) -> dict[str, Any]:
    """The keys every record of run ``cfg`` carries for its episode ``index``."""
    return {"episode": index, "task": cfg.task, "policy": cfg.policy, "split": cfg.split, "obs": cfg.obs}


def failure_record(cfg: RunConfig, index: int, reason: str, asset: Any = None) -> dict[str, Any]:
    """The record of an episode that could not be run to its end: a failure with NaN errors
    and ``failure_reason``; ``asset`` (the episode's furniture, if it was drawn) names the object."""
    record = {
        "seed": episode_seed(cfg.seed, index),
        "object_id": getattr(asset, "object_id", None),
        "category": getattr(asset, "category", None),
        "asset_source": getattr(asset, "source", None),
        "success": False, "success_at_end": False, "success_once": False,
        "stages": [], "failure_reason": reason,
    }
    record.update({key: float("nan") for key in ERROR_FIELDS})
    record.update(run_fields(cfg, index))
    return record


def where_am_i() -> dict[str, Any]:
    """Where an episode ran (not scored; differs between schedules like the timings do)."""
    return {"host": socket.gethostname(), "pid": os.getpid()}


class EpisodeSession:
    """The env and the policy of one run, built once, running its episodes by index.

    ``run(index)`` always returns a complete record: an error of the simulator during
    the episode becomes that episode's failure (with its reason) and the env is built
    anew for the next one.
    """

    def __init__(self, cfg: RunConfig, policy=None, observer=None) -> None:
        from wpbench.policies.registry import make_policy

        self.cfg = cfg
        self.policy = policy or make_policy(cfg.policy, **cfg.policy_kwargs)
        self.observer = observer
        self.env = make_env(cfg)

    def run(self, index: int) -> dict[str, Any]:
        if self.env is None:
            self.env = make_env(self.cfg)
        seed = episode_seed(self.cfg.seed, index)
        before = getattr(self.env.unwrapped, "asset", None)
        try:
            record = run_episode(self.env, self.policy, seed, observer=self.observer)
        except Exception as err:  # noqa: BLE001 - the simulator failed this episode, not the run
            asset = getattr(self.env.unwrapped, "asset", None)
            asset = None if asset is before else asset  # the failure came before this episode's draw
            record = failure_record(self.cfg, index, f"simulator error: {_describe_error(err)}", asset)
            self.close()
        record.update(run_fields(self.cfg, index))
        record["ran_on"] = where_am_i()
        return record

    def close(self) -> None:
        if self.env is not None:
            try:
                self.env.close()
            finally:
                self.env = None


def produced_by(cfg: RunConfig, policy) -> dict[str, Any]:
    """What decides an episode beside the run's settings: the trained weights the policy
    loaded (their ``model_hash``es, none for ``gt`` / ``identity``), the version of the
    furniture generator (built-in assets only) and the executor's version for the task
    (wpbench.evaluation.executor_version). ``run.json`` stores these, so ``--resume`` refuses
    to append episodes of retrained weights, rebuilt furniture or a changed executor to an old run.
    For a PartNet-Mobility folder, the content hash of the folder (``assets_digest``)
    plays the part of the generator version."""
    hashes: set[str] = set()

    def collect(value: Any) -> None:
        if isinstance(value, dict):
            if value.get("model_hash"):
                hashes.add(str(value["model_hash"]))
            for item in value.values():
                collect(item)

    collect(policy.describe())
    generator, digest = None, None
    if cfg.assets == "procedural":
        from wpbench.assets.procedural.generate import GENERATOR_VERSION

        generator = GENERATOR_VERSION
    else:
        from wpbench.evaluation.asset_digest import folder_digest

        digest = folder_digest(cfg.assets)
    from wpbench.evaluation.executor_version import executor_version

    return {"policy_weights": sorted(hashes), "furniture_generator": generator, "assets_digest": digest,
            "executor_version": executor_version(cfg.executor, cfg.task)}


def run_benchmark(
    cfg: RunConfig,
    progress: bool = True,
    policy=None,
    observer=None,
    on_episode: Callable[[dict], None] | None = None,
    workers: int | None = 1,
    ray_address: str | None = None,
    use_ray: bool = False,
) -> dict[str, Any]:
    """Run ``cfg`` and return its summary (also written to ``out/summary.json``).

    ``workers``: 1 runs the episodes in this process (``policy`` and ``observer`` objects
    are only usable then); more runs them in that many worker processes. ``use_ray``: run
    them on a Ray cluster instead (``ray_address`` ``"auto"`` for an existing one, None
    for a local one; ``workers`` None: one actor per CPU of the cluster). The records are
    the same whichever runs them.
    """
    from wpbench.evaluation.driver import run_many
    from wpbench.evaluation.pools import make_pool

    if (policy is not None or observer is not None) and (workers not in (None, 1) or use_ray):
        raise ValueError("a policy object or an observer (--record) needs the episodes in this process: --workers 1")
    pool = make_pool(workers=workers, use_ray=use_ray, ray_address=ray_address, policy=policy, observer=observer)
    return run_many([cfg], pool, policies={0: policy} if policy is not None else None, progress=progress,
                    on_episode=on_episode)[0]
