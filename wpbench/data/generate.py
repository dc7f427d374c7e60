"""Sample (action cloud, anchor cloud, cross-pose) triples from the wpbench tasks.

One env per kind (``OpenDoor-v0`` for articulated, ``PlaceIn-v0`` for
free-floating), on the split's furniture only. Samples are numbered per kind;
sample ``g`` uses an episode seed derived from (config seed, split, kind, g),
and every ``scene_reuse``-th sample reloads the scene (``reconfigure``) so
that a shard never depends on what was generated before it: shards are
reproducible and a run can be resumed by skipping the shards already on disk.

Why reuse scenes: a reset that loads a furniture URDF (and, with cameras, its
render bodies) is the slow part; a reset without reconfiguration only moves the
furniture, sets a new start state and a new camera viewpoint.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from wpbench.data.config import ARTICULATED, FREE, KIND_CODE, KIND_TASK, SPLITS, GenerationConfig
from wpbench.data.manifest import build_manifest, split_dir, write_manifest
from wpbench.data.shards import shard_path, stack_samples, write_shard
from wpbench.data.equivalent_goals import equivalent_goals


@dataclass
class GenerationReport:
    """What one ``generate`` call did."""

    directory: Path
    written_shards: int
    skipped_shards: int
    new_samples: int
    seconds: float
    manifest: dict

    @property
    def samples_per_second(self) -> float:
        return self.new_samples / self.seconds if self.seconds > 0 else float("nan")


def sample_seed(config: GenerationConfig, kind: str, index: int) -> int:
    """Episode seed of sample ``index`` of ``kind``: distinct across seeds, splits and kinds."""
    entropy = [int(config.seed), SPLITS.index(config.split), KIND_CODE[kind], int(index)]
    return int(np.random.SeedSequence(entropy).generate_state(1, dtype=np.uint32)[0] & 0x7FFFFFFF)


def make_env(config: GenerationConfig, kind: str):
    """The task env for ``kind``; scenes are reloaded only when we ask (reconfiguration_freq=0)."""
    import gymnasium as gym

    from wpbench.names import import_task

    env_id = import_task(KIND_TASK[kind]).env_id  # registers the task's env
    kwargs = dict(
        obs_mode=config.obs, assets=config.assets, split=config.split,
        num_action_points=config.num_action_points, num_anchor_points=config.num_anchor_points,
        reconfiguration_freq=0,
    )
    if kind == FREE:
        kwargs["objects"] = tuple(config.objects)
    if config.camera_noise:
        kwargs["camera_noise"] = dict(config.camera_noise)
    if config.extra_train_instances and config.split == "train":
        kwargs["extra_train_instances"] = config.extra_train_instances
    return gym.make(env_id, **kwargs)


def symmetric_min_rotation(T: np.ndarray, object_pose: np.ndarray, discrete: np.ndarray) -> np.ndarray:
    """Among the equivalent goals of a symmetric object (``equivalent_goals``), the one that rotates least.

    Picking the smallest rotation makes the stored target a function of what the model
    sees (it cannot tell the symmetric poses apart). T, object_pose (4, 4); discrete (K, 3, 3) -> (4, 4).
    """
    candidates = equivalent_goals(T, object_pose, discrete)
    cosines = (np.trace(candidates[:, :3, :3], axis1=1, axis2=2) - 1) / 2
    angles = np.arccos(np.clip(cosines, -1.0, 1.0))
    # The first of the (numerically) smallest, so ties resolve the same way on every machine.
    return candidates[int(np.flatnonzero(angles <= angles.min() + 1e-9)[0])]


def draw_sample(env, config: GenerationConfig, kind: str, index: int) -> dict:
    """Reset ``env`` for sample ``index`` and read one sample dict (keys of ``shards.ARRAY_KEYS``)."""
    from wpbench.sim.poses import pose_to_matrix

    seed = sample_seed(config, kind, index)
    base = env.unwrapped
    reconfigure = index % config.scene_reuse == 0
    options = {"reconfigure": reconfigure, "restart_rng": reconfigure}
    if kind == ARTICULATED:
        rng = np.random.default_rng([seed, 17])
        if rng.random() < config.wide_start_probability:
            options["start_fraction"] = float(rng.uniform(*config.wide_start_fraction))
    obs, _ = env.reset(seed=seed, options=options)
    start_fraction = float("nan")
    if kind == ARTICULATED:
        a = base.asset
        start_fraction = (base.furniture.qpos - a.closed_qpos) / (a.open_qpos - a.closed_qpos)
    T_raw = np.asarray(base.ground_truth()["cross_pose"], dtype=np.float64)
    T = T_raw
    free_object = ""
    if kind == FREE:
        free_object = base.free_spec.name
        action_pose = pose_to_matrix(base.free_body.entity_pose)
        symmetry = getattr(base.free_spec, "symmetry", None)
        if symmetry is not None and getattr(symmetry, "discrete", None) is not None:
            discrete = np.asarray(symmetry.discrete, dtype=np.float64).reshape(-1, 3, 3)
            T = symmetric_min_rotation(T_raw, action_pose, discrete)
    else:
        action_pose = base.furniture.target_link_pose()
    return {
        "action_points": obs["action_points"][0].cpu().numpy(),
        "anchor_points": obs["anchor_points"][0].cpu().numpy(),
        "gt_transform": T,
        "gt_transform_raw": T_raw,
        "action_pose": action_pose,
        "kind": KIND_CODE[kind],
        "category": base.asset.category,
        "object_id": base.asset.object_id,
        "free_object": free_object,
        "seed": seed,
        "start_fraction": start_fraction,
        "camera_fallback": base.observation_fallback,
    }


def own_objects_config(config: GenerationConfig) -> GenerationConfig:
    """``config`` with a folder of one's own objects as an absolute path, after checking that
    the folder has a split (so a train split never takes held-out objects)."""
    if config.assets == "procedural":
        return config
    from dataclasses import replace

    from wpbench.assets.object_split import find_split_file

    folder = Path(config.assets).expanduser()
    if not folder.is_dir():
        raise ValueError(f"--assets {config.assets!r} is neither 'procedural' nor an existing folder")
    if not (folder / "split.json").is_file() and find_split_file(folder) is None:
        raise ValueError(f"{folder} has no split file, so its test objects cannot be kept out of training data; "
                         f"run `wpbench assets split {folder}` first")
    return replace(config, assets=str(folder.resolve()))


_WORKER_ENVS: dict[tuple[str, str], object] = {}   # (config fingerprint, kind) -> env, in each worker process


def draw_shard(config: GenerationConfig, kind: str, shard: int, envs: dict,
               on_sample: Callable[[str, int], None] | None = None) -> dict[str, np.ndarray]:
    """The arrays of shard ``shard`` of ``kind`` (``shards.stack_samples``), drawn with the
    env in ``envs`` for this config and kind (made and kept there when missing)."""
    key = (config.sample_fingerprint(), kind)
    if key not in envs:
        envs[key] = make_env(config, kind)
    samples = []
    for i in range(shard * config.shard_size, (shard + 1) * config.shard_size):
        samples.append(draw_sample(envs[key], config, kind, i))
        if on_sample is not None:
            on_sample(kind, i)
    return stack_samples(samples, config.sample_fingerprint())


def draw_shard_in_worker(config: GenerationConfig, kind: str, shard: int) -> dict[str, np.ndarray]:
    """:func:`draw_shard` in a worker process: torch on one thread, the envs kept for the next shard."""
    import torch

    torch.set_num_threads(1)
    return draw_shard(config, kind, shard, _WORKER_ENVS)


def generate(
    root: Path,
    config: GenerationConfig,
    progress: bool = True,
    on_sample: Callable[[str, int], None] | None = None,
    workers: int = 1,
    use_ray: bool = False,
    ray_address: str | None = None,
    ray_cpus: int | None = None,
    on_shard: Callable[[str, int], None] | None = None,
) -> GenerationReport:
    """Write the shards of ``config`` under ``root/<split>/`` that do not exist yet, then the manifest.

    ``workers`` > 1 draws whole shards in that many processes; ``use_ray`` draws them as
    tasks on the Ray cluster at ``ray_address`` (``wpbench.data.ray_generation``; None: a
    local cluster with ``ray_cpus`` CPUs). Either way this process writes every shard and
    keeps the manifest current as they land (``on_shard(kind, shard)`` is called after each).
    A shard starts with a fresh scene and depends only on its index, so the shards are the
    same however they are drawn.
    """
    from tqdm import tqdm

    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if use_ray and workers != 1:
        raise ValueError("draw shards either in local worker processes or on Ray, not both")
    config = own_objects_config(config)
    directory = split_dir(root, config.split)
    todo = [(kind, i) for kind in config.kinds for i in range(config.shards_per_kind())
            if not shard_path(directory, kind, i).is_file()]
    total_shards = len(config.kinds) * config.shards_per_kind()
    skipped = total_shards - len(todo)
    new_samples, started = 0, time.perf_counter()
    bar = tqdm(total=len(todo) * config.shard_size, disable=not progress, unit="sample", dynamic_ncols=True,
               desc=f"{config.split} ({skipped} shards already done)")

    def shard_written(count: int) -> None:
        nonlocal new_samples
        new_samples += count
        elapsed = time.perf_counter() - started
        # Keep the manifest current so training can start on the shards written so far.
        write_manifest(directory, build_manifest(directory, config, {"in_progress": True}))
        bar.set_postfix(samples_per_s=f"{new_samples / max(elapsed, 1e-9):.2f}")

    def shard_drawn(kind: str, shard: int, arrays: dict[str, np.ndarray]) -> None:
        write_shard(shard_path(directory, kind, shard), arrays)
        shard_written(len(arrays["seed"]))
        if on_shard is not None:
            on_shard(kind, shard)

    envs: dict = {}
    try:
        if use_ray:
            from wpbench.data.ray_generation import draw_shards_on_ray

            for kind, shard, arrays in draw_shards_on_ray(config, todo, ray_address, ray_cpus, progress=progress):
                bar.update(len(arrays["seed"]))
                shard_drawn(kind, shard, arrays)
        elif workers == 1 or len(todo) <= 1:
            def counted(kind: str, index: int) -> None:
                bar.update(1)
                if on_sample is not None:
                    on_sample(kind, index)

            for kind, shard in todo:
                shard_drawn(kind, shard, draw_shard(config, kind, shard, envs, counted))
        else:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor, as_completed

            from wpbench.assets.prepare import prepare_asset_sources

            prepare_asset_sources([config.assets], progress=progress)   # once here, not in every worker
            context = multiprocessing.get_context("spawn")   # SAPIEN and torch do not survive fork
            with ProcessPoolExecutor(min(workers, len(todo)), mp_context=context) as pool:
                futures = {pool.submit(draw_shard_in_worker, config, kind, shard): (kind, shard) for kind, shard in todo}
                for future in as_completed(futures):
                    arrays = future.result()
                    bar.update(len(arrays["seed"]))
                    shard_drawn(*futures[future], arrays)
    finally:
        bar.close()
        for env in envs.values():
            env.close()
    seconds = time.perf_counter() - started
    generation = {"last_run_new_samples": new_samples, "last_run_seconds": round(seconds, 2),
                  "last_run_samples_per_second": round(new_samples / seconds, 3) if new_samples else None}
    manifest = build_manifest(directory, config, generation)
    write_manifest(directory, manifest)
    return GenerationReport(directory, len(todo), skipped, new_samples, seconds, manifest)
