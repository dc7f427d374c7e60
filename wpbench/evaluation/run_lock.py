"""One writer per run folder: an exclusive ``flock`` on ``<out_dir>/.lock``.

Two ``wpbench run`` with the same ``--out`` would append interleaved copies of the
same episodes. The first process to open the folder holds the lock until it exits
(the kernel releases it on any exit, ``kill -9`` included); a second one is refused
at once with :class:`RunLockedError`. The lock file holds the owner's pid, for the
message only, and is left in place (deleting it would let a third process lock a
fresh file while the second still waits on the old one).
"""

from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

__all__ = ["LOCK_FILE", "RunLockedError", "RunLock"]

LOCK_FILE = ".lock"


class RunLockedError(RuntimeError):
    """Another process is writing to this run folder."""


class RunLock:
    """Exclusive, non-blocking lock of ``out_dir`` (created if missing). A context manager.

    ``created_dir`` says whether this lock made the folder, so a caller that fails
    before writing anything can leave no trace.
    """

    def __init__(self, out_dir: str | os.PathLike[str]) -> None:
        self.out_dir = Path(out_dir)
        self.path = self.out_dir / LOCK_FILE
        self.created_dir = not self.out_dir.exists()
        self._fd: int | None = None

    def acquire(self) -> "RunLock":
        self.out_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as error:
            owner = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            if error.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise RunLockedError(
                    f"another wpbench process (pid {owner}) is writing to {self.out_dir}; wait for it to "
                    "finish, stop it, or choose another --out"
                ) from None
            raise
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def remove_if_unused(self) -> None:
        """Release, then delete the lock file and the folder if this lock created it and
        nothing else is in it (a run that failed before its first episode)."""
        self.release()
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass
        if self.created_dir:
            try:
                self.out_dir.rmdir()
            except OSError:
                pass

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, *exc_info: object) -> None:
        self.release()
