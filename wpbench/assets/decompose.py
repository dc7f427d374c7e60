"""Convex decomposition of links, each in a worker process of its own, several at once.

CoACD is native code: on some meshes it crashes the whole process (a segmentation
fault), and a large link takes a minute. So every link is decomposed by a fresh
``python -m wpbench.assets.decompose JOB.json`` process, at most ``workers`` at a time:

* a crash costs only that link: the parent sees the signal, gives the link a
  fallback (``wpbench.assets.collision_fallback``) and records why;
* a worker writes the link's cache entry itself, into a temporary directory that it
  renames into place, so an interrupted run leaves no half-written entry and two
  processes preparing the same object at once both end with one complete entry;
* the worker shares nothing with the caller (no SAPIEN, no torch state).

A cache entry is a directory ``piece_000.obj ...`` + ``timing.json`` =
{"link", "seconds", "source", "pieces", "coacd", and for a fallback "fallback" and "reason"}.
"""

from __future__ import annotations

import importlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import trimesh

from wpbench.assets.collision_fallback import fallback_pieces

# The decomposer a job runs unless it names another ("module:function" taking
# (mesh, CoacdConfig) and returning convex trimesh pieces).
DEFAULT_DECOMPOSER = "wpbench.assets.decompose:run_coacd"
# Pieces with less volume than this (in the mesh's units cubed) cannot push anything.
MIN_PIECE_VOLUME = 1e-12
# How often the scheduler looks at its workers (seconds).
POLL_SECONDS = 0.2
# Lines of a crashed worker's stderr kept in the reason.
STDERR_TAIL_LINES = 3


@dataclass(frozen=True)
class CoacdConfig:
    """CoACD parameters. Modest on purpose: a 2-core machine takes 35-60 s per body.

    threshold: concavity tolerance (fraction of the mesh size); 0.05-0.1 keeps
        thin walls as separate pieces while keeping the piece count low.
    max_convex_hull: cap on pieces per link (-1 = no cap).
    preprocess_resolution: voxel resolution of the manifold pre-pass.
    mcts_iterations / mcts_nodes: search effort per cut.
    seed: CoACD's random seed, for reproducible pieces.
    """

    threshold: float = 0.08
    max_convex_hull: int = 48
    preprocess_resolution: int = 50
    mcts_iterations: int = 100
    mcts_nodes: int = 15
    seed: int = 0


@dataclass(frozen=True)
class LinkJob:
    """One link to decompose: its mesh (an .npz with ``vertices`` (V, 3) and ``faces``
    (F, 3), link frame), the cache entry to write, and what decomposes it."""

    label: str  # what the progress bar shows, e.g. "01909/knob_link_2"
    link: str
    mesh_file: Path
    entry: Path
    config: CoacdConfig = CoacdConfig()
    decomposer: str = DEFAULT_DECOMPOSER

    def to_json(self) -> str:
        return json.dumps({"label": self.label, "link": self.link, "mesh_file": str(self.mesh_file),
                           "entry": str(self.entry), "config": asdict(self.config), "decomposer": self.decomposer})

    @classmethod
    def from_json(cls, text: str) -> "LinkJob":
        d = json.loads(text)
        return cls(label=d["label"], link=d["link"], mesh_file=Path(d["mesh_file"]), entry=Path(d["entry"]),
                   config=CoacdConfig(**d["config"]), decomposer=d["decomposer"])


# --------------------------------------------------------------------------- pieces and entries


def convex_pieces_from_vertices(groups: Sequence[np.ndarray]) -> list[trimesh.Trimesh]:
    """Convex hulls of vertex groups (K_i, 3); groups without volume are dropped."""
    pieces = []
    for vertices in groups:
        try:
            hull = trimesh.convex.convex_hull(np.asarray(vertices, dtype=np.float64))
        except Exception:  # degenerate (flat) group: PhysX cannot use it either
            continue
        if hull.volume > MIN_PIECE_VOLUME:
            pieces.append(hull)
    return pieces


def run_coacd(mesh: trimesh.Trimesh, config: CoacdConfig) -> list[trimesh.Trimesh]:
    """Convex pieces of ``mesh`` from CoACD (each piece a convex hull, link frame)."""
    import coacd  # heavy import; only needed on a cache miss

    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)),
        threshold=config.threshold,
        max_convex_hull=config.max_convex_hull,
        preprocess_resolution=config.preprocess_resolution,
        mcts_iterations=config.mcts_iterations,
        mcts_nodes=config.mcts_nodes,
        seed=config.seed,
    )
    return convex_pieces_from_vertices([np.asarray(v) for v, _f in parts])


def entry_is_complete(entry: Path) -> bool:
    return (Path(entry) / "timing.json").is_file()


def read_entry(entry: Path) -> dict:
    """The ``timing.json`` of a complete cache entry."""
    return json.loads((Path(entry) / "timing.json").read_text())


def entry_piece_files(entry: Path) -> list[Path]:
    return sorted(Path(entry).glob("piece_*.obj"))


def write_entry(entry: Path, pieces: Sequence[trimesh.Trimesh], info: dict) -> None:
    """Write convex pieces and ``timing.json`` into ``entry`` all at once (temporary
    directory + rename); if another process finished the same entry first, keep its."""
    entry = Path(entry)
    entry.parent.mkdir(parents=True, exist_ok=True)
    tmp_dir = Path(tempfile.mkdtemp(dir=entry.parent, prefix=f".{entry.name}.", suffix=".tmp"))
    try:
        for i, piece in enumerate(pieces):
            piece.export(tmp_dir / f"piece_{i:03d}.obj")
        (tmp_dir / "timing.json").write_text(json.dumps({**info, "pieces": len(pieces)}, indent=2) + "\n")
        try:
            os.rename(tmp_dir, entry)
        except OSError:
            if not entry_is_complete(entry):
                raise
            shutil.rmtree(tmp_dir, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp_dir, ignore_errors=True)
        raise


def write_fallback_entry(job: LinkJob, reason: str, seconds: float) -> None:
    """Give ``job``'s link its fallback pieces (see collision_fallback) and record why."""
    vertices = np.load(job.mesh_file)["vertices"]
    pieces, kind = fallback_pieces(vertices)
    write_entry(job.entry, pieces, {"link": job.link, "seconds": seconds, "source": "fallback", "fallback": kind,
                                    "reason": reason, "coacd": asdict(job.config)})


def save_mesh(mesh: trimesh.Trimesh, path: Path) -> None:
    np.savez(path, vertices=np.asarray(mesh.vertices, dtype=np.float64), faces=np.asarray(mesh.faces, dtype=np.int64))


def _decomposer(name: str) -> Callable:
    module, _, function = name.partition(":")
    return getattr(importlib.import_module(module), function)


def run_job(job: LinkJob) -> None:
    """Decompose one link and write its entry (what a worker process does)."""
    data = np.load(job.mesh_file)
    mesh = trimesh.Trimesh(vertices=data["vertices"], faces=data["faces"], process=False)
    start = time.perf_counter()
    pieces = _decomposer(job.decomposer)(mesh, job.config)
    seconds = time.perf_counter() - start
    if pieces:
        write_entry(job.entry, pieces, {"link": job.link, "seconds": seconds, "source": "coacd",
                                        "coacd": asdict(job.config)})
    else:
        write_fallback_entry(job, "the decomposition gave no piece with volume (a flat or thin mesh)", seconds)


# --------------------------------------------------------------------------- the scheduler


def _crash_reason(returncode: int, stderr_file: Path) -> str:
    if returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = f"signal {-returncode}"
        what = f"the decomposition crashed ({name})"
    else:
        what = f"the decomposition failed (exit code {returncode})"
    tail = [line for line in stderr_file.read_text(errors="replace").splitlines() if line.strip()][-STDERR_TAIL_LINES:]
    return what + (f": {' | '.join(tail)}" if tail and returncode > 0 else "")


def default_workers() -> int:
    return max(1, os.cpu_count() or 1)


def run_jobs(jobs: Sequence[LinkJob], workers: int | None = None, progress: bool = True,
             desc: str = "convex decomposition") -> dict[str, str]:
    """Decompose every job's link, at most ``workers`` worker processes at a time.

    Jobs whose entry already exists are skipped. A worker that crashes or fails gets
    its link a fallback entry. Returns {job label: reason} for the links that fell back
    because their worker crashed. Ctrl-C (or any error) stops every worker started here.
    """
    from tqdm import tqdm

    workers = default_workers() if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    pending = [j for j in jobs if not entry_is_complete(j.entry)]
    crashes: dict[str, str] = {}
    if not pending:
        return crashes
    scratch = Path(tempfile.mkdtemp(prefix="wpbench-decompose-"))
    running: dict[str, tuple[subprocess.Popen, LinkJob, Path, float]] = {}
    bar = tqdm(total=len(pending), desc=desc, unit="link", disable=not progress, dynamic_ncols=True)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    shown = ""
    try:
        queue = list(enumerate(pending))
        while queue or running:
            while queue and len(running) < workers:
                number, job = queue.pop(0)
                if entry_is_complete(job.entry):  # another process made it meanwhile
                    bar.update(1)
                    continue
                spec = scratch / f"job-{number:05d}.json"
                spec.write_text(job.to_json())
                stderr_file = spec.with_suffix(".stderr")
                with open(stderr_file, "w") as err:
                    process = subprocess.Popen([sys.executable, "-m", "wpbench.assets.decompose", str(spec)],
                                               stdout=subprocess.DEVNULL, stderr=err, env=env)
                running[job.label] = (process, job, stderr_file, time.perf_counter())
            names = ", ".join(running)
            if names != shown:
                bar.set_postfix_str(names, refresh=True)
                shown = names
            time.sleep(POLL_SECONDS)
            for label, (process, job, stderr_file, started) in list(running.items()):
                code = process.poll()
                if code is None:
                    continue
                del running[label]
                if not entry_is_complete(job.entry):
                    reason = _crash_reason(code, stderr_file)
                    crashes[label] = reason
                    write_fallback_entry(job, reason, time.perf_counter() - started)
                bar.update(1)
    finally:
        for process, *_rest in running.values():
            process.terminate()
        for process, *_rest in running.values():
            try:
                process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                process.kill()
        bar.close()
        shutil.rmtree(scratch, ignore_errors=True)
    return crashes


def main(argv: Sequence[str]) -> int:
    if len(argv) != 1:
        print("usage: python -m wpbench.assets.decompose JOB.json", file=sys.stderr)
        return 2
    run_job(LinkJob.from_json(Path(argv[0]).read_text()))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
