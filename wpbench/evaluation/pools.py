"""Which pool runs a run's episodes: this process, local worker processes, or Ray."""

from __future__ import annotations

from typing import Any

__all__ = ["make_pool"]


def make_pool(workers: int | None = 1, use_ray: bool = False, ray_address: str | None = None,
              policy: Any = None, observer: Any = None):
    """``use_ray``: a :class:`~wpbench.evaluation.ray_workers.RayPool` on ``ray_address``
    (None: a local cluster) with ``workers`` actors (None: one per CPU of the cluster);
    else ``workers`` 1 (or None): this process (where ``policy`` and ``observer`` objects
    can be used); else a :class:`~wpbench.evaluation.local_workers.LocalWorkerPool`."""
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be at least 1, got {workers}")
    if use_ray:
        from wpbench.evaluation.ray_workers import RayPool

        return RayPool(address=ray_address, workers=workers)
    if workers in (None, 1):
        from wpbench.evaluation.driver import InProcessPool

        return InProcessPool(policies={0: policy} if policy is not None else None, observer=observer)
    from wpbench.evaluation.local_workers import LocalWorkerPool

    return LocalWorkerPool(workers)
