"""Door goals turned past the stop (wpbench.training.past_stop): exact answers for a known
hinge, properties over random hinges, drawers and free objects untouched, and the trainer
training on the turned goals while it validates on the true ones."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from wpbench.data.synthetic import write_synthetic_split
from wpbench.names import ARTICULATED, FREE, KIND_CODE
from wpbench.training.config import TrainConfig
from wpbench.training.loop import train
from wpbench.training.past_stop import turn_doors_past_stop


def _door_goal(axis, point, degrees: float) -> np.ndarray:
    """The motion of a door turned ``degrees`` about the line through ``point`` along ``axis``."""
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    R = Rotation.from_rotvec(np.deg2rad(degrees) * axis).as_matrix()
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(point) - R @ np.asarray(point)
    return T


def _turn(goals: list[np.ndarray], kinds: list[str], degrees: float, max_turn_deg: float | None = None):
    T = torch.tensor(np.stack(goals))
    table = T[:, None].repeat(1, 3, 1, 1)
    kind = torch.tensor([KIND_CODE[k] for k in kinds])
    return turn_doors_past_stop(T, table, kind, degrees, max_turn_deg)


def test_a_door_turned_100_deg_about_a_known_hinge_becomes_the_same_door_turned_110():
    hinge_axis, hinge_point = [0.0, 0.0, 1.0], [0.31, -0.42, 0.0]
    goals, table, turned = _turn([_door_goal(hinge_axis, hinge_point, 100.0)], [ARTICULATED], 10.0)
    expected = _door_goal(hinge_axis, hinge_point, 110.0)
    assert turned == 1
    np.testing.assert_allclose(goals[0].numpy(), expected, atol=1e-12)
    for row in table[0]:
        np.testing.assert_allclose(row.numpy(), expected, atol=1e-12)


def test_a_door_hinged_at_the_bottom_or_top_is_left_at_its_stop():
    # An oven's door: its hinge along x; turned past the horizontal its top would head for the floor.
    oven = _door_goal([1.0, 0.0, 0.0], [0.0, 0.0, 0.1], -90.0)
    tilted = _door_goal([np.sin(np.deg2rad(35.0)), 0.0, np.cos(np.deg2rad(35.0))], [0.3, 0.0, 0.0], 80.0)
    leaning = _door_goal([np.sin(np.deg2rad(25.0)), 0.0, np.cos(np.deg2rad(25.0))], [0.3, 0.0, 0.0], 80.0)
    goals, _, turned = _turn([oven, tilted, leaning], [ARTICULATED] * 3, 10.0)
    assert turned == 1
    np.testing.assert_array_equal(goals[0].numpy(), oven)
    np.testing.assert_array_equal(goals[1].numpy(), tilted)
    expected = _door_goal([np.sin(np.deg2rad(25.0)), 0.0, np.cos(np.deg2rad(25.0))], [0.3, 0.0, 0.0], 90.0)
    np.testing.assert_allclose(goals[2].numpy(), expected, atol=1e-12)


def test_drawers_free_objects_and_doors_already_at_their_stop_are_left_as_they_are():
    drawer = np.eye(4)
    drawer[:3, 3] = [0.0, -0.3, 0.0]
    free = _door_goal([0.0, 0.0, 1.0], [0.1, 0.2, 0.3], 40.0)
    shut = _door_goal([0.0, 0.0, 1.0], [0.5, 0.0, 0.0], 0.5)
    door = _door_goal([0.0, 0.0, 1.0], [0.5, 0.0, 0.0], 60.0)
    before = [drawer, free, shut, door]
    goals, table, turned = _turn(before, [ARTICULATED, FREE, ARTICULATED, ARTICULATED], 12.0)
    assert turned == 1
    for i in range(3):
        np.testing.assert_array_equal(goals[i].numpy(), before[i])
        np.testing.assert_array_equal(table[i, 2].numpy(), before[i])
    np.testing.assert_allclose(goals[3].numpy(), _door_goal([0.0, 0.0, 1.0], [0.5, 0.0, 0.0], 72.0), atol=1e-12)


def test_a_cap_on_the_whole_turn_stops_wide_doors_at_it_and_leaves_narrow_ones_their_full_extra():
    hinge = ([0.0, 0.0, 1.0], [0.4, 0.1, 0.0])
    stops = [100.0, 137.0, 145.0, 150.0, 160.0]
    goals, table, turned = _turn([_door_goal(*hinge, d) for d in stops], [ARTICULATED] * 5, 20.0, max_turn_deg=150.0)
    assert turned == 3                          # 150 and 160 are at or beyond the cap already
    for got, want in zip(goals, [120.0, 150.0, 150.0, 150.0, 160.0]):
        np.testing.assert_allclose(got.numpy(), _door_goal(*hinge, want), atol=1e-12)
    np.testing.assert_allclose(table[1, 0].numpy(), _door_goal(*hinge, 150.0), atol=1e-12)


@pytest.mark.parametrize("cap", [0.0, 181.0, float("nan")])
def test_a_cap_outside_0_to_180_degrees_is_refused(cap):
    T = torch.eye(4)[None]
    with pytest.raises(ValueError, match="max_turn_deg"):
        turn_doors_past_stop(T, T[:, None], torch.tensor([0]), 10.0, cap)


def test_zero_degrees_changes_nothing_and_a_copy_is_returned():
    T = _door_goal([0.0, 1.0, 0.0], [0.2, 0.0, 0.0], 80.0)
    original = torch.tensor(T[None])
    goals, table, turned = turn_doors_past_stop(original, original[:, None], torch.tensor([0]), 0.0)
    assert turned == 0 and torch.equal(goals, original)
    goals[0, 0, 0] = 5.0
    assert original[0, 0, 0] != 5.0


# Side hinges: at most 25 deg from vertical, pointing up or down.
side_hinges = st.builds(lambda tilt, heading, up: [np.sin(tilt) * np.cos(heading), np.sin(tilt) * np.sin(heading),
                                                   np.cos(tilt) * (1 if up else -1)],
                        st.floats(0.0, np.deg2rad(25.0)), st.floats(0.0, 2 * np.pi), st.booleans())
points = st.tuples(*[st.floats(-1, 1)] * 3)


@settings(max_examples=60, deadline=None)
@given(axis=side_hinges, point=points, degrees=st.floats(5.0, 160.0), a=st.floats(0.0, 10.0), b=st.floats(0.0, 10.0))
def test_every_point_on_the_hinge_stays_and_the_turn_grows_by_exactly_the_extra(axis, point, degrees, a, b):
    T = _door_goal(axis, point, degrees)
    once, _, _ = _turn([T], [ARTICULATED], a + b)
    twice, _, _ = _turn([_turn([T], [ARTICULATED], a)[0][0].numpy()], [ARTICULATED], b)
    moved = once[0].numpy()
    unit = np.asarray(axis) / np.linalg.norm(axis)
    for s in (-0.5, 0.0, 2.0):
        on_hinge = np.append(np.asarray(point) + s * unit, 1.0)
        np.testing.assert_allclose(moved @ on_hinge, on_hinge, atol=1e-9)
    turn = np.rad2deg(Rotation.from_matrix(moved[:3, :3]).magnitude())
    assert turn == pytest.approx(min(degrees + a + b, 360.0 - degrees - a - b), abs=1e-6)
    np.testing.assert_allclose(twice[0].numpy(), moved, atol=1e-9)


@pytest.mark.parametrize("degrees", [-1.0, 90.0, float("nan")])
def test_an_extra_turn_outside_0_to_90_degrees_is_refused(degrees):
    T = torch.eye(4)[None]
    with pytest.raises(ValueError, match="past the stop"):
        turn_doors_past_stop(T, T[:, None], torch.tensor([0]), degrees)


def test_mismatched_shapes_are_refused():
    T = torch.eye(4).repeat(2, 1, 1)
    with pytest.raises(ValueError, match="gt_equivalents"):
        turn_doors_past_stop(T, T[:1, None], torch.tensor([0, 0]), 5.0)
    with pytest.raises(ValueError, match="kind"):
        turn_doors_past_stop(T, T[:, None], torch.tensor([0]), 5.0)


TINY_GF = {"encoder": {"k": 4, "edge_channels": [8, 8], "emb_dim": 16, "groups": 4}, "head_hidden": 16}


def test_the_trainer_trains_on_turned_goals_records_it_and_refuses_to_resume_with_another(tmp_path, monkeypatch):
    write_synthetic_split(tmp_path / "data", "train", per_kind=4, num_action_points=32, num_anchor_points=48)
    write_synthetic_split(tmp_path / "data", "val", per_kind=3, num_action_points=32, num_anchor_points=48, seed=1)
    import wpbench.training.loop as loop

    seen = {}
    real_batches = loop.training_batches

    def spying_batches(train_set, *args, **kwargs):
        seen["train"] = train_set.gt_transform.clone()
        return real_batches(train_set, *args, **kwargs)

    monkeypatch.setattr(loop, "training_batches", spying_batches)
    base = dict(policy="gf", data=tmp_path / "data", out=tmp_path / "run", weights_root=tmp_path, max_steps=1,
                steps_per_epoch=1, batch_size=2, num_action_points=24, num_anchor_points=40, val_per_kind=2,
                final_val_per_kind=3, model_overrides=TINY_GF)
    messages = []
    train(TrainConfig(**base, door_past_stop_deg=15.0), echo=messages.append)

    from wpbench.data.dataset import CrossPoseDataset
    stored = CrossPoseDataset(tmp_path / "data" / "train", (ARTICULATED,))
    expected, _, turned = turn_doors_past_stop(stored.gt_transform, stored.gt_equivalents, stored.kind, 15.0)
    assert turned > 0 and not torch.equal(expected, stored.gt_transform)
    assert torch.equal(seen["train"], expected)
    assert any(f"turned 15 deg past the stop in {turned} training samples" in m for m in messages)
    import json
    assert json.loads((tmp_path / "run" / "config.json").read_text())["train_config"]["door_past_stop_deg"] == 15.0

    with pytest.raises(ValueError, match="15 deg past the stop, not 0 deg past the stop"):
        train(TrainConfig(**{**base, "max_steps": 2}), echo=lambda _: None)
    with pytest.raises(ValueError, match=r"15 deg past the stop, not 15 deg past the stop \(at most 120 deg in all\)"):
        train(TrainConfig(**{**base, "max_steps": 2}, door_past_stop_deg=15.0, door_max_turn_deg=120.0), echo=lambda _: None)
