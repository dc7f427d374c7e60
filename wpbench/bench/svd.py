"""Benchmark: wpbench's weighted Procrustes against ``roma.rigid_points_registration``.

Both solve the same stacked weighted problem (``batch`` samples of ``points``
pairs, random positive weights, a random rigid motion plus noise). The table
reports the median (and minimum) wall time of the forward pass and the median
of forward + backward (gradient with respect to the source points), the two
solvers timed alternately so both see the same background load,
and the largest absolute difference between the two answers (rotation and
translation entries), computed on a float64 copy of the problem so it measures
the algorithms, not float32 rounding; the difference in the timed dtype is
reported too.

CLI: ``python -m wpbench.bench.svd --json out.json`` (``wpbench bench svd``
calls ``run``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import roma
import torch
from tabulate import tabulate

from wpbench.geometry.procrustes import weighted_procrustes
from wpbench.geometry.se3 import random_rotation

_DTYPES = {"float32": torch.float32, "float64": torch.float64}


@dataclass(frozen=True)
class SvdBenchConfig:
    """What to time: ``batch`` problems of ``points`` weighted pairs each."""

    batch: int = 256
    points: int = 2000
    repeats: int = 20
    dtype: str = "float32"
    seed: int = 0

    def __post_init__(self) -> None:
        if self.batch < 1 or self.points < 3 or self.repeats < 1:
            raise ValueError(f"need batch >= 1, points >= 3, repeats >= 1, got {self}")
        if self.dtype not in _DTYPES:
            raise ValueError(f"dtype must be one of {sorted(_DTYPES)}, got {self.dtype!r}")


def _make_problem(config: SvdBenchConfig) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """float64 source (B, N, 3), target (B, N, 3), weights (B, N)."""
    generator = torch.Generator().manual_seed(config.seed)
    shape = (config.batch, config.points, 3)
    source = torch.randn(shape, generator=generator, dtype=torch.float64) * 0.1 + 0.5
    rotation = random_rotation(config.batch, generator=generator, dtype=torch.float64)
    translation = torch.randn(config.batch, 1, 3, generator=generator, dtype=torch.float64)
    noise = 0.005 * torch.randn(shape, generator=generator, dtype=torch.float64)
    target = source @ rotation.transpose(-1, -2) + translation + noise
    weights = torch.rand(config.batch, config.points, generator=generator, dtype=torch.float64)
    return source, target, weights


def _solve_wpbench(source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    transform = weighted_procrustes(source, target, weights)
    return transform[:, :3, :3], transform[:, :3, 3]


def _solve_roma(source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    return roma.rigid_points_registration(source, target, weights)


def _time_interleaved(steps: dict[str, Callable[[], object]], repeats: int) -> dict[str, list[float]]:
    """Wall times in ms of each step, ``repeats`` each, alternating between steps.

    Alternating (A, B, A, B, ...) instead of timing A then B means both see the
    same background load on a shared machine, so their ratio is fair.
    """
    for step in steps.values():
        step()  # warm-up: first-call allocations and LAPACK initialisation
    samples: dict[str, list[float]] = {name: [] for name in steps}
    for _ in range(repeats):
        for name, step in steps.items():
            start = time.perf_counter()
            step()
            samples[name].append((time.perf_counter() - start) * 1e3)
    return samples


def _forward_backward(solver, source, target, weights) -> Callable[[], None]:
    def step() -> None:
        src = source.detach().requires_grad_(True)
        rotation, translation = solver(src, target, weights)
        (rotation.sum() + translation.sum()).backward()

    return step


def _max_abs_diff(source, target, weights) -> float:
    with torch.no_grad():
        ours = _solve_wpbench(source, target, weights)
        theirs = _solve_roma(source, target, weights)
    return max(float((a - b).abs().max()) for a, b in zip(ours, theirs))


def run(
    batch: int = 256,
    points: int = 2000,
    repeats: int = 20,
    json_path: str | Path | None = None,
    dtype: str = "float32",
    seed: int = 0,
) -> dict:
    """Time both solvers, print a table, optionally write JSON; return the results dict.

    Keys: batch, points, repeats, dtype, seed, torch_threads, wpbench_ms, roma_ms
    (medians), wpbench_min_ms, roma_min_ms, wpbench_fwd_bwd_ms, roma_fwd_bwd_ms, speedup (roma_ms / wpbench_ms),
    max_abs_diff (float64 problem), max_abs_diff_timed_dtype, torch_version,
    roma_version.
    """
    config = SvdBenchConfig(batch=batch, points=points, repeats=repeats, dtype=dtype, seed=seed)
    source64, target64, weights64 = _make_problem(config)
    timed = [x.to(_DTYPES[config.dtype]) for x in (source64, target64, weights64)]

    with torch.no_grad():
        forward = _time_interleaved(
            {"wpbench": lambda: _solve_wpbench(*timed), "roma": lambda: _solve_roma(*timed)}, config.repeats
        )
    backward = _time_interleaved(
        {
            "wpbench": _forward_backward(_solve_wpbench, *timed),
            "roma": _forward_backward(_solve_roma, *timed),
        },
        config.repeats,
    )
    wpbench_ms, roma_ms = statistics.median(forward["wpbench"]), statistics.median(forward["roma"])
    wpbench_fb_ms, roma_fb_ms = statistics.median(backward["wpbench"]), statistics.median(backward["roma"])

    results = {
        **asdict(config),
        "torch_threads": torch.get_num_threads(),
        "wpbench_ms": wpbench_ms,
        "roma_ms": roma_ms,
        "wpbench_min_ms": min(forward["wpbench"]),
        "roma_min_ms": min(forward["roma"]),
        "wpbench_fwd_bwd_ms": wpbench_fb_ms,
        "roma_fwd_bwd_ms": roma_fb_ms,
        "speedup": roma_ms / wpbench_ms,
        "max_abs_diff": _max_abs_diff(source64, target64, weights64),
        "max_abs_diff_timed_dtype": _max_abs_diff(*timed),
        "torch_version": torch.__version__,
        "roma_version": getattr(roma, "__version__", "unknown"),
    }
    header = (
        f"weighted Procrustes, batch={config.batch}, points={config.points}, dtype={config.dtype}, "
        f"torch threads={results['torch_threads']}, median of {config.repeats}"
    )
    rows = [
        ["wpbench.weighted_procrustes", f"{wpbench_ms:.2f}", f"{results['wpbench_min_ms']:.2f}", f"{wpbench_fb_ms:.2f}"],
        ["roma.rigid_points_registration", f"{roma_ms:.2f}", f"{results['roma_min_ms']:.2f}", f"{roma_fb_ms:.2f}"],
    ]
    print(header)
    print(
        tabulate(
            rows,
            headers=["solver", "forward ms (median)", "forward ms (min)", "forward+backward ms (median)"],
            tablefmt="github",
        )
    )
    print(
        f"speedup (roma / wpbench, forward): {results['speedup']:.2f}x; "
        f"max |difference| float64: {results['max_abs_diff']:.2e}, {config.dtype}: {results['max_abs_diff_timed_dtype']:.2e}"
    )
    if json_path is not None:
        path = Path(json_path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {path}")
    return results


def main(argv: list[str] | None = None) -> dict:
    """Command-line entry point: ``python -m wpbench.bench.svd [--batch B] [--points N] ... [--json FILE]``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    defaults = SvdBenchConfig()
    parser.add_argument("--batch", type=int, default=defaults.batch)
    parser.add_argument("--points", type=int, default=defaults.points)
    parser.add_argument("--repeats", type=int, default=defaults.repeats)
    parser.add_argument("--dtype", choices=sorted(_DTYPES), default=defaults.dtype)
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--json", dest="json_path", default=None, help="write the results as JSON to this file")
    args = parser.parse_args(argv)
    return run(**vars(args))


if __name__ == "__main__":
    main()
