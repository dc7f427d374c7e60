"""Benchmark: size and speed of TAX-Pose, Goal Flow and WeightedPose on the CPU.

For each model at two sizes

- ``default``: wpbench's laptop-sized config (``build_model(name)``) on
  256 action + 1024 anchor points,
- ``reference``: the published TAX-Pose size (DGCNN widths 64-64-128-256,
  512-dim embeddings, k = 20; ``<Config>.reference()``) on 200 + 1800 points,

it reports the parameter count, the inference latency of one sample
(median over repeats, ``torch.no_grad``, eval mode) and the time of one
training step at batch 16 (forward, the model's loss preset, backward, Adam
step; median over repeats), each as wall time and as process CPU time
(summed over threads; steadier on a shared machine). Inputs are random clouds with a random rigid
goal; speed does not depend on their content. The reference size is slow
(tens of seconds per training step) and gets ``reference_repeats`` runs.

Targets at the default size (2 threads): inference <= 50 ms, training step <= 2 s.
Timings are wall-clock; other processes on the CPU make them pessimistic
(the 1-minute load average at the start is recorded).

CLI: ``python -m wpbench.bench.models --json out.json`` (``wpbench bench models``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from tabulate import tabulate

from wpbench.geometry import se3
from wpbench.models.loss_presets import compute_loss
from wpbench.models.registry import MODEL_CONFIGS, build_model

MODEL_NAMES = ("taxpose", "goalflow", "weightedpose")
TRAINING_PRESET = {"taxpose": "tp", "goalflow": "gf", "weightedpose": "wp-postsvd"}
POINT_COUNTS = {"default": (256, 1024), "reference": (200, 1800)}
TRAIN_BATCH = 16


def _random_batch(batch: int, action_points: int, anchor_points: int, seed: int) -> dict[str, torch.Tensor]:
    generator = torch.Generator().manual_seed(seed)
    action = torch.rand(batch, action_points, 3, generator=generator) * 0.1 + torch.tensor([0.4, 0.0, 0.2])
    anchor = torch.rand(batch, anchor_points, 3, generator=generator) * torch.tensor([0.5, 0.5, 0.4])
    rotation = se3.random_rotation(batch, generator=generator)
    translation = torch.randn(batch, 3, generator=generator) * 0.1
    return {"action": action, "anchor": anchor, "gt_transform": se3.make_transform(rotation, translation)}


def _median_seconds(step: Callable[[], Any], repeats: int, warmup: int) -> tuple[float, float]:
    """Median wall time and median process CPU time (all threads) of ``step``, in seconds.

    CPU time is what the step costs this process; on a busy machine it is the
    steadier figure (wall time also counts waiting for a core).
    """
    for _ in range(warmup):
        step()
    wall, cpu = [], []
    for _ in range(repeats):
        start_wall, start_cpu = time.perf_counter(), time.process_time()
        step()
        wall.append(time.perf_counter() - start_wall)
        cpu.append(time.process_time() - start_cpu)
    return statistics.median(wall), statistics.median(cpu)


def measure(name: str, size: str, repeats: int, warmup: int, seed: int = 0) -> dict[str, Any]:
    """One row of the table: model ``name`` at ``size`` ("default" or "reference")."""
    config = MODEL_CONFIGS[name]() if size == "default" else MODEL_CONFIGS[name].reference()
    model = build_model(name, config)
    action_points, anchor_points = POINT_COUNTS[size]
    sample = _random_batch(1, action_points, anchor_points, seed)
    batch = _random_batch(TRAIN_BATCH, action_points, anchor_points, seed + 1)

    model.eval()

    def infer() -> None:
        with torch.no_grad():
            model(sample["action"], sample["anchor"])

    infer_s, infer_cpu_s = _median_seconds(infer, repeats, warmup)

    model.train()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-4)

    def train_step() -> None:
        output = model(batch["action"], batch["anchor"])
        loss, _ = compute_loss(output, batch, TRAINING_PRESET[name])
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()

    train_s, train_cpu_s = _median_seconds(train_step, repeats, warmup)
    encoder = config.taxpose.encoder if name == "weightedpose" else config.encoder
    return {
        "model": name,
        "size": size,
        "params": sum(p.numel() for p in model.parameters()),
        "infer_ms": infer_s * 1000.0,
        "train_step_s": train_s,
        "infer_cpu_ms": infer_cpu_s * 1000.0,
        "train_step_cpu_s": train_cpu_s,
        "action_points": action_points,
        "anchor_points": anchor_points,
        "train_batch": TRAIN_BATCH,
        "k": encoder.k,
        "emb_dim": encoder.emb_dim,
        "loss_preset": TRAINING_PRESET[name],
        "repeats": repeats,
    }


def run(
    json_path: str | Path | None = None,
    repeats: int = 5,
    reference_repeats: int = 1,
    threads: int = 2,
    models: tuple[str, ...] = MODEL_NAMES,
    sizes: tuple[str, ...] = ("default", "reference"),
) -> list[dict[str, Any]]:
    """Measure every (model, size), print a table, optionally write a JSON list of the rows.

    repeats: timed runs at the default size (after one warm-up run);
    reference_repeats: timed runs at the reference size (no warm-up, it is slow).
    threads: torch intra-op threads for the measurement (restored afterwards).
    """
    unknown = sorted(set(models) - set(MODEL_NAMES)) + sorted(set(sizes) - set(POINT_COUNTS))
    if unknown:
        raise ValueError(f"unknown model(s)/size(s) {unknown}; models: {MODEL_NAMES}, sizes: {tuple(POINT_COUNTS)}")
    if repeats < 1 or reference_repeats < 1 or threads < 1:
        raise ValueError("repeats, reference_repeats and threads must be >= 1")
    previous_threads = torch.get_num_threads()
    torch.set_num_threads(threads)
    load_average = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    rows = []
    try:
        for size in sizes:
            for name in models:
                if size == "default":
                    row = measure(name, size, repeats=repeats, warmup=1)
                else:
                    row = measure(name, size, repeats=reference_repeats, warmup=0)
                row["threads"] = threads
                row["load_average_1min"] = load_average
                rows.append(row)
    finally:
        torch.set_num_threads(previous_threads)

    table = [
        [r["model"], r["size"], f"{r['action_points']}+{r['anchor_points']}", r["k"], r["emb_dim"],
         f"{r['params']:,}", f"{r['infer_ms']:.1f}", f"{r['train_step_s']:.2f}",
         f"{r['infer_cpu_ms']:.1f}", f"{r['train_step_cpu_s']:.2f}"]
        for r in rows
    ]
    headers = ["model", "size", "points", "k", "emb", "params", "infer ms (1 sample)", f"train step s (batch {TRAIN_BATCH})", "infer CPU ms", "train CPU s"]
    print(tabulate(table, headers=headers))
    print(f"threads={threads}, 1-min load average at start {load_average:.1f} (timings pessimistic if > threads)")
    if json_path is not None:
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        Path(json_path).write_text(json.dumps(rows, indent=2))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", dest="json_path", type=Path, default=None, help="write the rows to this JSON file")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--reference-repeats", type=int, default=1)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--models", nargs="+", default=list(MODEL_NAMES), choices=MODEL_NAMES)
    parser.add_argument("--sizes", nargs="+", default=["default", "reference"], choices=list(POINT_COUNTS))
    args = parser.parse_args()
    run(args.json_path, args.repeats, args.reference_repeats, args.threads, tuple(args.models), tuple(args.sizes))


if __name__ == "__main__":
    main()
