"""A content hash of an asset folder, stored in ``run.json`` so that ``--resume`` never
mixes episodes drawn from two different sets of objects."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["folder_digest"]

_CHUNK = 1 << 20


def folder_digest(folder: str | os.PathLike[str]) -> str:
    """SHA-256 over every regular file under ``folder`` (hidden files and folders skipped):
    their paths relative to ``folder``, in sorted order, and their bytes. Renaming, adding,
    removing or editing a file changes it; touching a file does not."""
    root = Path(folder)
    if not root.is_dir():
        raise ValueError(f"{root} is not a folder")
    digest = hashlib.sha256()
    files = []
    for directory, subdirectories, names in os.walk(root, followlinks=True):
        subdirectories[:] = [d for d in subdirectories if not d.startswith(".")]
        files += [Path(directory) / name for name in names if not name.startswith(".")]
    for path in sorted(files, key=lambda p: p.relative_to(root).as_posix()):
        if not path.is_file():
            continue
        relative = path.relative_to(root).as_posix().encode()
        digest.update(len(relative).to_bytes(8, "little") + relative)
        digest.update(path.stat().st_size.to_bytes(8, "little"))
        with open(path, "rb") as handle:
            while chunk := handle.read(_CHUNK):
                digest.update(chunk)
    return digest.hexdigest()
