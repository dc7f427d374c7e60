"""Shared pytest fixtures, markers and hypothesis profiles for the wpbench suite.

- Hypothesis: profile ``ci`` (derandomized, no deadline, no example database) is
  loaded when ``CI`` is set; ``dev`` (no deadline) otherwise. Override with
  ``HYPOTHESIS_PROFILE=<name>``. Deadlines are off because five engineers share
  two cores: a slow example is load, not a bug.
- Markers: ``slow`` (> 20 s; still runs in CI), ``render`` (needs the Vulkan
  renderer), ``shared`` (needs ``../shared/partnet-mobility``).
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

REPO_ROOT = Path(__file__).resolve().parents[1]

settings.register_profile(
    "ci",
    deadline=None,
    derandomize=True,
    database=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("dev", deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE") or ("ci" if os.environ.get("CI") else "dev"))


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "slow: takes more than 20 s (runs the simulator for many episodes)")
    config.addinivalue_line("markers", "render: needs the Vulkan renderer (Mesa lavapipe)")
    config.addinivalue_line("markers", "shared: needs the real PartNet-Mobility objects in ../shared")


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The checkout's root folder (holds pyproject.toml)."""
    return REPO_ROOT


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared/partnet-mobility`` (or ``$WPBENCH_SHARED_DIR``); skips if absent."""
    path = Path(os.environ.get("WPBENCH_SHARED_DIR", REPO_ROOT.parent / "shared" / "partnet-mobility"))
    if not path.is_dir():
        pytest.skip(f"real PartNet-Mobility objects not found at {path}")
    return path


@pytest.fixture
def tmp_results(tmp_path: Path) -> Path:
    """An empty results folder for one test."""
    path = tmp_path / "results"
    path.mkdir()
    return path


@pytest.fixture(scope="session")
def wpbench_exe() -> Path:
    """The installed ``wpbench`` console script of the running interpreter's venv.

    Missing means the package is not installed (``pip install -e .``): a real
    failure, not a reason to skip.
    """
    beside_python = Path(sys.executable).parent / "wpbench"
    if beside_python.exists():
        return beside_python
    found = shutil.which("wpbench")
    if found is None:
        pytest.fail("the `wpbench` console script is not installed; run `make setup`")
    return Path(found)
