"""``paper-table``'s missing runs: one sweep over every missing or short run, in the run
folders the table reads."""

from __future__ import annotations

import json

from wpbench.evaluation import paper_table, sweep
from wpbench.evaluation.paper_table import TASKS, PaperTableConfig, make_paper_table, run_dir


def fake_errors(cfg, policy):
    return {(split, kind): {"rot_deg": 1.0, "trans_m": 0.01, "point_m": 0.01, "n": 1}
            for split in paper_table.SPLITS for kind in paper_table.KINDS}


def write_summary(directory, episodes):
    directory.mkdir(parents=True)
    (directory / "summary.json").write_text(json.dumps({"episodes": episodes, "success_rate": 0.5,
                                                        "success_ci95": [0.1, 0.9]}))


def test_missing_and_short_runs_go_to_one_sweep_and_the_table_reads_them(tmp_path, monkeypatch):
    cfg = PaperTableConfig(data=tmp_path, results=tmp_path / "results", policies=("gf", "tp", "no-weights"),
                           episodes=10, obs="mesh", workers=2)
    monkeypatch.setattr(paper_table, "pose_errors",
                        lambda c, p: (_ for _ in ()).throw(FileNotFoundError("none")) if p == "no-weights"
                        else fake_errors(c, p))
    monkeypatch.setattr(paper_table, "category_errors", lambda c, p: {})
    write_summary(run_dir(cfg, "gf", TASKS[0]), episodes=10)   # complete
    write_summary(run_dir(cfg, "gf", TASKS[1]), episodes=4)    # short
    calls = []

    def fake_sweep(configs, results, workers=1, use_ray=False, ray_address=None, **_):
        calls.append((list(configs), results, workers, use_ray))
        for config in configs:
            if (config.out / "summary.json").exists():
                (config.out / "summary.json").unlink()
                config.out.rmdir()
            write_summary(config.out, config.episodes)
        return []

    monkeypatch.setattr(sweep, "run_sweep", fake_sweep)
    out = make_paper_table(cfg)
    assert len(calls) == 1
    configs, results, workers, use_ray = calls[0]
    expected = {("gf", t) for t in TASKS[1:]} | {("tp", t) for t in TASKS}
    assert {(c.policy, c.task) for c in configs} == expected
    assert all(c.out == run_dir(cfg, c.policy, c.task) and c.resume and c.episodes == 10 and c.obs == "mesh"
               and c.split == "val" for c in configs)
    assert (results, workers, use_ray) == (cfg.results, 2, False)
    text = out.read_text()
    rows = [line for line in text.split("Simulated success rate")[1].splitlines() if line.startswith("| ")]
    assert not [row for row in rows if row.startswith(("| gf ", "| tp ")) and "not run" in row]
    assert text.count("(n=10)") == 2 * len(TASKS)


def test_without_run_missing_nothing_runs_and_short_runs_are_shown_as_they_are(tmp_path, monkeypatch):
    cfg = PaperTableConfig(data=tmp_path, results=tmp_path / "results", policies=("gf",), episodes=10,
                           run_missing=False)
    monkeypatch.setattr(paper_table, "pose_errors", fake_errors)
    monkeypatch.setattr(paper_table, "category_errors", lambda c, p: {})
    write_summary(run_dir(cfg, "gf", TASKS[0]), episodes=4)
    monkeypatch.setattr(sweep, "run_sweep", lambda *a, **k: (_ for _ in ()).throw(AssertionError("ran")))
    text = make_paper_table(cfg).read_text()
    assert "(n=4)" in text and text.count("not run") == len(TASKS) - 1


def test_the_command_reads_runs_from_results_wherever_the_table_is_written(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from wpbench.cli import app

    data, results, out = tmp_path / "data", tmp_path / "results", tmp_path / "elsewhere" / "table.md"
    (data / "train").mkdir(parents=True)
    (data / "val").mkdir()
    monkeypatch.setattr(paper_table, "pose_errors", fake_errors)
    monkeypatch.setattr(paper_table, "category_errors", lambda c, p: {})
    cfg = PaperTableConfig(results=results)
    for task in TASKS:
        write_summary(run_dir(cfg, "gf", task), episodes=10)
    result = CliRunner().invoke(app, ["paper-table", "--data", str(data), "--results", str(results), "--out", str(out),
                                      "--episodes", "10", "--no-run-missing"])
    assert result.exit_code == 0, result.output
    gf_row = next(line for line in out.read_text().split("Simulated success rate")[1].splitlines()
                  if line.startswith("| gf | ideal |"))
    assert gf_row.count("50% [10, 90] (n=10)") == len(TASKS)
