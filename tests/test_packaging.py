"""The installed distribution: every package is listed, and tasks/ and policies/ install under wpbench."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _listed() -> tuple[list[str], dict[str, str]]:
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    return config["packages"], config["package-dir"]


def test_every_package_folder_is_listed_in_pyproject():
    packages, package_dir = _listed()
    found = set()
    for init in REPO.glob("**/__init__.py"):
        rel = init.parent.relative_to(REPO)
        if rel.parts[0] in {".venv", "tests", "scripts", "docs"} or rel.parts[0].startswith("."):
            continue
        name = ".".join(rel.parts)
        for package, folder in package_dir.items():
            if package and (name == folder or name.startswith(folder + ".")):
                name = package + name[len(folder):]
        found.add(name)
    assert found == set(packages)


def test_tasks_and_policies_import_only_under_wpbench(tmp_path):
    """Run from outside the repository, as an installed user would: no top-level ``tasks``/``policies``."""
    code = ("import importlib.util, wpbench.tasks, wpbench.policies;"
            "print(importlib.util.find_spec('tasks'), importlib.util.find_spec('policies'))")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["None", "None"]
