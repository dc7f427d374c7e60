"""Leaderboard from synthetic summaries in temporary results folders."""

from __future__ import annotations

import math

import pytest

from wpbench.cli.leaderboard_cmd import SORT_CHOICES
from wpbench.evaluation.leaderboard import (
    LEADERBOARD_COLUMNS,
    SORT_KEYS,
    collect_summaries,
    find_summaries,
    leaderboard_markdown,
    write_leaderboard,
)
from wpbench.evaluation.summary import summarize, wilson_interval, write_summary

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def synthetic_records(policy: str, task: str, successes: int, episodes: int, rot: float):
    return [
        {
            "episode": index,
            "seed": index,
            "task": task,
            "policy": policy,
            "object_id": f"obj-{index % 2}",
            "category": "oven",
            "success": index < successes,
            "rot_err_deg": rot + index,
            "trans_err_m": 0.01 * (index + 1),
            "point_err_m": 0.02,
            "point_mse": 0.0004,
        }
        for index in range(episodes)
    ]


def add_run(results, subdir, policy, task, successes, episodes, rot=1.0, split="val", assets="procedural"):
    summary = summarize(
        synthetic_records(policy, task, successes, episodes, rot),
        {"split": split, "asset_source": assets, "seed": 0},
    )
    return write_summary(results / subdir, summary)


@pytest.fixture
def populated_results(tmp_results):
    add_run(tmp_results, "open/wp", "wp", "open", 9, 10, rot=2.0)
    add_run(tmp_results, "open/gf", "gf", "open", 6, 10, rot=5.0)
    add_run(tmp_results, "open/identity", "identity", "open", 0, 10, rot=90.0)
    add_run(tmp_results, "place/deep/nested/wp", "wp", "place", 4, 8, rot=3.0)
    add_run(tmp_results, "place/tp", "tp", "place", 7, 8, rot=1.0)
    return tmp_results


def test_finds_summaries_recursively_and_skips_hidden_and_archived_folders(populated_results):
    add_run(populated_results, ".scratch/wp", "wp", "open", 1, 1)
    add_run(populated_results, "archive/generator-v2/runs/wp", "wp", "open", 1, 1)
    add_run(populated_results, "archived/wp", "wp", "open", 1, 1)  # only a folder named exactly "archive"
    found = find_summaries(populated_results)
    assert len(found) == 6
    assert all(".scratch" not in str(path) and "/archive/" not in str(path) for path in found)


def test_collected_table_has_one_row_per_run_with_its_numbers(populated_results):
    frame, skipped = collect_summaries(populated_results)
    assert skipped == []
    assert list(frame.columns) == list(LEADERBOARD_COLUMNS)
    assert len(frame) == 5
    wp_place = frame[(frame.policy == "wp") & (frame.task == "place")].iloc[0]
    assert wp_place.episodes == 8 and wp_place.successes == 4
    assert wp_place.success_rate == 0.5
    low, high = wilson_interval(4, 8)
    assert (wp_place.success_ci95_low, wp_place.success_ci95_high) == pytest.approx((low, high))
    assert wp_place.rot_err_deg_mean == pytest.approx(3.0 + 3.5)
    assert wp_place.run == "place/deep/nested/wp"
    assert (wp_place.split, wp_place.asset_source) == ("val", "procedural")


def test_default_order_is_by_task_then_best_success_first(populated_results):
    frame, _ = collect_summaries(populated_results)
    assert list(zip(frame.task, frame.policy)) == [
        ("open", "wp"), ("open", "gf"), ("open", "identity"), ("place", "tp"), ("place", "wp"),
    ]
    by_rotation, _ = collect_summaries(populated_results, sort_by="rot")
    assert list(by_rotation[by_rotation.task == "open"].policy) == ["wp", "gf", "identity"]
    with pytest.raises(ValueError, match="valid"):
        collect_summaries(populated_results, sort_by="speed")


def test_writes_markdown_csv_and_png(populated_results):
    pd = pytest.importorskip("pandas")
    files = write_leaderboard(populated_results)
    assert files.runs == 5
    assert files.markdown == populated_results / "leaderboard.md"

    markdown = files.markdown.read_text()
    table_rows = [line for line in markdown.splitlines() if line.startswith("| ") and "`" in line]
    assert len(table_rows) == 5
    low, high = wilson_interval(9, 10)
    assert f"90.0% [{100 * low:.1f}, {100 * high:.1f}]" in markdown
    assert "`identity`" in markdown and "`place/tp`" in markdown

    csv = pd.read_csv(files.csv)
    assert len(csv) == 5
    assert set(csv.policy) == {"wp", "gf", "identity", "tp"}
    assert csv.loc[csv.policy == "identity", "success_rate"].item() == 0.0

    png = files.png.read_bytes()
    assert png.startswith(PNG_MAGIC) and len(png) > 5_000


def test_rerunning_does_not_pick_up_its_own_outputs(populated_results):
    first = write_leaderboard(populated_results)
    second = write_leaderboard(populated_results)
    assert first.runs == second.runs == 5


def test_out_dir_and_differing_splits_are_handled(populated_results, tmp_path):
    add_run(populated_results, "open/wp-real", "wp", "open", 2, 5, split="test", assets="../shared/partnet-mobility")
    files = write_leaderboard(populated_results, out_dir=tmp_path / "board")
    assert files.csv.parent == tmp_path / "board" and files.png.exists()
    markdown = files.markdown.read_text()
    assert "| partnet-mobility " in markdown and "../shared" not in markdown  # folder shown by name
    assert "../shared/partnet-mobility" in files.csv.read_text()  # the csv keeps the full value
    assert not (populated_results / "leaderboard.md").exists()


def test_unreadable_summary_is_reported_and_skipped(populated_results):
    broken = populated_results / "broken" / "summary.json"
    broken.parent.mkdir()
    broken.write_text("{ not json")
    warnings_seen = []
    files = write_leaderboard(populated_results, on_warning=warnings_seen.append)
    assert files.runs == 5 and files.skipped == (broken,)
    assert any("broken" in text for text in warnings_seen)
    assert "Unreadable summaries" in files.markdown.read_text()


def test_empty_or_missing_results_is_an_error_and_writes_nothing(tmp_results, tmp_path):
    with pytest.raises(FileNotFoundError, match="wpbench run"):
        write_leaderboard(tmp_results)
    assert not (tmp_results / "leaderboard.md").exists()
    with pytest.raises(FileNotFoundError, match="does not exist"):
        write_leaderboard(tmp_path / "nowhere")


def test_run_without_episodes_is_listed_as_not_available(tmp_results):
    write_summary(tmp_results / "empty", summarize([], {"policy": "gt", "task": "open", "split": "val"}))
    add_run(tmp_results, "open/wp", "wp", "open", 1, 2)
    frame, _ = collect_summaries(tmp_results)
    empty = frame[frame.policy == "gt"].iloc[0]
    assert empty.episodes == 0 and math.isnan(empty.success_rate)
    files = write_leaderboard(tmp_results)
    assert "n/a" in files.markdown.read_text()


def test_cli_sort_choices_match_the_library():
    assert set(SORT_CHOICES) == set(SORT_KEYS)


def test_the_executor_is_a_column_and_older_runs_count_as_ideal(tmp_results):
    record = {"episode": 0, "seed": 0, "task": "open-door", "policy": "gt", "object_id": "o", "category": "oven",
              "success": True, "rot_err_deg": 0.0, "trans_err_m": 0.0, "point_err_m": 0.0, "point_mse": 0.0}
    write_summary(tmp_results / "old", summarize([record], {"split": "val", "asset_source": "procedural"}))
    write_summary(tmp_results / "new", summarize([record], {"split": "val", "asset_source": "procedural",
                                                            "executor": "gripper"}))
    frame, _ = collect_summaries(tmp_results, sort_by="policy")
    assert sorted(frame["executor"]) == ["gripper", "ideal"]
    header = next(line for line in leaderboard_markdown(frame).splitlines() if line.startswith("| task"))
    assert [cell.strip() for cell in header.split("|")][5:7] == ["obs", "executor"]


def _episode(index, object_id, success, reason=""):
    stage = {"kind": "articulated", "success": success, "failure_reason": "" if success else reason}
    return {"episode": index, "seed": index, "task": "open-door", "policy": "p", "object_id": object_id,
            "category": "oven", "success": success, "stages": [stage],
            "rot_err_deg": 1.0, "trans_err_m": 0.01, "point_err_m": 0.01, "point_mse": 1e-4}


def test_instances_their_interval_and_the_most_common_failure_reach_the_leaderboard(tmp_results):
    # Four instances, five episodes each; two instances always fail. Outcomes cluster by
    # instance, so the instance interval must be wider than the Wilson one.
    records = []
    for i in range(20):
        object_id = f"oven-{i % 4}"
        ok = i % 4 < 2
        records.append(_episode(i, object_id, ok, "not_open_enough" if i % 2 else "slipped"))
    records[2]["stages"][0]["failure_reason"] = "policy error: RuntimeError: boom"
    summary = summarize(records, {"split": "val", "asset_source": "procedural"})
    assert summary["objects"] == 4
    assert summary["failure_reasons"] == {"not_open_enough": 5, "slipped": 4, "policy error": 1}
    wilson_low, wilson_high = summary["success_ci95"]
    low, high = summary["success_instance_ci95"]
    assert high - low > wilson_high - wilson_low
    assert 0.0 <= low < 0.5 < high <= 1.0
    write_summary(tmp_results / "run", summary)
    frame, _ = collect_summaries(tmp_results)
    row = frame.iloc[0]
    assert row["instances"] == 4 and row["top_failure"] == "not_open_enough"
    assert row["success_instance_ci95_low"] == low
    table = leaderboard_markdown(frame)
    assert f"[{100 * low:.1f}, {100 * high:.1f}]" in table and "not_open_enough" in table


def test_refresh_recomputes_an_old_summary_from_its_episodes(tmp_path, wpbench_exe):
    import json
    import subprocess
    run = tmp_path / "results" / "old-run"
    records = [_episode(i, f"oven-{i % 2}", i % 2 == 0, "slipped") for i in range(6)]
    write_summary(run, summarize(records, {"split": "val", "asset_source": "procedural", "obs": "mesh",
                                           "timings": {"peak_rss_mib": 512.0}}))
    (run / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    old = json.loads((run / "summary.json").read_text())
    for key in ("success_instance_ci95", "failure_reasons"):
        del old[key]
    old["format_version"] = 1
    (run / "summary.json").write_text(json.dumps(old))
    result = subprocess.run([str(wpbench_exe), "leaderboard", "--results", str(tmp_path / "results"),
                             "--refresh", "--quiet"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    new = json.loads((run / "summary.json").read_text())
    assert new["format_version"] == 2 and new["failure_reasons"] == {"slipped": 3}
    assert new["meta"]["obs"] == "mesh" and new["timings"]["run"]["peak_rss_mib"] == 512.0
    assert new["created_utc"] == old["created_utc"]
    assert "slipped" in (tmp_path / "results" / "leaderboard.md").read_text()


def _record_furniture(run_dir, assets, generator):
    import json

    (run_dir / "run.json").write_text(json.dumps({"assets": assets, "furniture_generator": generator}))


def test_runs_on_another_furniture_version_are_left_out_with_the_reason(populated_results):
    from wpbench.assets.procedural import GENERATOR_VERSION

    old = add_run(populated_results, "open/old-wp", "wp", "open", 0, 10).parent
    _record_furniture(old, "procedural", GENERATOR_VERSION - 1)
    current = add_run(populated_results, "open/new-wp", "wp", "open", 10, 10).parent
    _record_furniture(current, "procedural", GENERATOR_VERSION)
    real = add_run(populated_results, "open/real-wp", "wp", "open", 5, 10, assets="/data/partnet").parent
    _record_furniture(real, "/data/partnet", None)
    with pytest.warns(UserWarning, match=f"generator version {GENERATOR_VERSION - 1}.*results/archive/"):
        frame, skipped = collect_summaries(populated_results)
    assert skipped == [old / "summary.json"]
    assert set(frame.run) >= {"open/new-wp", "open/real-wp"} and "open/old-wp" not in set(frame.run)
    text = leaderboard_markdown(frame, skipped)
    assert "another generator version left out" in text and "open/old-wp" in text
    assert "Unreadable" not in text
