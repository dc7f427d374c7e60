"""Episode records (episodes.jsonl / run.json) and run summaries (summary.json)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from wpbench.evaluation.records import (
    EPISODES_FILE,
    REQUIRED_KEYS,
    RUN_CONFIG_FILE,
    EpisodeWriter,
    RecordFormatError,
    RunMismatchError,
    read_episodes,
)
from wpbench.evaluation.summary import (
    format_summary_table,
    load_summary,
    summarize,
    wilson_interval,
    write_summary,
)

CONFIG = {"policy": "wp", "task": "open-then-place", "split": "val", "seed": 0, "episodes": 4}


def make_record(episode: int, success: bool = True, rot: float = 1.0, trans: float = 0.01, **extra):
    record = {
        "episode": episode,
        "seed": 1000 + episode,
        "task": "open-then-place",
        "policy": "wp",
        "object_id": f"oven-{episode % 3}",
        "category": "oven" if episode % 2 == 0 else "microwave",
        "success": success,
        "rot_err_deg": rot,
        "trans_err_m": trans,
        "point_err_m": trans * 1.5,
        "point_mse": (trans * 1.5) ** 2,
    }
    record.update(extra)
    return record


def strict_json_loads(text: str):
    """json.loads that rejects NaN/Infinity, which are not JSON."""

    def reject(constant: str):
        raise ValueError(f"non-JSON constant {constant}")

    return json.loads(text, parse_constant=reject)


# --- writer ------------------------------------------------------------------


def test_writer_appends_one_json_line_per_episode_and_stores_run_config(tmp_path):
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        for episode in range(3):
            writer.write(make_record(episode))
    lines = (tmp_path / EPISODES_FILE).read_text().splitlines()
    assert [strict_json_loads(line)["episode"] for line in lines] == [0, 1, 2]
    assert json.loads((tmp_path / RUN_CONFIG_FILE).read_text()) == CONFIG
    assert [r["seed"] for r in read_episodes(tmp_path)] == [1000, 1001, 1002]


def test_writer_fsyncs_every_record(tmp_path, monkeypatch):
    synced = []
    real_fsync = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: (synced.append(fd), real_fsync(fd)))
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        writer.write(make_record(0))
        assert len(synced) == 1
        # Durable before the next episode starts: another reader sees it now.
        assert len(read_episodes(tmp_path)) == 1
        writer.write(make_record(1))
    assert len(synced) == 2


def test_nan_errors_are_written_as_null_and_read_back_as_nan(tmp_path):
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        writer.write(make_record(0, success=False, rot=float("nan"), trans=float("inf")))
    stored = strict_json_loads((tmp_path / EPISODES_FILE).read_text())
    assert stored["rot_err_deg"] is None and stored["trans_err_m"] is None
    (record,) = read_episodes(tmp_path / EPISODES_FILE)
    assert math.isnan(record["rot_err_deg"]) and math.isnan(record["trans_err_m"])


def test_numpy_values_are_stored_as_plain_json(tmp_path):
    np = pytest.importorskip("numpy")
    record = make_record(0, success=np.bool_(True), rot=np.float32(2.5))
    record["episode"] = np.int64(0)
    record["final_pose"] = np.eye(4)
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        writer.write(record)
    (stored,) = read_episodes(tmp_path)
    assert stored["success"] is True and stored["rot_err_deg"] == 2.5
    assert stored["final_pose"][3] == [0.0, 0.0, 0.0, 1.0]


@pytest.mark.parametrize("missing", REQUIRED_KEYS)
def test_record_missing_a_required_key_is_rejected(tmp_path, missing):
    record = make_record(0)
    del record[missing]
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        with pytest.raises(RecordFormatError, match=missing):
            writer.write(record)
    assert read_episodes(tmp_path) == []


def test_duplicate_episode_is_rejected(tmp_path):
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        writer.write(make_record(0))
        with pytest.raises(RecordFormatError, match="already recorded"):
            writer.write(make_record(0))


def test_existing_run_is_not_appended_to_without_resume(tmp_path):
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        writer.write(make_record(0))
    with pytest.raises(FileExistsError, match="--resume"):
        EpisodeWriter(tmp_path, CONFIG)


def test_resume_reports_completed_episodes_and_continues(tmp_path):
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        for episode in (0, 1, 3):
            writer.write(make_record(episode))
    # Asking for more episodes is the same run.
    with EpisodeWriter(tmp_path, {**CONFIG, "episodes": 10}, resume=True) as writer:
        assert writer.completed_episodes() == {0, 1, 3}
        writer.write(make_record(2))
        assert writer.completed_episodes() == {0, 1, 2, 3}
    assert sorted(r["episode"] for r in read_episodes(tmp_path)) == [0, 1, 2, 3]


@pytest.mark.parametrize("key, value", [("policy", "tp"), ("task", "open"), ("split", "test"), ("seed", 1),
                                        # retrained weights or rebuilt furniture make a different run too
                                        ("policy_weights", ["0f1e2d3c4b5a6978"]), ("furniture_generator", 99),
                                        # a run.json without it was made at executor version 1
                                        ("executor_version", 2)])
def test_resume_refuses_a_different_run(tmp_path, key, value):
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        writer.write(make_record(0))
    with pytest.raises(RunMismatchError, match=key):
        EpisodeWriter(tmp_path, {**CONFIG, key: value}, resume=True)


def test_a_record_drawn_from_other_furniture_is_refused_and_the_earlier_ones_kept(tmp_path):
    # A worker that skipped an object draws other furniture for the same seeds.
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        writer.write(make_record(0, furniture_pool="aaaa"))
        writer.write(make_record(1))  # a failure record made without an env names no pool
        with pytest.raises(RunMismatchError, match=r"episode 2 .*other furniture \(pool bbbb\) than episode 0 "):
            writer.write(make_record(2, furniture_pool="bbbb"))
        writer.write(make_record(3, furniture_pool="aaaa"))
    assert [r["episode"] for r in read_episodes(tmp_path)] == [0, 1, 3]


def test_resume_refuses_a_file_that_mixes_furniture_pools(tmp_path):
    lines = [make_record(0, furniture_pool="aaaa"), make_record(1, furniture_pool="bbbb")]
    (tmp_path / RUN_CONFIG_FILE).write_text(json.dumps(CONFIG))
    (tmp_path / EPISODES_FILE).write_text("".join(json.dumps(r) + "\n" for r in lines))
    with pytest.raises(RunMismatchError, match="other furniture"):
        EpisodeWriter(tmp_path, CONFIG, resume=True)
    with EpisodeWriter(tmp_path / "same", CONFIG) as writer:  # one pool throughout is fine
        writer.write(make_record(0, furniture_pool="aaaa"))
    with EpisodeWriter(tmp_path / "same", CONFIG, resume=True) as writer:
        writer.write(make_record(1, furniture_pool="aaaa"))
        with pytest.raises(RunMismatchError, match="other furniture"):
            writer.write(make_record(2, furniture_pool="cccc"))


def test_resume_refuses_episodes_without_run_config(tmp_path):
    (tmp_path / EPISODES_FILE).write_text(json.dumps(make_record(0)) + "\n")
    with pytest.raises(RunMismatchError, match=RUN_CONFIG_FILE):
        EpisodeWriter(tmp_path, CONFIG, resume=True)


def test_resume_drops_a_truncated_last_line(tmp_path):
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        for episode in range(3):
            writer.write(make_record(episode))
    path = tmp_path / EPISODES_FILE
    intact = path.read_bytes()
    # A crash in the middle of writing episode 3.
    path.write_bytes(intact + json.dumps(make_record(3)).encode()[:40])

    with pytest.warns(UserWarning, match="truncated"):
        assert len(read_episodes(path)) == 3
    assert path.read_bytes() != intact  # reading alone does not repair

    with pytest.warns(UserWarning, match="truncated"):
        writer = EpisodeWriter(tmp_path, CONFIG, resume=True)
    with writer:
        assert writer.completed_episodes() == {0, 1, 2}
        assert path.read_bytes() == intact
        writer.write(make_record(3))
    assert [r["episode"] for r in read_episodes(path)] == [0, 1, 2, 3]


def test_a_damaged_line_before_the_end_is_an_error(tmp_path):
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        writer.write(make_record(0))
    path = tmp_path / EPISODES_FILE
    path.write_text("{not json\n" + path.read_text())
    with pytest.raises(RecordFormatError, match=":1:"):
        read_episodes(path)
    with pytest.raises(RecordFormatError):
        EpisodeWriter(tmp_path, CONFIG, resume=True)


finite_or_nan = st.one_of(st.floats(min_value=0, max_value=1e3, allow_nan=False), st.just(float("nan")))


@given(
    rows=st.lists(
        st.tuples(st.booleans(), finite_or_nan, finite_or_nan, st.sampled_from(["oven", "fridge"])),
        max_size=12,
    )
)
def test_records_round_trip_through_the_file(tmp_path_factory, rows):
    out_dir = tmp_path_factory.mktemp("run")
    written = []
    with EpisodeWriter(out_dir, CONFIG) as writer:
        for index, (success, rot, trans, category) in enumerate(rows):
            record = make_record(index, success=success, rot=rot, trans=trans, category=category)
            writer.write(record)
            written.append(record)
    read = read_episodes(out_dir)
    assert len(read) == len(written)
    for original, stored in zip(written, read):
        for key, value in original.items():
            if isinstance(value, float) and math.isnan(value):
                assert math.isnan(stored[key])
            else:
                assert stored[key] == value


# --- Wilson interval ---------------------------------------------------------


@pytest.mark.parametrize(
    "successes, n, expected",
    [
        # Closed forms: k=0 -> [0, z^2/(n+z^2)]; k=n -> [n/(n+z^2), 1].
        (0, 10, (0.0, 1.959963984540054**2 / (10 + 1.959963984540054**2))),
        (10, 10, (10 / (10 + 1.959963984540054**2), 1.0)),
        # 4-decimal values worked by hand from the Wilson formula.
        (8, 10, (0.4902, 0.9433)),
        (1, 2, (0.0945, 0.9055)),
    ],
)
def test_wilson_interval_known_values(successes, n, expected):
    low, high = wilson_interval(successes, n)
    assert low == pytest.approx(expected[0], abs=5e-5)
    assert high == pytest.approx(expected[1], abs=5e-5)


@given(n=st.integers(1, 500), data=st.data())
def test_wilson_interval_properties(n, data):
    k = data.draw(st.integers(0, n))
    low, high = wilson_interval(k, n)
    assert 0.0 <= low <= k / n <= high <= 1.0
    # Swapping successes and failures mirrors the interval.
    mirror_low, mirror_high = wilson_interval(n - k, n)
    assert low == pytest.approx(1 - mirror_high, abs=1e-12)
    assert high == pytest.approx(1 - mirror_low, abs=1e-12)


def test_wilson_interval_agrees_with_scipy():
    stats = pytest.importorskip("scipy.stats")
    for k, n in [(3, 7), (37, 50), (99, 100), (1, 400)]:
        reference = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
        assert wilson_interval(k, n) == pytest.approx((reference.low, reference.high), abs=1e-9)


def test_wilson_interval_rejects_impossible_counts_and_is_undefined_for_no_trials():
    with pytest.raises(ValueError):
        wilson_interval(3, 2)
    assert all(math.isnan(bound) for bound in wilson_interval(0, 0))


# --- summary -----------------------------------------------------------------


def test_summary_rates_errors_and_categories():
    records = [
        make_record(0, success=True, rot=2.0, trans=0.01, success_once=True, success_at_end=True),
        make_record(1, success=False, rot=10.0, trans=0.05, success_once=True, success_at_end=False),
        make_record(2, success=True, rot=4.0, trans=0.02, success_once=True, success_at_end=True),
        make_record(3, success=False, rot=30.0, trans=0.30, success_once=False, success_at_end=False),
    ]
    summary = summarize(records, {"split": "val", "asset_source": "procedural", "seed": 0, "checkpoint": "a.pt"})
    assert (summary["policy"], summary["task"], summary["split"]) == ("wp", "open-then-place", "val")
    assert summary["asset_source"] == "procedural"
    assert summary["episodes"] == 4 and summary["successes"] == 2
    assert summary["success_rate"] == 0.5
    assert summary["success_ci95"] == pytest.approx(list(wilson_interval(2, 4)))
    assert summary["success_once_rate"] == 0.75 and summary["success_at_end_rate"] == 0.5
    assert summary["rot_err_deg"]["mean"] == pytest.approx(11.5)
    assert summary["rot_err_deg"]["median"] == pytest.approx(7.0)
    assert summary["trans_err_m"]["median"] == pytest.approx(0.035)
    assert summary["point_err_m"]["mean"] == pytest.approx(1.5 * (0.01 + 0.05 + 0.02 + 0.30) / 4)
    assert summary["rot_err_deg"]["nan_count"] == 0
    ovens = summary["per_category"]["oven"]  # episodes 0 and 2
    assert ovens["episodes"] == 2 and ovens["success_rate"] == 1.0
    assert ovens["rot_err_deg_mean"] == pytest.approx(3.0)
    assert summary["per_category"]["microwave"]["success_rate"] == 0.0
    assert summary["objects"] == 3
    assert summary["meta"] == {"checkpoint": "a.pt"}


def test_nan_errors_count_as_failures_and_are_excluded_from_means(tmp_path):
    nan = float("nan")
    records = [
        make_record(0, success=True, rot=2.0, trans=0.01),
        make_record(1, success=True, rot=nan, trans=nan),  # the task said yes; the pose is NaN
        make_record(2, success=False, rot=6.0, trans=0.03),
    ]
    summary = summarize(records, {"split": "val"})
    assert summary["successes"] == 1 and summary["nan_failures"] == 1
    assert summary["success_rate"] == pytest.approx(1 / 3)
    assert summary["rot_err_deg"] == {"mean": 4.0, "median": 4.0, "nan_count": 1, "n": 2}
    assert summary["per_category"]["microwave"]["nan_count"] == 1

    path = write_summary(tmp_path, summary)
    strict_json_loads(path.read_text())  # valid JSON: no NaN tokens
    assert load_summary(tmp_path)["rot_err_deg"]["nan_count"] == 1


def test_all_nan_errors_give_null_statistics_and_valid_json(tmp_path):
    nan = float("nan")
    summary = summarize([make_record(0, success=True, rot=nan, trans=nan)], {})
    assert summary["success_rate"] == 0.0
    assert summary["rot_err_deg"]["mean"] is None and summary["rot_err_deg"]["median"] is None
    strict_json_loads(write_summary(tmp_path, summary).read_text())


def test_empty_run_summary_is_valid(tmp_path):
    summary = summarize([], {"policy": "gt", "task": "open", "split": "val"})
    assert summary["episodes"] == 0 and summary["success_rate"] is None
    assert summary["success_ci95"] == [None, None]
    strict_json_loads(write_summary(tmp_path, summary).read_text())


def test_summary_refuses_records_of_several_policies():
    records = [make_record(0), make_record(1, policy="tp")]
    with pytest.raises(ValueError, match="policy"):
        summarize(records, {})
    # meta names the run explicitly: then it is the caller's statement.
    assert summarize(records, {"policy": "mixed"})["policy"] == "mixed"


def test_summary_aggregates_timings_and_reads_from_a_run_directory(tmp_path):
    with EpisodeWriter(tmp_path, CONFIG) as writer:
        writer.write(make_record(0, timings={"predict": 0.5, "simulate": 2.0}))
        writer.write(make_record(1, timings={"predict": 1.5, "simulate": 4.0}))
    summary = summarize(tmp_path, {"timings": {"wall_s": 9.0}})
    assert summary["timings"]["predict"] == {"mean_s": 1.0, "median_s": 1.0, "total_s": 2.0}
    assert summary["timings"]["simulate"]["total_s"] == 6.0
    assert summary["timings"]["run"] == {"wall_s": 9.0}


def test_summary_table_shows_the_headline_numbers():
    summary = summarize([make_record(0, success=True), make_record(1, success=False)], {"split": "val"})
    table = format_summary_table(summary)
    low, high = wilson_interval(1, 2)
    assert "wp" in table and "open-then-place" in table
    assert f"50.0% [{100 * low:.1f}, {100 * high:.1f}]" in table
    assert "oven" in table and "microwave" in table


def test_write_summary_replaces_atomically(tmp_path):
    first = write_summary(tmp_path, summarize([make_record(0)], {}))
    second = write_summary(tmp_path, summarize([make_record(0), make_record(1)], {}))
    assert first == second == Path(tmp_path) / "summary.json"
    assert load_summary(second)["episodes"] == 2
    assert not list(Path(tmp_path).glob("*.tmp"))
