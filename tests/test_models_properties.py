"""Behaviour every cross-pose model must have: shapes, rigid output, equivariance, no batch coupling."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from models_helpers import MODEL_NAMES, scene, small_model
from wpbench.data.augment import yaw_rotations
from wpbench.geometry import se3
from wpbench.models import build_model

EXPECTED_DIAGNOSTICS = {
    "taxpose": {"action_targets": "NA3", "action_weights": "NA", "anchor_sources": "NB3", "anchor_weights": "NB"},
    "goalflow": {"flow": "NA3", "w": "B"},
    "weightedpose": {
        "flow": "NA3", "w": "B", "action_targets": "NA3", "action_weights": "NA",
        "anchor_sources": "NB3", "anchor_weights": "NB", "taxpose_transform": "T", "goalflow_transform": "T",
    },
}


def _expected_shape(code: str, B: int, NA: int, NB: int) -> tuple[int, ...]:
    return {"NA3": (B, NA, 3), "NA": (B, NA), "NB3": (B, NB, 3), "NB": (B, NB), "B": (B,), "T": (B, 4, 4)}[code]


def _assert_rigid(T: torch.Tensor, atol: float) -> None:
    R = T[:, :3, :3]
    eye = torch.eye(3, dtype=T.dtype).expand_as(R)
    assert torch.allclose(R.transpose(1, 2) @ R, eye, atol=atol)
    assert torch.allclose(torch.linalg.det(R), torch.ones(T.shape[0], dtype=T.dtype), atol=atol)
    bottom = torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=T.dtype).expand(T.shape[0], 4)
    assert torch.equal(T[:, 3], bottom)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_default_model_output_shapes_finite_and_rigid(name):
    """Default sizes, default point counts (256 + 1024), float32."""
    torch.manual_seed(0)
    model = build_model(name).eval()
    data = scene(batch=2, action_points=256, anchor_points=1024)
    with torch.no_grad():
        out = model(data["action"], data["anchor"])
    assert out.transform.shape == (2, 4, 4) and out.transform.dtype == torch.float32
    assert torch.isfinite(out.transform).all()
    _assert_rigid(out.transform, atol=1e-5)
    assert set(out.diagnostics) == set(EXPECTED_DIAGNOSTICS[name])
    for key, code in EXPECTED_DIAGNOSTICS[name].items():
        assert out.diagnostics[key].shape == _expected_shape(code, 2, 256, 1024), key
        assert torch.isfinite(out.diagnostics[key]).all(), key


@pytest.mark.parametrize("name", ["taxpose", "weightedpose"])
def test_correspondence_weights_are_normalised_distributions(name):
    data = scene(batch=2, dtype=torch.float64)
    with torch.no_grad():
        out = small_model(name)(data["action"], data["anchor"])
    for key in ("action_weights", "anchor_weights"):
        weights = out.diagnostics[key]
        assert (weights >= 0).all()
        assert torch.allclose(weights.sum(dim=1), torch.ones(2, dtype=weights.dtype))


def test_mixing_weight_is_a_proportion_per_sample_or_per_point():
    torch.manual_seed(0)
    data = scene(batch=2, dtype=torch.float64)
    for mode, shape in (("per_sample", (2,)), ("per_point", (2, 48))):
        from models_helpers import small_overrides

        model = build_model("weightedpose", **small_overrides("weightedpose", w_mode=mode)).double().eval()
        # Make w differ from the 0.5 it starts at, so the range check means something.
        torch.nn.init.normal_(model.goalflow.mixing_head[-1].weight, std=3.0)
        with torch.no_grad():
            w = model(data["action"], data["anchor"]).diagnostics["w"]
        assert w.shape == shape
        assert ((w > 0) & (w < 1)).all() and w.std() > 0


@pytest.mark.parametrize("dynamic_graph", [False, True])
@pytest.mark.parametrize("name", MODEL_NAMES)
@settings(max_examples=5, deadline=None)
@given(shift=st.tuples(*[st.floats(-3.0, 3.0)] * 3))
def test_translation_equivariance(name, dynamic_graph, shift):
    """Moving both clouds by t moves the predicted goal of the action by t: T' (p + t) = T p + t."""
    model = small_model(name, dynamic_graph)
    data = scene(batch=1, dtype=torch.float64)
    t = torch.tensor(shift, dtype=torch.float64)
    with torch.no_grad():
        T = model(data["action"], data["anchor"]).transform
        T_moved = model(data["action"] + t, data["anchor"] + t).transform
    goal = se3.apply(T, data["action"])
    goal_moved = se3.apply(T_moved, data["action"] + t)
    assert torch.allclose(goal_moved, goal + t, atol=1e-8)


@pytest.mark.parametrize("name", MODEL_NAMES)
@settings(max_examples=5, deadline=None)
@given(yaw=st.floats(-math.pi, math.pi))
def test_yaw_equivariance(name, yaw):
    """Turning the whole scene by A about world z turns the prediction: T' = A T A^-1 (heading frame)."""
    _assert_yaw_equivariant(small_model(name), yaw)


def _assert_translation_equivariant(model: torch.nn.Module, shift) -> None:
    """Moving both clouds by ``shift`` moves the predicted goal of the action by it."""
    data = scene(batch=1, dtype=torch.float64)
    t = torch.tensor(shift, dtype=torch.float64)
    with torch.no_grad():
        T = model(data["action"], data["anchor"]).transform
        T_moved = model(data["action"] + t, data["anchor"] + t).transform
    assert torch.allclose(se3.apply(T_moved, data["action"] + t), se3.apply(T, data["action"]) + t, atol=1e-8)


def _assert_yaw_equivariant(model: torch.nn.Module, yaw: float) -> None:
    data = scene(batch=1, dtype=torch.float64)
    A = yaw_rotations(torch.tensor([yaw], dtype=torch.float64))
    R = A[:, :3, :3]
    with torch.no_grad():
        T = model(data["action"], data["anchor"]).transform
        T_turned = model(data["action"] @ R.transpose(1, 2), data["anchor"] @ R.transpose(1, 2)).transform
    assert torch.allclose(T_turned, A @ T @ A.transpose(1, 2), atol=1e-9)


def test_without_the_heading_frame_a_model_is_not_yaw_equivariant():
    """The property above comes from the heading frame, not from the data or luck."""
    from models_helpers import small_overrides

    torch.manual_seed(0)
    model = build_model("goalflow", **small_overrides("goalflow", heading_frame=False)).double().eval()
    # Non-zero output layers, so the flow depends on the input frame at all.
    for head in (model.flow_head, model.affine_head):
        torch.nn.init.normal_(head[-1].weight, std=0.5)
    data = scene(batch=1, dtype=torch.float64)
    A = yaw_rotations(torch.tensor([1.0], dtype=torch.float64))
    R = A[:, :3, :3]
    with torch.no_grad():
        T = model(data["action"], data["anchor"]).transform
        T_turned = model(data["action"] @ R.transpose(1, 2), data["anchor"] @ R.transpose(1, 2)).transform
    assert not torch.allclose(T_turned, A @ T @ A.transpose(1, 2), atol=1e-4)


@pytest.mark.parametrize("dynamic_graph", [False, True])
@pytest.mark.parametrize("name", MODEL_NAMES)
def test_sample_alone_equals_sample_in_batch(name, dynamic_graph):
    model = small_model(name, dynamic_graph)
    data = scene(batch=3, seed=5, dtype=torch.float64)
    with torch.no_grad():
        batched = model(data["action"], data["anchor"])
        alone = model(data["action"][1:2], data["anchor"][1:2])
    assert torch.allclose(batched.transform[1:2], alone.transform, atol=1e-10)
    for key, value in alone.diagnostics.items():
        assert torch.allclose(batched.diagnostics[key][1:2], value, atol=1e-10), key


def test_samples_do_not_couple_in_training_mode_either():
    """Training mode uses the same per-sample normalisation (no BatchNorm)."""
    model = small_model("weightedpose")
    data = scene(batch=2, seed=3, dtype=torch.float64)
    model.train()
    try:
        with torch.no_grad():
            batched = model(data["action"], data["anchor"]).transform
            alone = model(data["action"][:1], data["anchor"][:1]).transform
    finally:
        model.eval()
    assert torch.allclose(batched[:1], alone, atol=1e-10)


@pytest.mark.parametrize(
    "action, anchor, match",
    [
        (torch.randn(48, 3), torch.randn(1, 96, 3), r"\(B, N, 3\)"),
        (torch.randn(2, 48, 3), torch.randn(1, 96, 3), "batch sizes differ"),
        (torch.randn(1, 4, 3), torch.randn(1, 96, 3), "at least 8"),
        (torch.randn(1, 48, 2), torch.randn(1, 96, 3), r"\(B, N, 3\)"),
    ],
)
def test_bad_input_gets_a_clear_error(action, anchor, match):
    model = small_model("taxpose", dtype=torch.float32)
    with pytest.raises(ValueError, match=match):
        model(action, anchor)


def _goal_flow_reading_the_anchor_extent() -> torch.nn.Module:
    from models_helpers import small_overrides

    torch.manual_seed(0)
    model = build_model("goalflow", **small_overrides("goalflow", anchor_extent=True)).double().eval()
    # The heads start at zero output; give them weights so the extent inputs matter.
    for head in (model.flow_head, model.affine_head):
        torch.nn.init.normal_(head[-1].weight, std=0.1)
    return model


@settings(max_examples=5, deadline=None)
@given(shift=st.tuples(*[st.floats(-3.0, 3.0)] * 3), yaw=st.floats(-math.pi, math.pi))
def test_goal_flow_with_the_anchor_extent_stays_equivariant(shift, yaw):
    model = _goal_flow_reading_the_anchor_extent()
    _assert_translation_equivariant(model, shift)
    _assert_yaw_equivariant(model, yaw)


def test_the_anchor_extent_reaches_the_flow():
    model = _goal_flow_reading_the_anchor_extent()
    data = scene(batch=1, dtype=torch.float64)
    with torch.no_grad():
        before = model(data["action"], data["anchor"]).diagnostics["flow"]
        # Cut the six extent inputs of both flow heads: the flow must change.
        model.flow_head[0].weight[:, -6:] = 0.0
        model.affine_head[0].weight[:, -6:] = 0.0
        after = model(data["action"], data["anchor"]).diagnostics["flow"]
    assert not torch.allclose(before, after, atol=1e-6)


@settings(max_examples=5, deadline=None)
@given(yaw=st.floats(-math.pi, math.pi))
def test_goal_flow_in_the_action_panel_heading_is_yaw_equivariant(yaw):
    from models_helpers import small_overrides

    torch.manual_seed(0)
    model = build_model("goalflow", **small_overrides("goalflow", heading_source="action_panel")).double().eval()
    torch.nn.init.normal_(model.flow_head[-1].weight, std=0.1)
    _assert_yaw_equivariant(model, yaw)


def _tax_pose_seeing_heights():
    from models_helpers import small_overrides

    torch.manual_seed(0)
    return build_model("taxpose", **small_overrides("taxpose", absolute_height=True)).double().eval()


@settings(max_examples=5, deadline=None)
@given(shift=st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)), yaw=st.floats(-math.pi, math.pi))
def test_tax_pose_seeing_heights_stays_equivariant_on_the_floor(shift, yaw):
    """With ``absolute_height`` a horizontal move and a yaw of the scene still move the answer with it."""
    model = _tax_pose_seeing_heights()
    _assert_translation_equivariant(model, (shift[0], shift[1], 0.0))
    _assert_yaw_equivariant(model, yaw)


def test_tax_pose_seeing_heights_answers_a_lifted_scene_differently():
    """Lifting the whole scene 30 cm is a different scene for it; without the option it only lifts the answer."""
    data = scene(batch=1, dtype=torch.float64)
    lift = torch.tensor([0.0, 0.0, 0.3], dtype=torch.float64)
    for model, follows in ((_tax_pose_seeing_heights(), False), (small_model("taxpose"), True)):
        with torch.no_grad():
            T = model(data["action"], data["anchor"]).transform
            T_lifted = model(data["action"] + lift, data["anchor"] + lift).transform
        moved_with = torch.allclose(se3.apply(T_lifted, data["action"] + lift), se3.apply(T, data["action"]) + lift, atol=1e-6)
        assert moved_with == follows
