"""The paper table: layout, numbers in the right cells, missing weights and runs said plainly."""

from __future__ import annotations

import math
from pathlib import Path

from wpbench.evaluation.paper_table import KINDS, SPLITS, PaperTableConfig, make_paper_table, render, training_data


def test_render_puts_each_number_in_its_cell():
    cfg = PaperTableConfig(policies=("gf", "tp"))
    errors = {"gf": {(s, k): {"rot_deg": 1.25 if k == "articulated" else 40.0, "trans_m": 0.012,
                              "point_m": 0.034, "n": 10} for s in SPLITS for k in KINDS}}
    successes = {("gf", "ideal", "open-door"): {"success_rate": 0.9, "success_ci95": [0.8, 0.95], "episodes": 100}}
    text = render(cfg, errors, successes)
    gf_row = next(line for line in text.splitlines() if line.startswith("| gf |") and "/" in line)
    cells = [c.strip() for c in gf_row.strip("|").split("|")][1:]
    assert cells == ["40.0 / 1.2 / 3.4", "1.2 / 1.2 / 3.4"] * 2
    assert "| tp | no weights" in text
    assert "90% [80, 95] (n=100)" in text and "not run" in text


def test_nan_errors_are_not_numbers():
    cfg = PaperTableConfig(policies=("gf",))
    errors = {"gf": {(s, k): {"rot_deg": math.nan, "trans_m": math.nan, "point_m": math.nan, "n": 0}
                     for s in SPLITS for k in KINDS}}
    assert "n/a / n/a / n/a" in render(cfg, errors, {})


def test_missing_weights_give_a_table_that_says_so(tmp_path: Path):
    cfg = PaperTableConfig(data=tmp_path, policies=("no-such-policy",), run_missing=False, results=tmp_path)
    out = make_paper_table(cfg)
    assert "no-such-policy | no weights" in out.read_text()


def test_the_table_names_what_each_policy_was_trained_on():
    # The train columns are the table's data set, not necessarily the one a policy trained on.
    import json

    from wpbench.weights import shipped_weights_root

    cfg = PaperTableConfig(data=Path("data-g9"), policies=("gf", "oracle"))
    recorded = json.loads((shipped_weights_root() / "gf" / "config.json").read_text())["data"]
    gf = training_data(cfg, "gf")
    assert gf == f"trained on {recorded['path']} (train hash {recorded['train_manifest_hash']})"
    oracle = training_data(cfg, "oracle")
    assert oracle.startswith(f"free-floating: tp trained on ") and f"articulated: gf {gf}" in oracle
    text = render(cfg, {}, {}, trained_on={"gf": gf, "oracle": oracle})
    assert "`data-g9`'s train split" in text and f"| gf | {gf} |" in text and f"| oracle | {oracle} |" in text
    assert "its weights were" not in render(cfg, {}, {})


def test_the_table_says_when_a_policy_was_trained_with_door_goals_past_the_stop(tmp_path, monkeypatch):
    import json

    import wpbench.weights
    from wpbench.weights import shipped_weights_root

    shipped = json.loads((shipped_weights_root() / "gf" / "config.json").read_text())
    (tmp_path / "gf").mkdir()
    (tmp_path / "gf" / "config.json").write_text(json.dumps(
        {**shipped, "train_config": {**shipped.get("train_config", {}), "door_past_stop_deg": 10.0}}))
    monkeypatch.setattr(wpbench.weights, "shipped_weights_root", lambda: tmp_path)
    text = training_data(PaperTableConfig(policies=("gf",)), "gf")
    assert text.startswith("trained on ") and text.endswith(", door goals 10 deg past the stop")
    (tmp_path / "gf" / "config.json").write_text(json.dumps(
        {**shipped, "train_config": {**shipped.get("train_config", {}), "door_past_stop_deg": 20.0,
                                     "door_max_turn_deg": 150.0}}))
    text = training_data(PaperTableConfig(policies=("gf",)), "gf")
    assert text.endswith(", door goals 20 deg past the stop (at most 150 deg in all)")


def test_category_rows_show_each_category_of_each_kind():
    cfg = PaperTableConfig(policies=("gf",))
    by_category = {"gf": {"articulated": {"oven": {"rot_deg": 2.5, "trans_m": 0.031, "point_m": 0.03, "n": 5},
                                          "fridge": {"rot_deg": 30.0, "trans_m": 0.2, "point_m": 0.2, "n": 5}},
                          "free-floating": {"oven": {"rot_deg": 9.0, "trans_m": 0.05, "point_m": 0.05, "n": 5}}}}
    text = render(cfg, {}, {}, by_category)
    header = next(line for line in text.splitlines() if line.startswith("| policy | kind |"))
    assert [c.strip() for c in header.strip("|").split("|")] == ["policy", "kind", "fridge", "oven"]
    assert "| gf | articulated | 30.0 / 20.0 | 2.5 / 3.1 |" in text
    assert "| gf | free-floating | - | 9.0 / 5.0 |" in text


def test_real_object_runs_get_their_own_section_only_when_there_are_some():
    cfg = PaperTableConfig(policies=("gf", "wp-postsvd"))
    built_in = {("gf", "ideal", "open-door"): {"success_rate": 0.9, "success_ci95": [0.8, 0.95], "episodes": 100}}
    real = {("wp-postsvd", "ideal", "place-in"): {"success_rate": 0.65, "success_ci95": [0.43, 0.82], "episodes": 20}}
    assert "PartNet-Mobility" not in render(cfg, {}, built_in)
    lines = render(cfg, {}, built_in, real_successes=real).splitlines()
    start = next(i for i, line in enumerate(lines) if "real PartNet-Mobility" in line)
    section = lines[start:]
    assert "| wp-postsvd | ideal | not run | 65% [43, 82] (n=20) | not run |" in section
    assert "| gf | ideal | not run | not run | not run |" in section  # the built-in 90% stays in its own table
    assert "| gf | ideal | 90% [80, 95] (n=100) | not run | not run |" in lines[:start]


def test_real_object_runs_are_counted_per_object(tmp_path: Path):
    import json

    from wpbench.evaluation.paper_table import real_per_object, run_dir

    cfg = PaperTableConfig(policies=("gf", "wp-postsvd-t"), results=tmp_path)
    folder = run_dir(cfg, "wp-postsvd-t", "open-door", "partnet-mobility")
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({"success_rate": 0.5}))
    outcomes = [("45213", "storage", True), ("45213", "storage", False), ("7128", "oven", True),
                ("45213", "storage", False), ("7128", "oven", True)]
    (folder / "episodes.jsonl").write_text("".join(
        json.dumps({"episode": i, "seed": i, "object_id": o, "category": c, "success": ok}) + "\n"
        for i, (o, c, ok) in enumerate(outcomes)))
    counts = real_per_object(cfg, "wp-postsvd-t", "open-door")
    assert counts == {"45213": ("storage", 1, 3), "7128": ("oven", 2, 2)}
    assert real_per_object(cfg, "wp-postsvd-t", "place-in") is None
    text = render(cfg, {}, {}, real_per_object={("wp-postsvd-t", "ideal", "open-door"): counts,
                                                ("wp-postsvd-t", "gripper", "place-in"): {"7128": ("oven", 0, 4)}})
    lines = text.splitlines()
    start = lines.index("## Real PartNet-Mobility objects, per object")
    section = lines[start:]
    assert "| policy | executor | 7128 (oven) | 45213 (storage) |" in section
    assert "| wp-postsvd-t | ideal | 2/2 · - · - | 1/3 · - · - |" in section
    assert "| wp-postsvd-t | gripper | - · 0/4 · - | - · - · - |" in section
    assert not any(line.startswith("| gf |") for line in section)
    assert "per object" not in render(cfg, {}, {})


def test_test_split_runs_stand_beside_val_and_the_camera_settings_are_named():
    cfg = PaperTableConfig(policies=("wp-postsvd",))
    val = {("wp-postsvd", "ideal", "open-door"): {"success_rate": 0.9, "success_ci95": [0.8, 0.95], "episodes": 100,
                                         "meta": {"camera_noise": {}}}}
    test = {("wp-postsvd", "ideal", "open-door"): {"success_rate": 0.7, "success_ci95": [0.6, 0.8], "episodes": 100,
                                          "meta": {"camera_noise": {"depth_std": 0.002}}}}
    assert "test split" not in render(cfg, {}, val)
    assert "saw a clean camera" in render(cfg, {}, val)
    text = render(cfg, {}, val, test_successes=test)
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if "test split" in line and line.startswith("##"))
    assert "| wp-postsvd | ideal | 70% [60, 80] (n=100) | not run | not run |" in lines[start:]
    assert "| wp-postsvd | ideal | 90% [80, 95] (n=100) | not run | not run |" in lines[:start]
    assert "camera noise depth0.002 and a clean camera" in text


def test_other_executors_get_rows_beside_ideal_only_when_they_have_runs():
    cfg = PaperTableConfig(policies=("wp",))
    ideal = {("wp", "ideal", "open-door"): {"success_rate": 0.9, "success_ci95": [0.8, 0.95], "episodes": 100}}
    assert "| wp | gripper |" not in render(cfg, {}, ideal)
    both = {**ideal, ("wp", "gripper", "open-then-place"): {"success_rate": 0.8, "success_ci95": [0.7, 0.9],
                                                           "episodes": 100}}
    lines = render(cfg, {}, both).splitlines()
    assert "| wp | ideal | 90% [80, 95] (n=100) | not run | not run |" in lines
    assert "| wp | gripper | not run | not run | 80% [70, 90] (n=100) |" in lines
    assert "| wp | panda |" not in "\n".join(lines)


def test_runs_are_read_from_each_executors_folder(tmp_path: Path):
    import json

    from wpbench.evaluation.paper_table import run_dir, success

    cfg = PaperTableConfig(results=tmp_path)
    folder = run_dir(cfg, "wp", "open-door", executor="gripper")
    assert folder.name == "wp__open-door__val__procedural__camera__gripper"
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({"success_rate": 0.5}))
    assert success(cfg, "wp", "open-door", "gripper") == {"success_rate": 0.5}
    assert success(cfg, "wp", "open-door") is None
    assert run_dir(cfg, "wp", "place-in", "partnet-mobility", executor="panda").name == \
        "wp__place-in__val__partnet-mobility__camera__panda"


def test_the_cli_refuses_a_run_on_another_furniture_version_before_any_work(tmp_path: Path, wpbench_exe):
    import json
    import subprocess

    from wpbench.assets.procedural import GENERATOR_VERSION
    from wpbench.evaluation.paper_table import run_dir

    data = tmp_path / "data"
    (data / "train").mkdir(parents=True)
    (data / "val").mkdir()
    results = tmp_path / "results"
    old = run_dir(PaperTableConfig(results=results), "wp-postsvd-t", "place-in", split="test")
    old.mkdir(parents=True)
    (old / "run.json").write_text(json.dumps({"assets": "procedural", "furniture_generator": GENERATOR_VERSION - 1}))
    (old / "summary.json").write_text(json.dumps({"success_rate": 0.5}))
    out = tmp_path / "table.md"
    done = subprocess.run([str(wpbench_exe), "paper-table", "--data", str(data), "--results", str(results),
                           "--no-run-missing", "--out", str(out)],
                          capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("Error: ") and old.name in line and f"version {GENERATOR_VERSION - 1}" in line
    assert "results/archive/" in line and "Traceback" not in done.stderr
    assert not out.exists()
