"""Learned policies load trained weights, answer with a rigid cross-pose and fail
clearly (naming the command to run) when weights are missing or corrupt."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from wpbench.policies.learned import LearnedPolicy
from wpbench.policies.registry import make_policy
from wpbench.data.synthetic import write_synthetic_split
from wpbench.training.config import TrainConfig
from wpbench.training.loop import train
from wpbench.weights import select_best, shipped_weights_root

TINY_GF = {"encoder": {"k": 4, "edge_channels": [8, 8], "emb_dim": 16, "groups": 4}, "head_hidden": 16}
TINY_TP = {**TINY_GF, "attention_heads": 2}


@pytest.fixture(scope="module")
def weights_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("learned")
    write_synthetic_split(root / "data", "train", per_kind=3, num_action_points=32, num_anchor_points=48)
    write_synthetic_split(root / "data", "val", per_kind=2, num_action_points=32, num_anchor_points=48, seed=1)
    for policy, overrides in (("gf", TINY_GF), ("tp", TINY_TP), ("wp-postsvd", {})):
        train(TrainConfig(policy=policy, data=root / "data", out=root / "weights" / policy,
                          weights_root=root / "weights", max_steps=1, batch_size=2, num_action_points=24,
                          num_anchor_points=40, val_per_kind=1, final_val_per_kind=2, model_overrides=overrides),
              echo=lambda _: None)
    select_best(root / "weights")
    return root / "weights"


def _obs(seed=0, na=256, nb=1024, kind=0):
    rng = np.random.default_rng(seed)
    return {"action_points": rng.uniform(-0.1, 0.1, (na, 3)).astype(np.float32) + 0.5,
            "anchor_points": rng.uniform(-0.4, 0.4, (nb, 3)).astype(np.float32), "kind": kind, "stage": 0}


def _assert_rigid(T):
    assert T.shape == (4, 4) and T.dtype == np.float64 and np.all(np.isfinite(T))
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-5)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0, abs=1e-5)
    np.testing.assert_allclose(T[3], [0, 0, 0, 1])


@pytest.mark.parametrize("name", ["gf", "tp", "wp-postsvd"])
def test_learned_policy_gives_a_rigid_transform_and_full_size_diagnostics(weights_root, name):
    policy = LearnedPolicy(policy=name, weights_root=weights_root)
    out = policy.predict(_obs())
    _assert_rigid(out.transform)
    np.testing.assert_array_equal(out.transform, policy.predict(_obs()).transform)  # same input, same answer
    if name != "tp":
        assert out.diagnostics["flow"].shape == (256, 3)
        assert 0.0 <= float(np.mean(out.diagnostics["w"])) <= 1.0
    if name != "gf":
        assert out.diagnostics["action_targets"].shape == (256, 3)
        assert out.diagnostics["anchor_weights"].shape == (1024,)
        assert out.diagnostics["anchor_weights"].sum() == pytest.approx(1.0, abs=1e-4)
    assert policy.describe()["policy"] == name


def _subset_answers(policy, obs, count, mirrored):
    """The model's answer on each of the policy's first ``count`` subsets of ``obs``, the odd ones
    (when ``mirrored``) given the mirrored clouds and their answers mirrored back."""
    import torch

    from wpbench.models.subset_ensemble import random_subset

    rng = np.random.default_rng(0)
    picks = [(random_subset(len(obs["action_points"]), policy.num_action_points, rng),
              random_subset(len(obs["anchor_points"]), policy.num_anchor_points, rng)) for _ in range(count)]
    mirror = np.diag([1.0, -1.0, 1.0, 1.0])
    answers = []
    for k, (ia, ib) in enumerate(picks):
        flip = mirrored and k % 2 == 1
        seen = [torch.from_numpy(cloud * np.float32([1, -1, 1]) if flip else cloud)[None]
                for cloud in (obs["action_points"][ia], obs["anchor_points"][ib])]
        with torch.no_grad():
            T = policy.model(*seen).transform[0].double().numpy()
        answers.append(mirror @ T @ mirror if flip else T)
    return answers


def _fused(obs, answers):
    import torch

    from wpbench.models.subset_ensemble import fuse_goal_clouds

    return fuse_goal_clouds(torch.from_numpy(obs["action_points"]).double()[None],
                            torch.from_numpy(np.stack(answers))[:, None])[0].numpy()


@pytest.mark.parametrize("mirror_views", [False, True])
def test_subset_ensemble_fuses_several_subsets_and_one_subset_is_the_single_pass(weights_root, mirror_views):
    single = LearnedPolicy(policy="wp-postsvd", weights_root=weights_root, subsets=1, mirror_views=mirror_views)
    fused = LearnedPolicy(policy="wp-postsvd", weights_root=weights_root, subsets=4, mirror_views=mirror_views)
    obs = _obs(seed=3)
    one, four = single.predict(obs).transform, fused.predict(obs).transform
    _assert_rigid(four)
    # subsets=1 is the model on the first subset as observed (never mirrored); the fused answer is
    # the consensus of the four, every second one answered in the mirrored scene when asked.
    np.testing.assert_allclose(one, _subset_answers(single, obs, 1, mirrored=False)[0], atol=1e-5)
    np.testing.assert_allclose(four, _fused(obs, _subset_answers(fused, obs, 4, mirror_views)), atol=1e-5)
    assert not np.allclose(four, one, atol=1e-6)  # the other subsets changed the answer
    assert fused.describe()["config"]["subsets"] == 4
    assert fused.describe()["config"]["mirror_views"] is mirror_views
    with pytest.raises(ValueError, match="subsets"):
        LearnedPolicy(policy="wp-postsvd", weights_root=weights_root, subsets=0)


def test_mirrored_views_change_the_answer_of_a_model_that_is_not_mirror_equivariant(weights_root):
    obs = _obs(seed=5)
    plain = LearnedPolicy(policy="wp-postsvd", weights_root=weights_root, subsets=4, mirror_views=False)
    mirrored = LearnedPolicy(policy="wp-postsvd", weights_root=weights_root, subsets=4, mirror_views=True)
    assert not np.allclose(plain.predict(obs).transform, mirrored.predict(obs).transform, atol=1e-6)
    # The diagnostics are the first subset's, which is never mirrored.
    np.testing.assert_allclose(plain.predict(obs).diagnostics["flow"], mirrored.predict(obs).diagnostics["flow"])


def test_registry_builds_the_learned_policies_and_wp_follows_best_json(weights_root):
    best = json.loads((weights_root / "best.json").read_text())["policy"]
    assert best == "wp-postsvd"
    wp = make_policy("wp", weights_root=weights_root)
    assert wp.config.policy == "wp-postsvd" and wp.describe()["alias_of"] == "wp-postsvd"
    _assert_rigid(make_policy("gf", weights_root=weights_root).predict(_obs()).transform)


def test_wp_without_best_json_falls_back_and_says_what_is_missing(tmp_path, weights_root):
    shutil.copytree(weights_root / "gf", tmp_path / "gf")
    with pytest.raises(FileNotFoundError, match=r"wp-postsvd-t.*wpbench train --policy wp-postsvd-t"):
        make_policy("wp", weights_root=tmp_path)


def test_oracle_switches_expert_by_the_ground_truth_kind(weights_root):
    oracle = make_policy("oracle", weights_root=weights_root)
    assert oracle.uses_ground_truth
    gf, tp = (LearnedPolicy(policy=n, weights_root=weights_root) for n in ("gf", "tp"))
    art = oracle.predict(_obs(1), {"kind": "articulated"})
    free = oracle.predict(_obs(1), {"kind": "free-floating"})
    assert art.diagnostics["oracle_choice"] == "articulated" and "flow" in art.diagnostics
    assert free.diagnostics["oracle_choice"] == "free-floating" and "action_targets" in free.diagnostics
    np.testing.assert_allclose(art.transform, gf.predict(_obs(1)).transform)
    np.testing.assert_allclose(free.transform, tp.predict(_obs(1)).transform)
    with pytest.raises(ValueError, match="ground-truth kind"):
        oracle.predict(_obs(1))  # the observation never tells the kind
    with pytest.raises(ValueError, match="ground-truth kind"):
        oracle.predict(_obs(1), {"kind": 7})


def test_missing_weights_name_the_training_command(tmp_path):
    with pytest.raises(FileNotFoundError, match="wpbench train --policy gf"):
        LearnedPolicy(policy="gf", weights_root=tmp_path)


@pytest.mark.parametrize("victim, content", [("model.pt", b"not a torch file"), ("config.json", b"{broken")])
def test_corrupt_weights_give_a_clear_error(tmp_path, weights_root, victim, content):
    shutil.copytree(weights_root / "gf", tmp_path / "gf")
    (tmp_path / "gf" / victim).write_bytes(content)
    with pytest.raises(ValueError, match=r"corrupt.*wpbench train --policy gf"):
        LearnedPolicy(policy="gf", weights_root=tmp_path)


SHIPPED = ("gf", "tp", "oracle", "wp-og", "wp-postsvd", "wp-postsvd-t", "wp")


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_weights_load_and_answer(name):
    """The weights committed under policies/weights/ fit today's model code (no retraining needed)."""
    policy = make_policy(name)
    out = policy.predict(_obs(kind=1), info={"kind": "free-floating"})
    _assert_rigid(out.transform)
    if name.startswith("wp"):
        assert 0.0 < float(np.mean(out.diagnostics["w"])) < 1.0


def test_shipped_weights_say_how_they_were_made():
    WEIGHTS_ROOT = shipped_weights_root()
    best = json.loads((WEIGHTS_ROOT / "best.json").read_text())
    assert best["policy"] in ("wp-og", "wp-postsvd", "wp-postsvd-t")
    for name in ("gf", "tp", "wp-og", "wp-postsvd", "wp-postsvd-t"):
        config = json.loads((WEIGHTS_ROOT / name / "config.json").read_text())
        metrics = json.loads((WEIGHTS_ROOT / name / "metrics.json").read_text())
        assert config["policy"] == name
        # The wall time the training really took (a step budget's --minutes is only a cap).
        assert 0 < metrics["train_wall_s"] <= 60 * 60, (name, metrics["train_wall_s"])
        assert metrics["val"] and metrics["peak_rss_mib"] < 8 * 1024


def test_a_run_records_the_weights_and_furniture_it_was_made_with(weights_root):
    """run.json keeps the model hashes (both experts for the oracle) and the generator version,
    so that --resume never mixes episodes of retrained weights into an old run."""
    from wpbench.assets.procedural.generate import GENERATOR_VERSION
    from wpbench.evaluation.runner import RunConfig, produced_by

    def config(name):
        return json.loads((weights_root / name / "config.json").read_text())

    oracle = make_policy("oracle", weights_root=weights_root)
    made = produced_by(RunConfig(policy="oracle"), oracle)  # (what else run.json records is the runner's tests')
    assert made["policy_weights"] == sorted({config("gf")["model_hash"], config("tp")["model_hash"]})
    assert made["furniture_generator"] == GENERATOR_VERSION
    gf = produced_by(RunConfig(policy="gf", assets="../shared/partnet-mobility"), LearnedPolicy(policy="gf", weights_root=weights_root))
    assert gf["policy_weights"] == [config("gf")["model_hash"]]
    assert gf["furniture_generator"] is None  # real objects: no generator
    assert produced_by(RunConfig(policy="gt"), make_policy("gt"))["policy_weights"] == []
