"""Episodes in N worker processes on this machine (``wpbench run --workers N``).

Each worker is a fresh (spawned) Python process that builds a run's env and policy
once and then runs whichever of its episodes it is handed, one at a time, sending
back the record; the driver writes it. One job at a time per worker means a worker
that dies takes exactly one episode with it: that episode is handed out again once,
and recorded as a failure (with the reason) if it kills a worker a second time.

Workers ignore Ctrl-C (the terminal sends it to the whole process group): the driver
decides. After the first Ctrl-C no new episode is handed out, the ones in progress
are finished and kept, and the workers are stopped.

Torch runs ``threads_per_worker(N)`` threads in each worker, so N workers keep the
cores busy without oversubscribing them.

Before the first worker starts, the driver decomposes what the collision cache lacks of
every PartNet-Mobility folder the runs use (``wpbench.assets.prepare.prepare_asset_sources``,
all links at once on every core), so the workers find each object's pieces ready
instead of decomposing the same object side by side.
"""

from __future__ import annotations

import os
import signal
from collections import deque
from dataclasses import dataclass
from typing import Any, Iterator, Sequence

__all__ = ["available_cores", "threads_per_worker", "LocalWorkerPool", "WorkerError", "RETRIES"]

# How many times an episode whose worker died is handed out again before it is a failure.
RETRIES = 1
# Seconds between checks of the stop flag while waiting for workers.
POLL_S = 0.5
# Seconds a worker gets to exit after being asked to, before it is killed.
SHUTDOWN_S = 10.0
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


class WorkerError(RuntimeError):
    """A worker could not run a run's episodes at all (e.g. its env cannot be built)."""


def available_cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def threads_per_worker(workers: int, cores: int | None = None) -> int:
    """Torch threads per worker so that ``workers`` of them fill ``cores`` and no more."""
    return max(1, (cores or available_cores()) // max(1, workers))


def set_thread_count(threads: int) -> None:
    """Limit torch and the BLAS / OpenMP pools of this process to ``threads``."""
    for variable in THREAD_VARIABLES:
        os.environ[variable] = str(threads)
    import torch

    torch.set_num_threads(threads)


def worker_main(connection, threads: int, session_factory=None) -> None:
    """A worker process: receive ``(job_id, run, cfg, index)``, send back ``("done", job_id,
    record)``; ``None`` or a closed pipe ends it. An error that is not one episode's
    (building the env or the policy) is sent as ``("fatal", job_id, message)``.
    ``session_factory(cfg)`` builds what runs a run's episodes (default ``EpisodeSession``)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    set_thread_count(threads)
    if session_factory is None:
        from wpbench.evaluation.runner import EpisodeSession as session_factory

    session, current = None, None
    try:
        while True:
            try:
                message = connection.recv()
            except EOFError:
                break
            if message is None:
                break
            job_id, run, cfg, index = message
            try:
                if current != run:
                    if session is not None:
                        session.close()
                    session, current = None, None
                    session, current = session_factory(cfg), run
                connection.send(("done", job_id, session.run(index)))
            except Exception as err:  # noqa: BLE001 - reported to the driver, which stops the run
                connection.send(("fatal", job_id, f"{type(err).__name__}: {err}"))
    finally:
        if session is not None:
            session.close()


@dataclass
class _Worker:
    process: Any
    connection: Any
    job: int | None = None  # the job id it is running


def death_reason(exitcode: int | None) -> str:
    how = f"killed by signal {-exitcode}" if exitcode is not None and exitcode < 0 else f"exit code {exitcode}"
    return f"worker process died ({how}) while running this episode, {RETRIES + 1} times"


class LocalWorkerPool:
    """``workers`` spawned processes; see the module docstring."""

    def __init__(self, workers: int, threads: int | None = None, session_factory=None) -> None:
        if workers < 1:
            raise ValueError(f"need at least one worker, got {workers}")
        self.workers = workers
        self.session_factory = session_factory
        self.threads = threads or threads_per_worker(workers)
        self._live: list[_Worker] = []
        self._idle_deaths = 0
        self.started = 0  # processes started (replacements included)

    def _spawn(self) -> _Worker:
        import multiprocessing

        context = multiprocessing.get_context("spawn")
        ours, theirs = context.Pipe()
        process = context.Process(target=worker_main, args=(theirs, self.threads, self.session_factory), daemon=True,
                                  name=f"wpbench-worker-{self.started}")
        process.start()
        theirs.close()
        self.started += 1
        worker = _Worker(process, ours)
        self._live.append(worker)
        return worker

    def run(self, jobs: Sequence[Any], stop) -> Iterator[tuple[Any, dict[str, Any]]]:
        import sys
        from multiprocessing.connection import wait

        from wpbench.assets.prepare import prepare_asset_sources

        if not jobs:
            return
        prepare_asset_sources([job.cfg.assets for job in jobs], progress=sys.stderr.isatty())
        pending = deque(range(len(jobs)))
        attempts = [0] * len(jobs)
        self._idle_deaths = 0
        for _ in range(min(self.workers, len(jobs))):
            self._spawn()
        while self._live and (pending or any(w.job is not None for w in self._live)):
            if not stop:
                for worker in self._live:
                    if worker.job is None and pending:
                        job_id = pending.popleft()
                        job = jobs[job_id]
                        worker.job = job_id
                        attempts[job_id] += 1
                        worker.connection.send((job_id, job.run, job.cfg, job.index))
            busy = [w for w in self._live if w.job is not None]
            if stop and not busy:
                break
            ready = set(wait([w.connection for w in busy] + [w.process.sentinel for w in self._live], POLL_S))
            for worker in list(self._live):
                died = worker.process.sentinel in ready
                if worker.connection in ready:
                    try:
                        kind, job_id, payload = worker.connection.recv()
                    except (EOFError, OSError):
                        died = True  # it died mid-send: its job is handled with the death below
                    else:
                        worker.job = None
                        if kind == "fatal":
                            raise WorkerError(payload)
                        yield jobs[job_id], payload
                if died:
                    yield from self._bury(worker, jobs, pending, attempts, stop)

    def _bury(self, worker: _Worker, jobs, pending: deque, attempts: list[int], stop):
        """A worker died: its episode is handed out again, or recorded as a failure after
        :data:`RETRIES` retries; a replacement is started if episodes remain."""
        from wpbench.evaluation.runner import failure_record

        worker.process.join(1.0)
        self._live.remove(worker)
        worker.connection.close()
        job_id, worker.job = worker.job, None
        if job_id is None:
            self._idle_deaths += 1
            if self._idle_deaths > 2 * self.workers:
                raise WorkerError(f"worker processes keep dying before running any episode "
                                  f"(exit code {worker.process.exitcode})")
        elif attempts[job_id] > RETRIES:
            job = jobs[job_id]
            yield job, failure_record(job.cfg, job.index, death_reason(worker.process.exitcode))
        else:
            pending.appendleft(job_id)
        if pending and not stop:
            self._spawn()

    def close(self) -> None:
        """Ask every worker to exit, kill those that do not, and wait for all."""
        for worker in self._live:
            try:
                worker.connection.send(None)
            except OSError:
                pass
        for worker in self._live:
            worker.process.join(SHUTDOWN_S if worker.job is None else 0.1)
            if worker.process.is_alive():
                worker.process.kill()
                worker.process.join()
            worker.connection.close()
        self._live = []
