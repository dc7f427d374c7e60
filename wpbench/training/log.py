"""Training progress on disk: ``train_log.csv`` (one row per epoch), ``progress.json``
(what a later session needs to know at a glance) and the ``train_log.png`` plot."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from wpbench.weights import atomic_write_text

LOG_FILE, PLOT_FILE, PROGRESS_FILE = "train_log.csv", "train_log.png", "progress.json"


def read_log(out: Path) -> list[dict]:
    path = Path(out) / LOG_FILE
    if not path.is_file():
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def write_log(out: Path, rows: list[dict]) -> None:
    """Rewrite the whole log (rows may gain columns over time; resumed runs truncate to the checkpoint)."""
    columns: list[str] = []
    for row in rows:
        columns += [key for key in row if key not in columns]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns)
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_text(Path(out) / LOG_FILE, buffer.getvalue())


def write_progress(out: Path, progress: dict) -> None:
    atomic_write_text(Path(out) / PROGRESS_FILE, json.dumps(progress, indent=2, sort_keys=True) + "\n")


def plot_log(out: Path, rows: list[dict], title: str) -> Path | None:
    """Loss (log scale) and validation point / rotation errors against training steps."""
    if not rows:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def series(key: str) -> tuple[list[float], list[float]]:
        xs, ys = [], []
        for row in rows:
            value = row.get(key, "")
            if value not in ("", None):
                xs.append(float(row["step"]))
                ys.append(float(value))
        return xs, ys

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    axes[0].plot(*series("train_loss"), marker="o", label="train loss")
    axes[0].set_yscale("log")
    axes[0].set_title("loss")
    for key in rows[-1]:
        if key.startswith("val_") and key.endswith("_point_m"):
            xs, ys = series(key)
            axes[1].plot(xs, [y * 100 for y in ys], marker="o", label=key[4:-8])
        if key.startswith("val_") and key.endswith("_rot_deg"):
            axes[2].plot(*series(key), marker="o", label=key[4:-8])
    axes[1].set_title("val point error (cm)")
    axes[2].set_title("val rotation error (deg)")
    for ax in axes:
        ax.set_xlabel("step")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(out) / PLOT_FILE
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
