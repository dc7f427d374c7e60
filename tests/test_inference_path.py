"""One inference path: the learned policy in the simulator and the pose-error tables (``wpbench
paper-table``, ``wpbench.training.evaluate`` with ``subsets``) answer a sample with the same pose
for the same seed, through ``wpbench.models.subset_ensemble.ensemble_predict``."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from wpbench.data.dataset import CrossPoseDataset
from wpbench.data.equivalent_goals import nearest_goal
from wpbench.data.synthetic import write_synthetic_split
from wpbench.geometry import metrics
from wpbench.models.subset_ensemble import ensemble_predict, random_subset
from wpbench.names import ARTICULATED, FREE
from wpbench.policies.registry import make_policy
from wpbench.training.evaluate import per_sample_errors, predicted_poses

# Poses of the same sample from a batch of one scene and from a batch of several agree to float32
# rounding of the forward pass, far below a micrometre or a microradian.
POSE_TOLERANCE = 1e-5
PER_KIND = 2
# Observed clouds larger than the shipped models' inputs (128 action / 512 anchor points), so
# every subset is a different draw.
OBSERVED_ACTION, OBSERVED_ANCHOR = 300, 900


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("inference") / "data"
    for split, seed in (("train", 0), ("val", 1)):
        write_synthetic_split(root, split, per_kind=PER_KIND, num_action_points=OBSERVED_ACTION,
                              num_anchor_points=OBSERVED_ANCHOR, seed=seed)
    return root


def _policy_poses(policy, dataset: CrossPoseDataset) -> np.ndarray:
    return np.stack([policy.predict({"action_points": dataset.action[i].numpy(),
                                     "anchor_points": dataset.anchor[i].numpy()}).transform
                     for i in range(len(dataset))])


@pytest.mark.parametrize("name, subsets, mirror_views, seed",
                         [("wp-postsvd-t", 8, True, 0), ("gf", 1, True, 0), ("tp", 3, False, 5)])
def test_the_policy_and_the_evaluation_give_the_same_pose(data, name, subsets, mirror_views, seed):
    policy = make_policy(name, subsets=subsets, mirror_views=mirror_views, seed=seed)
    dataset = CrossPoseDataset(data / "val")
    indices = torch.arange(len(dataset))
    evaluated = torch.cat([T for _, T, _, _ in predicted_poses(
        policy.model, dataset, indices, policy.num_action_points, policy.num_anchor_points, seed=seed,
        subsets=subsets, mirror_views=mirror_views)]).numpy()
    answered = _policy_poses(policy, dataset)
    np.testing.assert_allclose(evaluated, answered, atol=POSE_TOLERANCE, rtol=0)
    # The poses differ from sample to sample, and from what another seed draws.
    assert not np.allclose(answered[0], answered[1], atol=1e-3)
    other = make_policy(name, subsets=subsets, mirror_views=mirror_views, seed=seed + 1)
    first = {"action_points": dataset.action[0].numpy(), "anchor_points": dataset.anchor[0].numpy()}
    assert not np.allclose(other.predict(first).transform, answered[0], atol=POSE_TOLERANCE, rtol=0)


def _errors_of(poses: np.ndarray, dataset: CrossPoseDataset) -> dict[str, np.ndarray]:
    """The paper table's errors of ``poses``, measured on every stored action point."""
    T_pred = torch.from_numpy(poses)
    T_gt = nearest_goal(T_pred, dataset.gt_equivalents.double())
    points = dataset.action.double()
    return {"rot_deg": metrics.rotation_error_deg(T_pred[:, :3, :3], T_gt[:, :3, :3]).numpy(),
            "trans_m": metrics.translation_error(T_pred, T_gt, points.mean(dim=1)).numpy(),
            "point_m": metrics.point_error(T_pred, T_gt, points)[0].numpy()}


def test_the_paper_table_reports_the_errors_of_the_policys_answers(data):
    from wpbench.evaluation.paper_table import PaperTableConfig, pose_errors

    cfg = PaperTableConfig(data=data, samples_per_kind=PER_KIND, policies=("wp-postsvd-t",))
    table = pose_errors(cfg, "wp-postsvd-t")
    policy = make_policy("wp-postsvd-t")  # the benchmark's defaults, as the table's
    assert (policy.config.subsets, policy.config.mirror_views) == (cfg.subsets, cfg.mirror_views)
    for split in ("train", "val"):
        for kind in (ARTICULATED, FREE):
            dataset = CrossPoseDataset(data / split, kinds=(kind,))
            expected = _errors_of(_policy_poses(policy, dataset), dataset)
            row = table[(split, kind)]
            assert row["n"] == PER_KIND
            assert row["rot_deg"] == pytest.approx(expected["rot_deg"].mean(), abs=1e-3)
            assert row["trans_m"] == pytest.approx(expected["trans_m"].mean(), abs=1e-6)
            assert row["point_m"] == pytest.approx(expected["point_m"].mean(), abs=1e-6)
            if split == "val":
                per_sample = per_sample_errors(policy.model, dataset, torch.arange(len(dataset)),
                                               policy.num_action_points, policy.num_anchor_points,
                                               subsets=cfg.subsets, mirror_views=cfg.mirror_views)
                np.testing.assert_allclose(per_sample["point_m"].numpy(), expected["point_m"], atol=1e-6, rtol=0)


def test_a_batch_of_scenes_gets_what_each_scene_gets_alone(data):
    policy = make_policy("tp", subsets=4)
    dataset = CrossPoseDataset(data / "val", kinds=(FREE,))
    args = (policy.num_action_points, policy.num_anchor_points, 4, True, 11)
    batched = ensemble_predict(policy.model, dataset.action, dataset.anchor, *args)
    assert batched.transform.shape == (PER_KIND, 4, 4) and batched.transform.dtype == torch.float64
    assert batched.first.transform.shape == (PER_KIND, 4, 4) and len(batched.picks) == 4
    for i in range(PER_KIND):
        alone = ensemble_predict(policy.model, dataset.action[i], dataset.anchor[i], *args)
        assert alone.transform.shape == (4, 4) and alone.first.transform.shape == (1, 4, 4)
        torch.testing.assert_close(batched.transform[i], alone.transform, atol=POSE_TOLERANCE, rtol=0)
        for (a, b), (c, d) in zip(batched.picks, alone.picks):
            np.testing.assert_array_equal(a, c)
            np.testing.assert_array_equal(b, d)


def test_the_subsets_are_the_seeded_draws_action_then_anchor():
    """The draws the simulator's numbers depend on: per subset the action points, then the anchor
    points, from one NumPy generator seeded per answer; clouds no larger than the input go in whole."""
    policy = make_policy("gf", subsets=3)
    rng = np.random.default_rng(2)
    action = rng.uniform(-0.1, 0.1, (OBSERVED_ACTION, 3)).astype(np.float32)
    anchor = rng.uniform(-0.4, 0.4, (OBSERVED_ANCHOR, 3)).astype(np.float32)
    answer = ensemble_predict(policy.model, action, anchor, policy.num_action_points, policy.num_anchor_points, 3,
                              True, seed=9)
    draws = np.random.default_rng(9)
    for ia, ib in answer.picks:
        np.testing.assert_array_equal(ia, np.sort(draws.choice(OBSERVED_ACTION, policy.num_action_points, replace=False)))
        np.testing.assert_array_equal(ib, np.sort(draws.choice(OBSERVED_ANCHOR, policy.num_anchor_points, replace=False)))
    small = ensemble_predict(policy.model, action[:100], anchor[:400], policy.num_action_points,
                             policy.num_anchor_points, 3, True, seed=9)
    assert len(small.picks) == 1  # every subset would be the whole of both clouds
    np.testing.assert_array_equal(small.picks[0][0], np.arange(100))
    assert random_subset(5, 10, np.random.default_rng(0)).tolist() == [0, 1, 2, 3, 4]


@pytest.mark.parametrize("action_shape, anchor_shape, match", [
    ((0, 3), (50, 3), "action"), ((40, 2), (50, 3), "action"), ((40, 3), (50, 3, 1), "anchor"),
    ((2, 40, 3), (3, 50, 3), "same scenes"), ((40, 3), (1, 50, 3), "same scenes"),
])
def test_bad_shapes_are_refused(action_shape, anchor_shape, match):
    policy = make_policy("gf")
    with pytest.raises(ValueError, match=match):
        ensemble_predict(policy.model, torch.zeros(action_shape), torch.zeros(anchor_shape), 128, 512, 2, True, 0)
    with pytest.raises(ValueError, match="subsets"):
        ensemble_predict(policy.model, torch.zeros(40, 3), torch.zeros(50, 3), 128, 512, 0, True, 0)
