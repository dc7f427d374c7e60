"""Run published runs again, each with the settings its own run.json records, into another folder.

Used when weights are scored against a release (``--weights-root`` of a candidate) and when a release
is shipped (every run of the shipped policies made again). Runs whose folder name starts with one of
POLICIES are taken, optionally only those whose name ends with one of ``--only``'s suffixes, cheapest
executor first (ideal, gripper, panda). A run already complete in OUT is skipped and a partial one is
resumed, so the script can be stopped and started again. results/runs itself is never written.

    python scripts/remake_runs.py /work/candidate-runs wp --weights-root /work/candidate \\
        --only __val__procedural__camera,__val__partnet-mobility__camera
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from wpbench.evaluation.records import EPISODES_FILE, stored_run_config
from wpbench.evaluation.summary import SUMMARY_FILE

EXECUTOR_ORDER = {"ideal": 0, "gripper": 1, "panda": 2}


def run_command(settings: dict, out: Path, weights_root: Path | None, workers: int) -> list[str]:
    """The `wpbench run` command line that repeats a run with these run.json settings into ``out``."""
    if settings.get("camera_noise"):
        raise ValueError(f"{out.name}: runs with camera noise are not handled; run it by hand")
    command = ["wpbench", "run", "--policy", settings["policy"], "--task", settings["task"],
               "--split", settings["split"], "--episodes", str(settings["episodes"]), "--seed", str(settings["seed"]),
               "--assets", settings["assets"], "--obs", settings["obs"], "--executor", settings["executor"],
               "--out", str(out), "--resume", "--workers", str(workers), "--no-progress"]
    if weights_root is not None:
        command += ["--weights-root", str(weights_root)]
    return command


def is_complete(folder: Path, episodes: int) -> bool:
    records = folder / EPISODES_FILE
    if not (folder / SUMMARY_FILE).exists() or not records.exists():
        return False
    with records.open() as handle:
        return sum(1 for _ in handle) == episodes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="folder to write the runs into")
    parser.add_argument("policies", nargs="+", help="policies whose runs to make again")
    parser.add_argument("--runs", type=Path, default=Path("results/runs"), help="published runs [results/runs]")
    parser.add_argument("--only", help="comma-separated suffixes of run names to keep")
    parser.add_argument("--weights-root", type=Path, help="weights to score instead of the shipped ones")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    args = parser.parse_args()
    if not args.runs.is_dir():
        parser.error(f"{args.runs} is not a folder of runs; run from the repository root or give --runs")

    suffixes = tuple(args.only.split(",")) if args.only else None
    chosen = []
    for folder in sorted(args.runs.iterdir()):
        if folder.name.split("__")[0] not in args.policies or (suffixes and not folder.name.endswith(suffixes)):
            continue
        settings = stored_run_config(folder)
        if settings is not None:
            chosen.append((settings, folder.name))
    if not chosen:
        parser.error(f"no run of {', '.join(args.policies)} in {args.runs} matches")
    chosen.sort(key=lambda item: (EXECUTOR_ORDER.get(item[0]["executor"], 9), item[1]))

    for settings, name in chosen:
        target = args.out / name
        if is_complete(target, settings["episodes"]):
            print(f"complete: {name}", flush=True)
            continue
        command = run_command(settings, target, args.weights_root, args.workers)
        print(" ".join(command), flush=True)
        if not args.dry_run:
            done = subprocess.run(command)
            if done.returncode != 0:
                sys.exit(f"{name}: wpbench run failed (exit {done.returncode}); run this script again to resume it")


if __name__ == "__main__":
    main()
