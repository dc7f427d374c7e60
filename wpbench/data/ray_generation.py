"""Training data shards drawn as Ray tasks (``wpbench data generate --ray ADDRESS``).

Each task draws one whole shard (``wpbench.data.generate.draw_shard``) on one CPU of the
cluster and returns its arrays; the driver writes the shard file and the manifest, so
the nodes need no shared file system. A node's worker process keeps its envs for the
next shard it is given, as a local worker process does.

A folder of one's own objects travels as an evaluation's does
(``wpbench.evaluation.ray_workers``): the folder and its collision cache, decomposed
once on the driver, go through Ray's object store and are unpacked once per node. The
shards keep the driver's fingerprint, so they are the same whichever node drew them.
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Any, Iterator, Sequence

import numpy as np

from wpbench.data.config import GenerationConfig

__all__ = ["draw_shards_on_ray", "draw_shard_task"]


def draw_shard_task(config: GenerationConfig, kind: str, shard: int, shipped: list) -> dict[str, np.ndarray]:
    """What a Ray task runs: shard ``shard`` of ``kind``, drawn with the asset folder that
    ``shipped`` brings (unpacked on this node), stamped with ``config``'s fingerprint."""
    from wpbench.data.generate import draw_shard_in_worker
    from wpbench.evaluation.ray_workers import receive_shipped

    local = receive_shipped(shipped)
    drawn_with = dataclasses.replace(config, assets=local["assets"]) if "assets" in local else config
    arrays = draw_shard_in_worker(drawn_with, kind, shard)
    arrays["fingerprint"] = np.asarray(config.sample_fingerprint())
    return arrays


def draw_shards_on_ray(config: GenerationConfig, todo: Sequence[tuple[str, int]], address: str | None = None,
                       num_cpus: int | None = None, progress: bool = False
                       ) -> Iterator[tuple[str, int, dict[str, np.ndarray]]]:
    """``(kind, shard, arrays)`` of every ``(kind, shard)`` in ``todo``, in the order they
    finish, each drawn by a task of one CPU on the Ray cluster at ``address`` ("auto": the
    running one; None: start a local one on 127.0.0.1 with ``num_cpus`` CPUs, shut down at
    the end). A task that fails stops the generation with its error."""
    from wpbench.evaluation.local_workers import POLL_S, WorkerError
    from wpbench.evaluation.ray_workers import connect, ray_available, ship_asset_folder

    if not todo:
        return
    if not ray_available():
        raise ValueError("--ray needs Ray: pip install 'ray==2.*' (scripts/setup.sh installs it)")
    started = connect(address, num_cpus)
    import ray
    from ray.exceptions import RayError, RayTaskError

    task = ray.remote(num_cpus=1, max_retries=1)(draw_shard_task)
    in_flight: dict[Any, tuple[str, int]] = {}
    try:
        shipped = ship_asset_folder(config.assets, {}, ray.put, progress=progress and sys.stderr.isatty())
        in_flight = {task.remote(config, kind, shard, shipped): (kind, shard) for kind, shard in todo}
        while in_flight:
            ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=POLL_S)
            for reference in ready:
                kind, shard = in_flight.pop(reference)
                try:
                    arrays = ray.get(reference)
                except RayTaskError as err:
                    raise WorkerError(f"shard {shard} of {kind}: {err.cause if err.cause is not None else err}") \
                        from None
                except RayError as err:
                    raise WorkerError(f"shard {shard} of {kind}: {type(err).__name__}: {err}") from None
                yield kind, shard, arrays
    finally:
        for reference in in_flight:
            try:
                ray.cancel(reference, force=True)
            except Exception:  # noqa: BLE001 - finished or gone meanwhile
                pass
        if started:
            ray.shutdown()
