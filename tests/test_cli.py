"""The ``wpbench`` command line: the installed console script, run as a user would."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import types
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

import wpbench.cli as cli
from wpbench.cli.choices import check_choice, choice_callback
from wpbench.evaluation.summary import summarize, write_summary
from wpbench.names import DEFAULT_EXECUTOR


def run_wpbench(exe: Path, *args: str, cwd: Path | None = None, timeout: float = 120):
    return subprocess.run(
        [str(exe), *args], capture_output=True, text=True, timeout=timeout, cwd=cwd, stdin=subprocess.DEVNULL
    )


def write_one_summary(results: Path, policy: str = "wp", task: str = "open") -> None:
    record = {
        "episode": 0, "seed": 0, "task": task, "policy": policy, "object_id": "o", "category": "oven",
        "success": True, "rot_err_deg": 1.0, "trans_err_m": 0.01, "point_err_m": 0.01, "point_mse": 1e-4,
    }
    write_summary(results / policy, summarize([record], {"split": "val", "asset_source": "procedural"}))


# --- the real console script ---------------------------------------------------


def test_help_lists_the_command_groups(wpbench_exe):
    result = run_wpbench(wpbench_exe, "--help")
    assert result.returncode == 0, result.stderr
    assert "Usage: wpbench" in result.stdout
    for name in ("bench", "leaderboard"):
        assert f"  {name} " in result.stdout
    # Groups written by others appear exactly when their module exists.
    for entry in cli.LAZY_COMMANDS:
        exists = importlib.util.find_spec(entry.module) is not None
        assert (f"  {entry.name} " in result.stdout) == exists, entry.name


def test_help_does_not_import_torch_or_sapien(repo_root):
    probe = (
        "import sys\n"
        "sys.argv = ['wpbench', '--help']\n"
        "from wpbench.cli import main\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        "heavy = sorted(m for m in ('torch', 'sapien', 'mani_skill', 'pandas', 'matplotlib') if m in sys.modules)\n"
        "print('HEAVY=' + ','.join(heavy))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd=repo_root
    )
    assert result.returncode == 0, result.stderr
    assert "HEAVY=\n" in result.stdout, result.stdout


def test_bench_help_lists_benchmarks(wpbench_exe):
    result = run_wpbench(wpbench_exe, "bench", "--help")
    assert result.returncode == 0, result.stderr
    for name in ("svd", "models", "episodes"):
        assert name in result.stdout


def test_unknown_subcommand_fails_with_a_suggestion(wpbench_exe):
    result = run_wpbench(wpbench_exe, "leaderbord")
    assert result.returncode == 2
    assert "No such command 'leaderbord'" in result.stderr
    assert "Did you mean 'leaderboard'" in result.stderr


def test_unknown_choice_is_one_line_listing_the_valid_names(wpbench_exe, tmp_results):
    result = run_wpbench(wpbench_exe, "leaderboard", "--results", str(tmp_results), "--sort-by", "speed")
    assert result.returncode == 2
    error_lines = [line for line in result.stderr.splitlines() if line.startswith("Error")]
    assert error_lines == [
        "Error: Invalid value for '--sort-by': unknown sort key 'speed'; valid: policy, rot, success, task, trans"
    ]


def test_leaderboard_command_writes_the_three_files(wpbench_exe, tmp_results):
    write_one_summary(tmp_results, "wp")
    write_one_summary(tmp_results, "identity")
    result = run_wpbench(wpbench_exe, "leaderboard", "--results", str(tmp_results))
    assert result.returncode == 0, result.stderr
    for name in ("leaderboard.md", "leaderboard.csv", "leaderboard.png"):
        assert (tmp_results / name).stat().st_size > 0
    assert "`identity`" in result.stdout and "(2 runs)" in result.stdout


def test_leaderboard_command_on_empty_results_says_what_to_do(wpbench_exe, tmp_results):
    result = run_wpbench(wpbench_exe, "leaderboard", "--results", str(tmp_results))
    assert result.returncode == 1
    assert "wpbench run" in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.skipif(importlib.util.find_spec("wpbench.cli.run_cmd") is None, reason="wpbench run not written yet")
def test_run_rejects_an_unknown_policy_listing_the_valid_ones(wpbench_exe, tmp_results):
    result = run_wpbench(
        wpbench_exe, "run", "--policy", "no-such-policy", "--task", "open-then-place", "--out", str(tmp_results),
        timeout=300,
    )
    assert result.returncode != 0
    assert "unknown policy 'no-such-policy'; valid:" in result.stderr
    assert "gt" in result.stderr and "identity" in result.stderr


def test_make_test_treats_no_collected_tests_as_failure(repo_root):
    """CI relies on this: pytest's exit code 5 ("no tests collected") must fail."""
    result = subprocess.run(
        ["make", "--no-print-directory", "test", "PYTEST_ARGS=tests/test_records.py -k no_test_has_this_name"],
        capture_output=True, text=True, timeout=300, cwd=repo_root, stdin=subprocess.DEVNULL,
    )
    assert result.returncode != 0
    assert "collected no tests" in result.stderr


def test_make_run_names_its_folder_after_the_executor(repo_root):
    """`make run` resumes its own folder: one per executor, so a new default never resumes an old run."""
    result = subprocess.run(["make", "--no-print-directory", "-n", "run"], capture_output=True, text=True,
                            timeout=120, cwd=repo_root, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr
    assert f"--executor {DEFAULT_EXECUTOR} --out runs/wp__open-then-place__val__{DEFAULT_EXECUTOR}__weights-" \
        in result.stdout
    other = subprocess.run(["make", "--no-print-directory", "-n", "run", "EXECUTOR=ideal"], capture_output=True,
                           text=True, timeout=120, cwd=repo_root, stdin=subprocess.DEVNULL)
    assert "--executor ideal --out runs/wp__open-then-place__val__ideal__weights-" in other.stdout


# --- in-process: wiring of lazily imported commands ---------------------------


@pytest.fixture
def runner():
    return CliRunner()


def fake_module(monkeypatch, name: str, **attributes) -> types.ModuleType:
    module = types.ModuleType(name)
    for key, value in attributes.items():
        setattr(module, key, value)
    monkeypatch.setitem(sys.modules, name, module)
    return module


def test_bench_svd_passes_its_options_to_the_benchmark(runner, monkeypatch, tmp_path):
    calls = []
    fake_module(monkeypatch, "wpbench.bench.svd", run=lambda **kw: calls.append(kw))
    out = tmp_path / "svd.json"
    result = runner.invoke(cli.app, ["bench", "svd", "--batch", "8", "--points", "64", "--json", str(out)])
    assert result.exit_code == 0, result.output
    assert calls == [{"batch": 8, "points": 64, "json_path": out}]


def test_bench_episodes_passes_only_what_the_benchmark_accepts(runner, monkeypatch):
    calls = []

    def run(episodes=10, tasks=("a", "b"), json_path=None):
        calls.append((episodes, tasks, json_path))

    fake_module(monkeypatch, "wpbench.bench.episodes", run=run)
    assert runner.invoke(cli.app, ["bench", "episodes"]).exit_code == 0
    assert calls == [(10, ("a", "b"), None)]  # nothing given: the benchmark's defaults
    result = runner.invoke(cli.app, ["bench", "episodes", "--episodes", "3", "--task", "open-door", "--task", "x"])
    assert result.exit_code == 0, result.output
    assert calls[-1] == (3, ("open-door", "x"), None)
    refused = runner.invoke(cli.app, ["bench", "episodes", "--policy", "gt"])
    assert refused.exit_code == 2 and "--policy" in refused.output
    assert len(calls) == 2


def test_a_command_module_that_fails_to_import_reports_itself(runner, monkeypatch, tmp_path):
    (tmp_path / "wpbench_broken_cmd_for_test.py").write_text("raise RuntimeError('half-written module')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    entry = cli.LazyCommand("broken", "wpbench_broken_cmd_for_test", "app", "A broken group.")
    monkeypatch.setattr(cli, "LAZY_COMMANDS", (*cli.LAZY_COMMANDS, entry))
    monkeypatch.setitem(cli._BY_NAME, "broken", entry)

    listing = runner.invoke(cli.app, ["--help"])
    assert listing.exit_code == 0 and "broken" in listing.output and "bench" in listing.output
    result = runner.invoke(cli.app, ["broken", "anything"])
    assert result.exit_code == 1
    assert "half-written module" in result.output
    # Other commands still work.
    assert runner.invoke(cli.app, ["bench", "--help"]).exit_code == 0


def test_a_plain_function_is_mounted_as_a_single_command(runner, monkeypatch, tmp_path):
    (tmp_path / "wpbench_fake_hello_cmd.py").write_text(
        "import typer\n"
        "def hello(name: str = typer.Option('x')) -> None:\n"
        "    typer.echo(f'hello {name}')\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    entry = cli.LazyCommand("hello", "wpbench_fake_hello_cmd", "hello", "Say hello.")
    monkeypatch.setattr(cli, "LAZY_COMMANDS", (*cli.LAZY_COMMANDS, entry))
    monkeypatch.setitem(cli._BY_NAME, "hello", entry)
    result = runner.invoke(cli.app, ["hello", "--name", "wp"])
    assert result.exit_code == 0, result.output
    assert result.output.strip() == "hello wp"


# --- choices -------------------------------------------------------------------


def test_check_choice_accepts_valid_and_lists_sorted_valid_names_otherwise():
    assert check_choice("policy", "wp", ["wp", "gt"]) == "wp"
    with pytest.raises(typer.BadParameter) as raised:
        check_choice("policy", "WP", ["wp", "identity", "gt"])
    assert str(raised.value.message) == "unknown policy 'WP'; valid: gt, identity, wp"
    with pytest.raises(typer.BadParameter, match=r"\(none available\)"):
        check_choice("task", "open", [])


def test_choice_callback_calls_the_registry_only_when_needed():
    calls = []

    def registry():
        calls.append(1)
        return ["val", "test"]

    callback = choice_callback("split", registry)
    assert callback(None) is None and calls == []
    assert callback("val") == "val" and calls == [1]
    with pytest.raises(typer.BadParameter, match="unknown split 'train'; valid: test, val"):
        callback("train")


@pytest.mark.slow
def test_run_writes_results_resumes_and_never_overwrites(wpbench_exe, tmp_path):
    """`wpbench run` as a user runs it: files, summary table, --resume, and a refusal to clobber."""
    import json

    out = tmp_path / "run"
    common = ("run", "--policy", "gt", "--task", "open-door", "--obs", "mesh", "--out", str(out), "--no-progress")
    first = run_wpbench(wpbench_exe, *common, "--episodes", "2", timeout=600)
    assert first.returncode == 0, first.stderr
    assert "success" in first.stdout.lower()
    lines = (out / "episodes.jsonl").read_text().splitlines()
    assert [json.loads(line)["episode"] for line in lines] == [0, 1]
    assert all(json.loads(line)["success"] for line in lines)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success_rate"] == 1.0
    # No --executor: the default one carries out the pose, and the table says which it was.
    assert summary["meta"]["executor"] == DEFAULT_EXECUTOR != "ideal"
    assert any(line.split() == ["executor", DEFAULT_EXECUTOR] for line in first.stdout.splitlines())

    refused = run_wpbench(wpbench_exe, *common, "--episodes", "3", timeout=600)
    assert refused.returncode != 0 and "--resume" in (refused.stderr + refused.stdout)
    assert (out / "episodes.jsonl").read_text().splitlines() == lines  # nothing written was lost

    resumed = run_wpbench(wpbench_exe, *common, "--episodes", "3", "--resume", timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    after = (out / "episodes.jsonl").read_text().splitlines()
    assert after[:2] == lines and len(after) == 3
    assert json.loads((out / "summary.json").read_text())["episodes"] == 3


def test_model_options_become_nested_overrides_and_bad_ones_say_how():
    from wpbench.cli.train_cmd import parse_model_options

    assert parse_model_options(["anchor_extent=true", "encoder.k=20", "encoder.edge_channels=[16, 32]"]) == {
        "anchor_extent": True, "encoder": {"k": 20, "edge_channels": [16, 32]}}
    with pytest.raises(ValueError, match="KEY=VALUE"):
        parse_model_options(["anchor_extent"])
    with pytest.raises(ValueError, match="must be JSON"):
        parse_model_options(["anchor_extent=yes please"])


@pytest.fixture
def tiny_data(tmp_path):
    """A synthetic data folder (train and val, 2 samples per kind) small enough for a 1-step training."""
    from wpbench.data.synthetic import write_synthetic_split

    write_synthetic_split(tmp_path / "data", "train", per_kind=2, num_action_points=32, num_anchor_points=48)
    write_synthetic_split(tmp_path / "data", "val", per_kind=2, num_action_points=32, num_anchor_points=48, seed=1)
    return tmp_path / "data"


@pytest.fixture
def captured_runs(monkeypatch):
    """``wpbench run`` stops before simulating; the list holds the run configs it would have run."""
    import wpbench.evaluation.runner as runner_module

    seen = []

    def fake_run_benchmark(cfg, **_):
        seen.append(cfg)
        raise ValueError("stopped by the test")

    monkeypatch.setattr(runner_module, "run_benchmark", fake_run_benchmark)
    return seen


def test_train_passes_model_options_to_the_model_config(wpbench_exe, tmp_path, tiny_data):
    """A typo in an option is refused with the valid names before anything is written."""
    out = tmp_path / "gf"
    result = subprocess.run([str(wpbench_exe), "train", "--policy", "gf", "--data", str(tiny_data),
                             "--out", str(out), "--model-option", "anchor_extnt=true"],
                            capture_output=True, text=True)
    assert result.returncode == 2
    assert "anchor_extnt" in result.stderr and "anchor_extent" in result.stderr
    assert not (out / "model.pt").exists()


def test_train_records_the_augmentation_retarget_gate_and_loss_weights_it_was_given(wpbench_exe, tmp_path, tiny_data):
    out = tmp_path / "gf"
    result = subprocess.run([str(wpbench_exe), "train", "--policy", "gf", "--data", str(tiny_data),
                             "--out", str(out), "--max-steps", "1", "--steps-per-epoch", "1", "--val-per-kind", "2",
                             "--final-val-per-kind", "2", "--num-action-points", "16", "--num-anchor-points", "16",
                             "--model-option", "encoder.emb_dim=16", "--scale", "0.05", "--stretch", "0.3",
                             "--retarget-within", "90", "--loss-weight", "goal_flow=2"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    described = json.loads((out / "config.json").read_text())
    recorded = described["train_config"]
    assert (recorded["augment_scale"], recorded["augment_stretch"], recorded["retarget_within_deg"]) == (0.05, 0.3, 90)
    assert recorded["loss_weights"] == {"goal_flow": 2.0} and described["loss_weights"]["goal_flow"] == 2.0
    for bad in ("goal_flow", "goal_flow=lots"):
        refused = subprocess.run([str(wpbench_exe), "train", "--policy", "gf", "--data", str(tiny_data),
                                  "--out", str(tmp_path / "other"), "--loss-weight", bad], capture_output=True, text=True)
        assert refused.returncode == 2 and "TERM=NUMBER" in refused.stderr
    refused = subprocess.run([str(wpbench_exe), "train", "--policy", "gf", "--data", str(tiny_data),
                              "--out", str(tmp_path / "other"), "--stretch", "1.5"], capture_output=True, text=True)
    assert refused.returncode == 2 and "stretch" in refused.stderr
    assert not (tmp_path / "other").exists()


def test_run_weights_root_loads_the_experiment_and_writes_beside_it(runner, captured_runs, tmp_path, repo_root):
    """--weights-root: the policy loads from that folder, the run goes to <root>/runs/."""
    import shutil

    from wpbench.policies.registry import make_policy

    root = tmp_path / "experiment"
    shutil.copytree(repo_root / "policies" / "weights" / "gf", root / "gf", ignore=shutil.ignore_patterns("checkpoint.pt"))
    result = runner.invoke(cli.app, ["run", "--policy", "gf", "--task", "open-door", "--weights-root", str(root)])
    assert result.exit_code == 2 and "stopped by the test" in result.output
    (cfg,) = captured_runs
    assert cfg.out == root / "runs" / f"gf__open-door__val__procedural__camera__{DEFAULT_EXECUTOR}"
    assert make_policy(cfg.policy, **cfg.policy_kwargs).config.weights_dir == root / "gf"

    refused = runner.invoke(cli.app, ["run", "--policy", "gt", "--weights-root", str(root)])
    assert refused.exit_code == 2 and "applies to the trained policies" in refused.output
    missing = runner.invoke(cli.app, ["run", "--policy", "gf", "--weights-root", str(tmp_path / "nowhere")])
    assert missing.exit_code == 2 and "wpbench train --policy NAME --weights-root" in missing.output
    assert len(captured_runs) == 1


def test_run_subsets_reaches_the_learned_policy_and_is_refused_for_the_others(runner, captured_runs):
    from wpbench.policies.registry import make_policy

    result = runner.invoke(cli.app, ["run", "--policy", "oracle", "--task", "open-door", "--subsets", "2"])
    assert result.exit_code == 2 and "stopped by the test" in result.output
    policy = make_policy(captured_runs[0].policy, **captured_runs[0].policy_kwargs)
    assert {expert.config.subsets for expert in policy.experts.values()} == {2}
    assert {expert.config.mirror_views for expert in policy.experts.values()} == {True}  # the default
    refused = runner.invoke(cli.app, ["run", "--policy", "identity", "--subsets", "2"])
    assert refused.exit_code == 2 and "--subsets applies to the trained policies" in refused.output
    assert len(captured_runs) == 1


def test_run_no_mirror_views_reaches_the_learned_policy_and_is_refused_for_the_others(runner, captured_runs):
    from wpbench.policies.registry import make_policy

    result = runner.invoke(cli.app, ["run", "--policy", "gf", "--task", "open-door", "--no-mirror-views"])
    assert result.exit_code == 2 and "stopped by the test" in result.output
    assert make_policy(captured_runs[0].policy, **captured_runs[0].policy_kwargs).config.mirror_views is False
    refused = runner.invoke(cli.app, ["run", "--policy", "identity", "--mirror-views"])
    assert refused.exit_code == 2 and "mirror-views applies to the trained policies" in refused.output
    assert len(captured_runs) == 1


def test_a_bare_ray_means_a_local_cluster():
    assert cli.bare_ray_means_local(["sweep", "--ray"]) == ["sweep", "--ray", "local"]
    assert cli.bare_ray_means_local(["run", "--ray", "--workers", "2"]) == ["run", "--ray", "local", "--workers", "2"]
    assert cli.bare_ray_means_local(["run", "--ray", "auto"]) == ["run", "--ray", "auto"]
    assert cli.bare_ray_means_local(["run", "--ray=auto"]) == ["run", "--ray=auto"]


def test_a_bare_ray_is_accepted_by_the_console_script(wpbench_exe):
    # The policy check comes after parsing: reaching it shows `--ray` alone parsed.
    result = run_wpbench(wpbench_exe, "sweep", "--policies", "no-such-policy", "--ray", "--episodes", "1")
    assert result.returncode != 0
    assert "requires an argument" not in result.stderr and "no-such-policy" in result.stderr, result.stderr
