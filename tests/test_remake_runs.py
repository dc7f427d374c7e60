"""scripts/remake_runs.py as a developer runs it: which runs it repeats, in which order, with which settings."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "remake_runs.py"


def _published(root: Path, name: str, executor: str, episodes: int = 3) -> None:
    policy, task, split = name.split("__")[:3]
    folder = root / name
    folder.mkdir(parents=True)
    (folder / "run.json").write_text(json.dumps({
        "policy": policy, "task": task, "split": split, "episodes": episodes, "seed": 0, "assets": "procedural",
        "obs": "camera", "executor": executor, "camera_noise": {}}))


def _remake(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=60)


def test_repeats_the_chosen_policies_runs_cheapest_executor_first(tmp_path: Path) -> None:
    runs, out = tmp_path / "runs", tmp_path / "out"
    _published(runs, "wp__place-in__val__procedural__camera__panda", "panda")
    _published(runs, "wp__place-in__val__procedural__camera", "ideal")
    _published(runs, "wp__open-door__test__procedural__camera__gripper", "gripper")
    _published(runs, "gf__place-in__val__procedural__camera", "ideal")
    done = _remake(str(out), "wp", "--runs", str(runs), "--weights-root", "/w", "--dry-run")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert [line.split("--out ")[1].split()[0] for line in lines] == [
        str(out / "wp__place-in__val__procedural__camera"),
        str(out / "wp__open-door__test__procedural__camera__gripper"),
        str(out / "wp__place-in__val__procedural__camera__panda"),
    ]
    assert "--executor panda" in lines[2] and "--split test" in lines[1] and lines[0].endswith("--weights-root /w")


def test_skips_a_complete_run_and_keeps_only_the_given_suffixes(tmp_path: Path) -> None:
    runs, out = tmp_path / "runs", tmp_path / "out"
    _published(runs, "wp__place-in__val__procedural__camera", "ideal", episodes=2)
    _published(runs, "wp__open-door__val__procedural__camera", "ideal", episodes=2)
    _published(runs, "wp__open-door__val__procedural__camera__panda", "panda", episodes=2)
    complete = out / "wp__place-in__val__procedural__camera"
    complete.mkdir(parents=True)
    (complete / "summary.json").write_text("{}")
    (complete / "episodes.jsonl").write_text("{}\n{}\n")
    done = _remake(str(out), "wp", "--runs", str(runs), "--only", "__camera", "--dry-run")
    assert done.returncode == 0, done.stderr
    expected = (f"wpbench run --policy wp --task open-door --split val --episodes 2 --seed 0 --assets procedural "
                f"--obs camera --executor ideal --out {out / 'wp__open-door__val__procedural__camera'} "
                "--resume --workers 2 --no-progress")
    assert done.stdout.splitlines()[0] == expected
    assert "complete: wp__place-in__val__procedural__camera" in done.stdout
    assert "panda" not in done.stdout


def test_no_matching_run_is_a_one_line_error(tmp_path: Path) -> None:
    (tmp_path / "runs").mkdir()
    done = _remake(str(tmp_path / "out"), "wp", "--runs", str(tmp_path / "runs"))
    assert done.returncode == 2 and "no run of wp" in done.stderr
