"""The environment the mplib planner process runs in: numpy 1 ahead of the venv's numpy 2.

mplib (pinned in pyproject.toml to the 0.1.1 that mani-skill requires; 0.2.1 crashes the
same way) is compiled against numpy 1 and segfaults when its planner is built under
numpy 2. wpbench needs numpy 2 (pandas, rerun), so the planner runs in a child process
(wpbench.sim.arm_planner_server) whose ``PYTHONPATH`` starts with a directory holding
numpy ``NUMPY_FOR_MPLIB`` and nothing else; every other package (mplib, toppra, scipy)
comes from the venv. ``scripts/setup.sh`` creates the directory
(``python -m wpbench.sim.arm_planner_env``); a process that finds it missing creates it
the same way, once, under a file lock.
"""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
from pathlib import Path

NUMPY_FOR_MPLIB = "1.26.4"


def side_dir() -> Path:
    """Where numpy 1 for the planner lives: inside the running venv (or $WPBENCH_MPLIB_NUMPY_DIR)."""
    override = os.environ.get("WPBENCH_MPLIB_NUMPY_DIR")
    return Path(override) if override else Path(sys.prefix) / "mplib-numpy1"


def _installed(path: Path) -> bool:
    return (path / f"numpy-{NUMPY_FOR_MPLIB}.dist-info").is_dir()


def ensure_side_dir() -> Path:
    """The numpy-1 directory, installed with pip (``--target``, no dependencies) if missing."""
    path = side_dir()
    if _installed(path):
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.parent / ".mplib-numpy1.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not _installed(path):
            tmp = path.with_name(path.name + f".tmp{os.getpid()}")
            proc = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(tmp),
                                   f"numpy=={NUMPY_FOR_MPLIB}"], capture_output=True, text=True)
            if proc.returncode != 0:
                raise RuntimeError(f"could not install numpy=={NUMPY_FOR_MPLIB} for mplib's planner into {path} "
                                   f"({proc.stderr.strip()[-300:]}); run scripts/setup.sh with network access")
            if path.exists():
                import shutil

                shutil.rmtree(path)
            tmp.replace(path)
    return path


def planner_environment() -> dict[str, str]:
    """os.environ for the planner process: numpy 1 first on PYTHONPATH, one thread."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ensure_side_dir()), *filter(None, [env.get("PYTHONPATH")])])
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


if __name__ == "__main__":
    print(ensure_side_dir())
