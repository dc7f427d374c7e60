"""Trained weights (``wpbench.weights``): training writes a run folder, never the shipped weights;
``wpbench train --promote RUN`` ships a finished run after checking it, and refuses anything
else with a one-line error saying what to do; training and policies never import each other."""

from __future__ import annotations

import ast
import hashlib
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from wpbench import weights
from wpbench.data.synthetic import write_synthetic_split
from wpbench.training.config import TrainConfig
from wpbench.training.loop import train

TINY_GF = {"encoder": {"k": 4, "edge_channels": [8, 8], "emb_dim": 16, "groups": 4}, "head_hidden": 16}
TINY_TP = {**TINY_GF, "attention_heads": 2}
TINY = {"gf": TINY_GF, "tp": TINY_TP}
TINY_CLI = ["--max-steps", "1", "--steps-per-epoch", "1", "--batch-size", "2", "--num-action-points", "24",
            "--num-anchor-points", "40", "--val-per-kind", "1", "--final-val-per-kind", "2",
            "--model-option", "encoder.k=4", "--model-option", "encoder.edge_channels=[8, 8]",
            "--model-option", "encoder.emb_dim=16", "--model-option", "encoder.groups=4",
            "--model-option", "head_hidden=16"]
REPO = Path(__file__).resolve().parents[1]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _tree_digests(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): _digest(p) for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> Path:
    """Finished tiny runs of gf, tp and (from them) wp-postsvd under ``runs/``, and the data."""
    root = tmp_path_factory.mktemp("weights")
    write_synthetic_split(root / "data", "train", per_kind=2, num_action_points=32, num_anchor_points=48)
    write_synthetic_split(root / "data", "val", per_kind=2, num_action_points=32, num_anchor_points=48, seed=1)
    for policy in ("gf", "tp", "wp-postsvd"):
        train(TrainConfig(policy=policy, data=root / "data", out=root / "runs" / policy, weights_root=root / "runs",
                          max_steps=1, steps_per_epoch=1, batch_size=2, num_action_points=24, num_anchor_points=40,
                          val_per_kind=1, final_val_per_kind=2, model_overrides=TINY.get(policy, {})),
              echo=lambda _: None)
    return root / "runs"


def _copy_run(runs: Path, policy: str, tmp_path: Path) -> Path:
    run = tmp_path / "run" / policy
    shutil.copytree(runs / policy, run)
    return run


# --- the default run folder -----------------------------------------------------------------------

def test_a_training_without_out_writes_runs_train_policy():
    assert TrainConfig(policy="gf").out == Path("runs/train/gf")
    assert TrainConfig(policy="wp-og").out == Path("runs/train/wp-og")
    assert TrainConfig(policy="gf").weights_root == weights.shipped_weights_root()  # warm starts read the shipped


def test_wpbench_train_without_out_leaves_the_shipped_weights_alone(wpbench_exe, tmp_path):
    write_synthetic_split(tmp_path / "data", "train", per_kind=2, num_action_points=32, num_anchor_points=48)
    write_synthetic_split(tmp_path / "data", "val", per_kind=2, num_action_points=32, num_anchor_points=48, seed=1)
    shipped = weights.shipped_weights_root()
    before = _tree_digests(shipped)
    result = subprocess.run([str(wpbench_exe), "train", "--policy", "gf", "--data", str(tmp_path / "data"), *TINY_CLI],
                            cwd=tmp_path, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    run = tmp_path / "runs" / "train" / "gf"
    assert {"model.pt", "config.json", "metrics.json", "progress.json"} <= {p.name for p in run.iterdir()}
    assert f"wpbench train --promote {Path('runs/train/gf')}" in result.stdout
    assert _tree_digests(shipped) == before


# --- promotion ------------------------------------------------------------------------------------

def test_promote_ships_a_finished_run_and_the_policy_answers_with_it(runs, tmp_path):
    from wpbench.policies.learned import LearnedPolicy

    root = tmp_path / "weights"
    shipped = weights.promote(runs / "gf", root)
    assert shipped["policy"] == "gf" and shipped["weights_dir"] == root / "gf" and shipped["best"] is None
    for name in ("model.pt", "config.json", "metrics.json", "progress.json", "train_log.csv"):
        assert _digest(root / "gf" / name) == _digest(runs / "gf" / name), name
    assert not (root / "gf" / "checkpoint.pt").exists()  # the run's resume state is not shipped
    assert sorted(p.name for p in root.iterdir()) == ["gf"]  # no staging folder left behind
    obs = {"action_points": np.random.default_rng(0).uniform(-0.1, 0.1, (60, 3)).astype(np.float32),
           "anchor_points": np.random.default_rng(1).uniform(-0.4, 0.4, (90, 3)).astype(np.float32)}
    np.testing.assert_array_equal(LearnedPolicy(policy="gf", weights_root=root).predict(obs).transform,
                                  LearnedPolicy(policy="gf", weights_root=runs).predict(obs).transform)


def test_promoting_a_weighted_pose_variant_chooses_best_json_and_replaces_what_was_shipped(runs, tmp_path):
    root = tmp_path / "weights"
    (root / "wp-postsvd").mkdir(parents=True)
    (root / "wp-postsvd" / "stale.txt").write_text("from an older release")
    shipped = weights.promote(runs / "wp-postsvd", root)
    assert shipped["best"]["policy"] == "wp-postsvd"
    assert json.loads((root / "best.json").read_text())["policy"] == "wp-postsvd"
    assert weights.best_weighted_pose(root) == "wp-postsvd"
    assert not (root / "wp-postsvd" / "stale.txt").exists()  # the folder is the run's, whole
    assert sorted(p.name for p in root.iterdir()) == ["best.json", "wp-postsvd"]


def test_wpbench_train_promote_as_a_command(wpbench_exe, runs, tmp_path):
    root = tmp_path / "weights"
    ok = subprocess.run([str(wpbench_exe), "train", "--promote", str(runs / "tp"), "--weights-root", str(root)],
                        capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    assert "promoted tp" in ok.stdout and (root / "tp" / "model.pt").is_file()
    refused = subprocess.run([str(wpbench_exe), "train", "--promote", str(tmp_path / "nowhere"), "--weights-root",
                              str(root)], capture_output=True, text=True)
    assert refused.returncode == 2
    error = refused.stderr.strip()
    assert error.startswith("Error: no run folder") and "wpbench train --policy" in error and "\n" not in error
    assert "--promote RUN_DIR" in subprocess.run([str(wpbench_exe), "train", "--help"], capture_output=True,
                                                 text=True).stdout


def test_wpbench_train_select_best_still_chooses_wp(wpbench_exe, runs, tmp_path):
    root = tmp_path / "weights"
    select = [str(wpbench_exe), "train", "--select-best", "--weights-root", str(root)]
    weights.promote(runs / "gf", root)
    none = subprocess.run(select, capture_output=True, text=True)
    assert none.returncode == 2 and "no trained WeightedPose variant" in none.stderr
    weights.promote(runs / "wp-postsvd", root)
    (root / "best.json").unlink()
    chosen = subprocess.run(select, capture_output=True, text=True)
    assert chosen.returncode == 0, chosen.stderr
    assert json.loads((root / "best.json").read_text())["policy"] == "wp-postsvd"


def test_best_json_is_not_chosen_between_variants_validated_on_different_data(wpbench_exe, runs, tmp_path):
    root = tmp_path / "weights"
    weights.promote(runs / "wp-postsvd", root)
    before = (root / "best.json").read_text()
    other = _copy_run(runs, "wp-postsvd", tmp_path)
    config = json.loads((other / weights.CONFIG_FILE).read_text())
    config["policy"] = "wp-og"
    config["data"]["val_manifest_hash"] = "0000000000000000"
    (other / weights.CONFIG_FILE).write_text(json.dumps(config))
    shutil.copytree(other, root / "wp-og")
    with pytest.raises(ValueError, match="validated on different data.*retrain them on the same data"):
        weights.select_best(root)
    assert (root / "best.json").read_text() == before
    refused = subprocess.run([str(wpbench_exe), "train", "--select-best", "--weights-root", str(root)],
                             capture_output=True, text=True)
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1 and "different data" in refused.stderr
    assert (root / "best.json").read_text() == before
    shipped = weights.promote(runs / "wp-postsvd", root)  # shipping still works; the choice is left alone
    assert shipped["best"] is None and "different data" in shipped["best_unchanged"]
    assert (root / "best.json").read_text() == before


def _break_metrics(run: Path, change) -> None:
    path = run / weights.METRICS_FILE
    metrics = json.loads(path.read_text())
    change(metrics)
    path.write_text(json.dumps(metrics))


def _nan_point_error(metrics: dict) -> None:
    metrics["val"]["articulated"]["point_m"] = math.nan


def _other_gf_weights(run: Path, runs: Path, tmp_path: Path) -> None:
    """The same architecture, other weights: a second gf training with another seed."""
    other = train(TrainConfig(policy="gf", data=runs.parent / "data", out=tmp_path / "other-gf", max_steps=1,
                              steps_per_epoch=1, batch_size=2, num_action_points=24, num_anchor_points=40,
                              val_per_kind=1, final_val_per_kind=2, model_overrides=TINY_GF, seed=7),
                  echo=lambda _: None)
    assert other["policy"] == "gf"
    shutil.copy(tmp_path / "other-gf" / "model.pt", run / "model.pt")


REFUSALS = {
    "missing metrics": (lambda run, runs, tmp: (run / "metrics.json").unlink(),
                        r"metrics.json is missing.*wpbench train --policy gf --out"),
    "NaN metrics": (lambda run, runs, tmp: _break_metrics(run, _nan_point_error),
                    r"no finite val\.articulated\.point_m.*wpbench train --policy gf --restart"),
    "no validation": (lambda run, runs, tmp: _break_metrics(run, lambda m: m.pop("val")),
                      r"no validation errors.*wpbench train --policy gf --restart"),
    "another architecture's model": (lambda run, runs, tmp: shutil.copy(runs / "tp" / "model.pt", run / "model.pt"),
                                     r"does not match its config.json.*wpbench train --policy gf"),
    "other weights": (_other_gf_weights, r"model_hash .* config.json records .*different trainings"),
    "interrupted": (lambda run, runs, tmp: (run / "model.pt").unlink(),
                    r"holds only a checkpoint: the training did not finish; resume it with `wpbench train --policy gf"),
    "still training": (lambda run, runs, tmp: (run / "progress.json").write_text(json.dumps({"status": "training"})),
                       r"says the training is 'training', not 'done'; resume it"),
    "unknown policy": (lambda run, runs, tmp: _rename_policy(run), r"names policy 'gf-mine', not one of gf, tp"),
}


def _rename_policy(run: Path) -> None:
    config = json.loads((run / "config.json").read_text())
    config["policy"] = "gf-mine"
    (run / "config.json").write_text(json.dumps(config))


@pytest.mark.parametrize("case", sorted(REFUSALS))
def test_promote_refuses_a_run_that_is_not_fit_to_ship(runs, tmp_path, case):
    spoil, message = REFUSALS[case]
    run = _copy_run(runs, "gf", tmp_path)
    spoil(run, runs, tmp_path)
    root = tmp_path / "weights"
    (root / "gf").mkdir(parents=True)
    (root / "gf" / "model.pt").write_bytes(b"the shipped weights")
    with pytest.raises(ValueError, match=message) as refused:
        weights.promote(run, root)
    assert "\n" not in str(refused.value)
    assert (root / "gf" / "model.pt").read_bytes() == b"the shipped weights"  # untouched
    assert sorted(p.name for p in root.iterdir()) == ["gf"]


def test_promote_refuses_the_shipped_folder_itself(runs, tmp_path):
    root = tmp_path / "weights"
    weights.promote(runs / "gf", root)
    with pytest.raises(ValueError, match="already is the shipped 'gf'"):
        weights.promote(root / "gf", root)


def test_the_shipped_weights_pass_the_promotion_checks():
    """Every shipped policy is a finished training whose files belong together."""
    shipped = weights.shipped_weights_root()
    for policy in ("gf", "tp", "wp-og", "wp-postsvd", "wp-postsvd-t"):
        assert weights.check_run(shipped / policy)["policy"] == policy


def test_best_json_is_read_with_a_fallback_and_a_clear_error(tmp_path):
    assert weights.best_weighted_pose(tmp_path) == weights.FALLBACK_WEIGHTED_POSE
    assert weights.select_best(tmp_path) is None and not (tmp_path / "best.json").exists()
    (tmp_path / "best.json").write_text("{broken")
    with pytest.raises(ValueError, match="corrupt.*--select-best"):
        weights.best_weighted_pose(tmp_path)
    (tmp_path / "best.json").write_text(json.dumps({"policy": "gf"}))
    with pytest.raises(ValueError, match="not a WeightedPose variant"):
        weights.best_weighted_pose(tmp_path)


# --- no import cycle ------------------------------------------------------------------------------

def _modules(package_dir: Path, package: str) -> list[str]:
    return sorted(f"{package}.{p.stem}" if p.stem != "__init__" else package for p in package_dir.glob("*.py"))


TRAINING = _modules(REPO / "wpbench" / "training", "wpbench.training")
POLICIES = _modules(REPO / "policies", "wpbench.policies")


def _imported_names(path: Path) -> set[str]:
    """Every module a file imports, at any depth of its code (function-level imports too)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names |= {node.module, *(f"{node.module}.{alias.name}" for alias in node.names)}
    return names


def _reaches(names: set[str], package: str) -> bool:
    return any(name == package or name.startswith(package + ".") for name in names)


@pytest.mark.parametrize("folder, forbidden", [("wpbench/training", "wpbench.policies"),
                                               ("policies", "wpbench.training"),
                                               ("wpbench/weights.py", "wpbench.policies"),
                                               ("wpbench/weights.py", "wpbench.training")])
def test_no_file_imports_the_other_side(folder, forbidden):
    path = REPO / folder
    files = [path] if path.is_file() else sorted(path.glob("*.py"))
    assert files
    offenders = [str(f.relative_to(REPO)) for f in files if _reaches(_imported_names(f), forbidden)]
    assert not offenders, f"{offenders} import {forbidden}"


@pytest.mark.parametrize("modules, forbidden", [(TRAINING, "wpbench.policies"), (POLICIES, "wpbench.training")])
def test_importing_one_side_loads_nothing_of_the_other(modules, forbidden):
    """Also through other modules: import every module of one side in a fresh interpreter, use the
    weights module as they do, and look at what got loaded."""
    code = (f"import importlib, sys\nfor m in {modules!r}: importlib.import_module(m)\n"
            "from wpbench import weights\nweights.shipped_weights_root()\n"
            f"bad = sorted(m for m in sys.modules if m == {forbidden!r} or m.startswith({forbidden + '.'!r}))\n"
            "print(bad)\nsys.exit(1 if bad else 0)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert result.returncode == 0, f"loaded {result.stdout.strip()} {result.stderr[-2000:]}"
