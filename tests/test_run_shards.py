"""``wpbench run --shard i/N`` and ``wpbench merge``: shards of a run joined give the run."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

FAST = ("--policy", "identity", "--task", "open-door", "--obs", "mesh", "--no-progress", "--workers", "1")


def wpbench(exe: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=900, stdin=subprocess.DEVNULL)


def content(run: Path) -> list[dict]:
    records = []
    for line in (run / "episodes.jsonl").read_text().splitlines():
        record = {k: v for k, v in json.loads(line).items() if k not in ("timings", "ran_on")}
        record["stages"] = [{k: v for k, v in s.items() if k != "exec_seconds"} for s in record["stages"]]
        records.append(record)
    return records


@pytest.mark.slow
def test_two_shards_merged_are_the_whole_run_and_mixed_shards_are_refused(wpbench_exe, tmp_path):
    for index in (0, 1):
        done = wpbench(wpbench_exe, "run", *FAST, "--episodes", "4", "--shard", f"{index}/2",
                       "--out", str(tmp_path / f"shard{index}"))
        assert done.returncode == 0, done.stderr
    assert [r["episode"] for r in content(tmp_path / "shard1")] == [1, 3]
    merged = wpbench(wpbench_exe, "merge", str(tmp_path / "shard0"), str(tmp_path / "shard1"),
                     "--out", str(tmp_path / "merged"))
    assert merged.returncode == 0, merged.stderr
    whole = wpbench(wpbench_exe, "run", *FAST, "--episodes", "4", "--out", str(tmp_path / "whole"))
    assert whole.returncode == 0, whole.stderr
    assert content(tmp_path / "merged") == content(tmp_path / "whole")
    summary = json.loads((tmp_path / "merged" / "summary.json").read_text())
    assert summary["episodes"] == 4

    refused = wpbench(wpbench_exe, "merge", str(tmp_path / "shard0"), str(tmp_path / "whole"), "--out",
                      str(tmp_path / "bad"))
    assert refused.returncode == 2 and "not a shard" in refused.stderr
    only_one = wpbench(wpbench_exe, "merge", str(tmp_path / "shard0"), "--out", str(tmp_path / "bad"))
    assert only_one.returncode == 2 and "once each" in only_one.stderr


def test_shards_of_different_runs_are_refused(tmp_path):
    from wpbench.evaluation.merge import merge_shards
    from wpbench.evaluation.records import RunMismatchError

    for index, seed in ((0, 0), (1, 7)):
        folder = tmp_path / f"s{index}"
        folder.mkdir()
        (folder / "run.json").write_text(json.dumps({"policy": "gt", "task": "open-door", "split": "val", "seed": seed,
                                                     "episodes": 2, "shard": f"{index}/2", "obs": "mesh"}))
        (folder / "episodes.jsonl").write_text("")
    with pytest.raises(RunMismatchError, match="seed: 0 vs 7"):
        merge_shards([tmp_path / "s0", tmp_path / "s1"], tmp_path / "merged")
