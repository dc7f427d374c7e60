"""The driver of one or many runs: it alone writes their folders, whoever runs the episodes.

``run_many(cfgs, pool)`` opens every run's folder (locked against a second writer,
checked for ``--resume``), hands all their missing episodes at once to a *pool*
(in this process, local worker processes, or a Ray cluster), appends each record
as it comes back, and at the end puts every ``episodes.jsonl`` in episode order and
writes each ``summary.json``.

A pool is an object with ``run(jobs, stop) -> iterator of (job, record)`` and
``close()``; it yields one complete record per job (a failed episode is a record
too) and stops handing out jobs once ``stop`` is set.
"""

from __future__ import annotations

import resource
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Protocol, Sequence

from wpbench.evaluation.interrupt import StopRequest
from wpbench.evaluation.runner import EpisodeSession, RunConfig, episode_seed, produced_by

__all__ = ["Job", "Pool", "InProcessPool", "RunFolder", "RunInterrupted", "run_many", "peak_rss_mib"]


@dataclass(frozen=True)
class Job:
    """Episode ``index`` of run number ``run`` (its position in ``run_many``'s list)."""

    run: int
    cfg: RunConfig
    index: int


class Pool(Protocol):
    def run(self, jobs: Sequence[Job], stop: StopRequest) -> Iterator[tuple[Job, dict[str, Any]]]: ...

    def close(self) -> None: ...


class RunInterrupted(Exception):
    """Ctrl-C stopped the runs; every finished episode is in its folder."""

    def __init__(self, folders: Sequence["RunFolder"]) -> None:
        self.folders = list(folders)
        kept = ", ".join(f"{len(f.writer.records)} in {f.out}" for f in self.folders if f.writer is not None)
        super().__init__(f"interrupted; finished episodes kept ({kept})")


def peak_rss_mib() -> float:
    """The largest resident set of this process and of its finished child processes
    (worker processes), in MiB: what ``/usr/bin/time`` reports as maximum resident size."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return max(own, children) / 1024  # Linux reports KiB


def run_config_record(cfg: RunConfig, out: Path, policy) -> dict[str, Any]:
    """What ``run.json`` stores: the settings, the output folder and what produced the episodes."""
    record = {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()}
    record["out"] = str(out)
    record.update(produced_by(cfg, policy))
    return record


class RunFolder:
    """One run's output folder while its episodes are scheduled: lock, writer, what is left."""

    def __init__(self, cfg: RunConfig, policy) -> None:
        from wpbench.evaluation.run_lock import RunLock

        self.cfg = cfg
        self.out = Path(cfg.out) if cfg.out is not None else cfg.default_out()
        self.policy_info = policy.describe()
        self.run_config = run_config_record(cfg, self.out, policy)
        self.lock = RunLock(self.out)
        self.writer = None
        self.todo: list[int] = []
        self.notes: list[str] = []

    def open(self) -> None:
        from wpbench.evaluation.records import EpisodeWriter

        self.lock.acquire()
        try:
            self.writer = EpisodeWriter(self.out, self.run_config, resume=self.cfg.resume,
                                        expected_seed=lambda i: episode_seed(self.cfg.seed, i))
        except BaseException:
            self.lock.release()
            raise
        done = self.writer.completed_episodes()
        planned = self.cfg.episode_indices()
        self.todo = [i for i in planned if i not in done]
        beyond = sorted(set(done) - set(planned))
        if self.cfg.shard is not None and any(i < self.cfg.episodes for i in beyond):
            from wpbench.evaluation.records import RunMismatchError

            self.close()
            raise RunMismatchError(f"{self.out} holds episodes of another shard than {self.cfg.shard}; "
                                   "use the shard's own folder")
        if beyond:
            self.notes.append(
                f"{self.out} holds {len(done)} episodes, more than the {self.cfg.episodes} asked for; its "
                f"summary covers all {len(done)} (use a new --out for a {self.cfg.episodes}-episode run)")

    def write(self, record: dict[str, Any]) -> None:
        self.writer.write(record)

    def finish(self, session_started: float) -> dict[str, Any]:
        """Episodes in order, ``summary.json`` written; returns the summary."""
        import json

        from wpbench.evaluation.summary import summarize, write_summary

        self.writer.sort_by_episode()
        records = list(self.writer.records)
        cfg = self.cfg
        meta = {
            "policy": cfg.policy, "task": cfg.task, "split": cfg.split, "asset_source": cfg.assets,
            "obs": cfg.obs, "seed": cfg.seed, "executor": cfg.executor, "shard": cfg.shard,
            "camera_noise": dict(cfg.camera_noise),
            # Episode times come from the records, so a resumed run reports the whole run;
            # peak memory is this session's (a resumed run keeps its largest session's).
            "timings": {"wall_s": float(sum(r.get("timings", {}).get("episode_s", 0.0) for r in records)),
                        "session_wall_s": time.perf_counter() - session_started},
            "policy_info": self.policy_info,
        }
        summary = summarize(records, meta)
        peak = peak_rss_mib()  # after summarize: its pandas import is part of the run's memory
        previous = self.out / "summary.json"
        if previous.is_file():
            try:
                peak = max(peak, float(json.loads(previous.read_text())["timings"]["run"]["peak_rss_mib"]))
            except (KeyError, TypeError, ValueError):
                pass
        summary["timings"]["run"]["peak_rss_mib"] = peak
        write_summary(self.out, summary)
        self.close()
        summary["_out_dir"] = str(self.out)
        summary["_notes"] = list(self.notes)
        return summary

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
        self.lock.release()

    def abandon(self) -> None:
        """After an error: close, and leave no trace if this session wrote nothing to a new folder."""
        if self.writer is not None:
            self.writer.discard_if_unused()
            if not self.writer.records and not self.writer.written:
                self.lock.remove_if_unused()
        self.lock.release()


class InProcessPool:
    """Runs the episodes one after another in this process (``--workers 1``).

    ``policies`` / ``observer``: objects to use instead of building them (by run number).
    """

    def __init__(self, policies: dict[int, Any] | None = None, observer=None) -> None:
        self.policies = dict(policies or {})
        self.observer = observer
        self._session: EpisodeSession | None = None
        self._run: int | None = None

    def run(self, jobs: Sequence[Job], stop: StopRequest) -> Iterator[tuple[Job, dict[str, Any]]]:
        for job in jobs:
            if stop:
                return
            if self._run != job.run:
                self.close()
                self._session = EpisodeSession(job.cfg, policy=self.policies.get(job.run), observer=self.observer)
                self._run = job.run
            yield job, self._session.run(job.index)

    def close(self) -> None:
        if self._session is not None:
            self._session.close()
            self._session, self._run = None, None


def run_many(
    cfgs: Sequence[RunConfig],
    pool: Pool,
    policies: dict[int, Any] | None = None,
    progress: bool = True,
    description: str | None = None,
    on_episode: Callable[[dict], None] | None = None,
) -> list[dict[str, Any]]:
    """Run every episode still missing from the runs ``cfgs`` on ``pool``; their summaries.

    ``policies``: policy objects by run number (else built here to describe the run).
    Raises :class:`RunInterrupted` after Ctrl-C (finished episodes kept, no summary
    written for an unfinished run); any other error closes the folders, removing those
    a failed first session left empty.
    """
    from tqdm import tqdm

    from wpbench.policies.registry import make_policy

    started = time.perf_counter()
    folders: list[RunFolder] = []
    try:
        for number, cfg in enumerate(cfgs):
            policy = (policies or {}).get(number) or make_policy(cfg.policy, **cfg.policy_kwargs)
            folders.append(RunFolder(cfg, policy))
            folders[-1].open()
    except BaseException:
        for folder in folders:
            folder.abandon()
        raise
    jobs = [Job(number, folder.cfg, index) for number, folder in enumerate(folders) for index in folder.todo]
    total = sum(len(folder.todo) + len(folder.writer.records) for folder in folders)
    first = cfgs[0] if cfgs else None
    label = description or (f"{first.policy} {first.task}" if len(cfgs) == 1 else f"{len(cfgs)} runs")
    bar = tqdm(total=total, initial=total - len(jobs), disable=not progress, desc=label, unit="ep",
               dynamic_ncols=True)
    successes = sum(bool(r.get("success")) for f in folders for r in f.writer.records)
    finished = total - len(jobs)
    try:
        with StopRequest() as stop:
            try:
                for job, record in pool.run(jobs, stop):
                    folders[job.run].write(record)
                    finished += 1
                    successes += bool(record.get("success"))
                    bar.update(1)
                    bar.set_postfix(success=f"{successes / max(finished, 1):.0%}")
                    if on_episode is not None:
                        on_episode(record)
            finally:
                pool.close()
                bar.close()
            if stop:
                for folder in folders:
                    folder.close()
                raise RunInterrupted(folders)
    except RunInterrupted:
        raise
    except BaseException:
        for folder in folders:
            folder.abandon()
        raise
    return [folder.finish(started) for folder in folders]
