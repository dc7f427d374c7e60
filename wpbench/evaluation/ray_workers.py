"""Episodes on a Ray cluster (``wpbench run --ray [ADDRESS]``).

The same scheme as :mod:`wpbench.evaluation.local_workers`, with Ray actors in place
of processes: one actor per CPU of the cluster (one CPU each), each building a run's
env and policy once and running one episode at a time; the driver writes every record,
so the nodes need no shared file system. What an episode needs beyond the installed
package travels with the tasks through Ray's object store: the trained weights of a
weighted policy and a PartNet-Mobility ``--assets`` folder are put there once per
sweep as bytes and unpacked once per node into a folder named by their content hash.
A folder's convex decomposition is made once, on the driver (what its collision cache
lacks, all links at once on the driver's cores, ``wpbench.assets.prepare``), and its
cache entries travel the same way: each node copies them into its own collision cache
before its first episode, so no node decomposes again. (The built-in furniture is
generated on each node from the package: same code, same seed, same furniture.)
``wpbench data generate --ray`` ships an asset folder the same way
(``wpbench.data.ray_generation``).

An actor that dies takes its episode with it: that episode goes to a new actor once,
and is recorded as a failure with the reason if it dies again. Each record's
``ran_on`` names the Ray node that ran it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import os
import sys
import tarfile
import tempfile
from collections import deque
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

from wpbench.evaluation.local_workers import POLL_S, RETRIES, WorkerError, set_thread_count

__all__ = ["RayPool", "connect", "folder_files", "pack_folder", "pack_files", "asset_folder_files", "unpack_folder", "collision_cache_files",
           "install_collision_cache", "ship_folder", "ship_asset_folder", "receive_shipped", "ray_available"]

LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
SINGLE_MACHINE_VARIABLE = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
ACTOR_DEATH_REASON = f"Ray actor died while running this episode, {RETRIES + 1} times"


def ray_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("ray") is not None


def connect(address: str | None = None, num_cpus: int | None = None) -> bool:
    """Connect this process to the Ray cluster at ``address`` ("auto": the running one;
    None: start a local one with ``num_cpus`` CPUs, on 127.0.0.1), unless it already is;
    True when this call connected (the caller then shuts Ray down when done)."""
    host = (address or "127.0.0.1").rsplit(":", 1)[0]
    if host in LOOPBACK_HOSTS:
        # Ray turns a loopback address into this machine's network address before
        # connecting, unless told the cluster is this machine alone (read when ray is
        # first imported): a cluster on 127.0.0.1 stays on 127.0.0.1.
        os.environ.setdefault(SINGLE_MACHINE_VARIABLE, "0")
    import ray

    if ray.is_initialized():
        return False
    options = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
    if address is None:
        ray.init(num_cpus=num_cpus, _node_ip_address="127.0.0.1", **options)
    else:
        ray.init(address=address, **options)
    return True


def pack_files(files: Iterable[tuple[str, Path]]) -> tuple[str, bytes]:
    """``(sha256 of the archive, tar archive)`` of ``(name in the archive, file)`` pairs, in
    sorted order with fixed times and owners, so equal contents give equal archives."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as archive:
        for name, path in sorted(files):
            info = archive.gettarinfo(str(path), arcname=name)
            info.mtime, info.uid, info.gid, info.uname, info.gname = 0, 0, 0, "", ""
            with open(path, "rb") as handle:
                archive.addfile(info, handle)
    data = buffer.getvalue()
    return hashlib.sha256(data).hexdigest(), data


def folder_files(folder: str | os.PathLike[str], prefix: str = "") -> list[tuple[str, Path]]:
    """Every file under ``folder`` (hidden entries left out) as ``(path in the folder, under
    ``prefix/`` when given, file)`` pairs, for :func:`pack_files`."""
    root = Path(folder)
    files = []
    for path in root.rglob("*"):
        relative = path.relative_to(root)
        if any(part.startswith(".") for part in relative.parts) or not path.is_file():
            continue
        files.append(((Path(prefix) / relative).as_posix() if prefix else relative.as_posix(), path))
    return files


def pack_folder(folder: str | os.PathLike[str], prefix: str = "") -> tuple[str, bytes]:
    """:func:`pack_files` of :func:`folder_files`."""
    return pack_files(folder_files(folder, prefix))


def asset_folder_files(folder: Path) -> list[tuple[str, Path]]:
    """:func:`folder_files` of an asset folder under its own name, with its split file in it
    even when that file lives in this machine's cache (a folder one cannot write into), so
    a node loads the split's objects as the driver would."""
    from wpbench.assets.object_split import SPLIT_FILE_NAME, find_split_file

    in_folder = f"{folder.name}/{SPLIT_FILE_NAME}"
    files = folder_files(folder, prefix=folder.name)
    split = find_split_file(folder)
    if split is not None and split.parent != folder:
        files = [(name, path) for name, path in files if not (name == in_folder or name.startswith(in_folder + "/"))]
        files.append((in_folder, split))
    return files


def unpack_folder(digest: str, data: bytes, root: Path | None = None) -> Path:
    """The folder ``data`` (from :func:`pack_folder`) unpacked under ``root`` (default: the
    temporary folder), named by its digest; unpacked once per machine (atomically)."""
    root = Path(root or Path(tempfile.gettempdir()) / "wpbench-ray")
    target = root / digest
    if target.is_dir():
        return target
    root.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=root, prefix=f".{digest[:12]}-"))
    with tarfile.open(fileobj=io.BytesIO(data), mode="r") as archive:
        archive.extractall(staging, filter="data")
    try:
        os.rename(staging, target)
    except OSError:  # another actor on this node was first
        import shutil

        shutil.rmtree(staging, ignore_errors=True)
    return target


def collision_cache_files(folder: Path, progress: bool = False) -> list[tuple[str, Path]]:
    """The collision cache entries of every usable object under ``folder``, as
    ``("<object id>/pieces/<entry>/<file>", path)`` pairs; what this machine's cache lacks
    is decomposed first (:func:`wpbench.assets.prepare.prepare_folder`)."""
    from wpbench.assets.collision import plan_collision
    from wpbench.assets.partnet import default_cache_dir
    from wpbench.assets.prepare import prepare_folder

    files = []
    for prepared in prepare_folder(folder, progress=progress):
        if prepared.derived is None:
            continue  # the loader refuses it on every node alike
        object_id = prepared.folder.name
        plan = plan_collision(prepared.folder, default_cache_dir(object_id))
        plan.cleanup()
        for entry in plan.entries.values():
            files += [(f"{object_id}/pieces/{entry.name}/{path.relative_to(entry).as_posix()}", path)
                      for path in entry.rglob("*") if path.is_file()]
    return files


def install_collision_cache(unpacked: Path) -> list[Path]:
    """Copy the entries of an unpacked :func:`collision_cache_files` archive into this node's
    collision cache (``wpbench.assets.partnet.default_cache_dir``), each atomically; entries
    already there are kept. The entries copied."""
    import shutil

    from wpbench.assets.decompose import entry_is_complete
    from wpbench.assets.partnet import default_cache_dir

    copied = []
    for entry in sorted(Path(unpacked).glob("*/pieces/*")):
        target = default_cache_dir(entry.parent.parent.name) / "pieces" / entry.name
        if entry_is_complete(target):
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{entry.name}-"))
        shutil.copytree(entry, staging, dirs_exist_ok=True)
        try:
            os.rename(staging, target)
            copied.append(target)
        except OSError:  # another actor on this node was first
            shutil.rmtree(staging, ignore_errors=True)
    return copied


def ship_folder(what: str, folder: Path, packed: dict, put, progress: bool = False) -> tuple[str, str, Any, str]:
    """``(what, digest, object reference, folder name in the archive)`` of ``folder`` put in
    Ray's object store with ``put``: "weights_root" the folder itself, "assets" the folder
    with its split file (:func:`asset_folder_files`), "collision_cache" its collision cache
    entries (:func:`collision_cache_files`, so the folder is decomposed here first).
    ``packed`` holds what was already put there."""
    name = folder.name if what == "assets" else ""
    key = (what, str(folder))
    if key not in packed:
        if what == "collision_cache":
            digest, data = pack_files(collision_cache_files(folder, progress=progress))
        elif what == "assets":
            digest, data = pack_files(asset_folder_files(folder))
        else:
            digest, data = pack_folder(folder)
        packed[key] = (digest, put(data))
    return (what, *packed[key], name)


def ship_asset_folder(assets: str, packed: dict, put, progress: bool = False) -> list[tuple[str, str, Any, str]]:
    """What a node needs of the asset source ``assets`` (nothing for "procedural"): the
    folder and its collision cache, as :func:`ship_folder` entries."""
    if assets == "procedural":
        return []
    folder = Path(assets).expanduser().resolve()
    return [ship_folder(what, folder, packed, put, progress) for what in ("assets", "collision_cache")]


def receive_shipped(shipped: list[tuple[str, str, Any, str]]) -> dict[str, str]:
    """On a node: unpack what :func:`ship_folder` put in the object store (once per node)
    and install collision cache entries; ``{what: local folder}``."""
    import ray

    local = {}
    for what, digest, reference, name in shipped:
        unpacked = unpack_folder(digest, ray.get(reference))
        if what == "collision_cache":
            install_collision_cache(unpacked)
        local[what] = str(unpacked / name)
    return local


def _shipped(cfg, packed: dict, put, progress: bool = False) -> list[tuple[str, str, Any, str]]:
    """What of run ``cfg`` lives outside the package: its weights root, its asset folder
    and that folder's collision cache (:func:`ship_folder` entries)."""
    from wpbench import names

    shipped = []
    if cfg.policy in names.WEIGHTED_POLICIES:
        from wpbench.weights import weights_root_or_shipped

        root = Path(weights_root_or_shipped(cfg.policy_kwargs.get("weights_root")))
        shipped.append(ship_folder("weights_root", root, packed, put, progress))
    return shipped + ship_asset_folder(cfg.assets, packed, put, progress)


class EpisodeActor:
    """A Ray actor running episodes; see the module docstring."""

    def __init__(self, threads: int) -> None:
        set_thread_count(threads)
        self.session, self.current = None, None

    def run(self, run: int, cfg, index: int, shipped: list) -> dict[str, Any]:
        import ray

        from wpbench.evaluation.runner import EpisodeSession

        if self.current != run:
            if self.session is not None:
                self.session.close()
            self.session, self.current = None, None
            local = receive_shipped(shipped)
            if "weights_root" in local:
                cfg = dataclasses.replace(cfg, policy_kwargs={**cfg.policy_kwargs, "weights_root": local["weights_root"]})
            if "assets" in local:
                cfg = dataclasses.replace(cfg, assets=local["assets"])
            self.session, self.current = EpisodeSession(cfg), run
        record = self.session.run(index)
        record["ran_on"]["node"] = ray.get_runtime_context().get_node_id()
        return record

    def close(self) -> None:
        if self.session is not None:
            self.session.close()


class RayPool:
    """Episodes on the Ray cluster at ``address`` ("auto": the running one; None: start a
    local one with ``num_cpus`` CPUs, on 127.0.0.1). ``workers``: actors to use
    (default: the cluster's CPUs)."""

    def __init__(self, address: str | None = None, workers: int | None = None, num_cpus: int | None = None) -> None:
        if not ray_available():
            raise ValueError("--ray needs Ray: pip install 'ray==2.*' (scripts/setup.sh installs it)")
        self.address = address
        self.workers = workers
        self.num_cpus = num_cpus
        self._actors: list[Any] = []
        self._started_ray = False
        self.started = 0

    def _connect(self) -> None:
        self._started_ray = connect(self.address, self.num_cpus) or self._started_ray

    def _new_actor(self):
        import ray

        actor_class = ray.remote(num_cpus=1, max_restarts=0)(EpisodeActor)
        self.started += 1
        actor = actor_class.remote(1)
        self._actors.append(actor)
        return actor

    def run(self, jobs: Sequence[Any], stop) -> Iterator[tuple[Any, dict[str, Any]]]:
        import ray
        from ray.exceptions import RayActorError, RayTaskError

        from wpbench.evaluation.runner import failure_record

        if not jobs:
            return
        self._connect()
        shipped: dict[int, list] = {}
        packed: dict = {}
        for job in jobs:
            if job.run not in shipped:
                shipped[job.run] = _shipped(job.cfg, packed, ray.put, progress=sys.stderr.isatty())
        capacity = int(ray.cluster_resources().get("CPU", 1))
        count = min(self.workers or capacity, capacity, len(jobs))
        idle = deque(self._new_actor() for _ in range(count))
        pending = deque(range(len(jobs)))
        attempts = [0] * len(jobs)
        in_flight: dict[Any, tuple[Any, int]] = {}
        while pending or in_flight:
            while not stop and pending and idle:
                actor, job_id = idle.popleft(), pending.popleft()
                job = jobs[job_id]
                attempts[job_id] += 1
                in_flight[actor.run.remote(job.run, job.cfg, job.index, shipped[job.run])] = (actor, job_id)
            if stop and not in_flight:
                break
            ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=POLL_S)
            for reference in ready:
                actor, job_id = in_flight.pop(reference)
                try:
                    record = ray.get(reference)
                except RayActorError:
                    self._actors.remove(actor)
                    if attempts[job_id] > RETRIES:
                        job = jobs[job_id]
                        yield job, failure_record(job.cfg, job.index, ACTOR_DEATH_REASON)
                    else:
                        pending.appendleft(job_id)
                    if pending and not stop:
                        idle.append(self._new_actor())
                    continue
                except RayTaskError as err:
                    raise WorkerError(str(err.cause) if err.cause is not None else str(err)) from None
                idle.append(actor)
                yield jobs[job_id], record

    def close(self) -> None:
        import ray

        for actor in self._actors:
            try:
                ray.kill(actor)
            except Exception:  # noqa: BLE001 - already gone
                pass
        self._actors = []
        if self._started_ray:
            ray.shutdown()
            self._started_ray = False
