"""Loss functions and presets: zero at the truth, right terms per preset, gradients where intended."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from models_helpers import scene, small_model, small_overrides
from wpbench.geometry import se3
from wpbench.models import build_model, losses
from wpbench.models.loss_presets import LOSS_PRESETS, LossPreset, compute_loss
from wpbench.models.output import CrossPoseOutput


def _perfect_output(data) -> CrossPoseOutput:
    """An output that is exactly right in every diagnostic."""
    T = data["gt_transform"]
    p, q = data["action"], data["anchor"]
    B, NA = p.shape[:2]
    diagnostics = {
        "action_targets": se3.apply(T, p),
        "anchor_sources": se3.apply(se3.invert(T), q),
        "action_weights": torch.full((B, NA), 1.0 / NA, dtype=p.dtype),
        "anchor_weights": torch.full(q.shape[:2], 1.0 / q.shape[1], dtype=p.dtype),
        "flow": se3.apply(T, p) - p,
        "w": torch.full((B,), 0.5, dtype=p.dtype),
        "taxpose_transform": T.clone(),
        "goalflow_transform": T.clone(),
    }
    return CrossPoseOutput(transform=T.clone(), diagnostics=diagnostics)


@pytest.mark.parametrize("preset", sorted(LOSS_PRESETS))
def test_every_preset_is_zero_for_a_perfect_prediction_and_positive_otherwise(preset):
    data = scene(batch=2, dtype=torch.float64)
    total, terms = compute_loss(_perfect_output(data), data, preset)
    assert total.item() == pytest.approx(0.0, abs=1e-20)
    assert set(terms) == set(LOSS_PRESETS[preset].terms)

    wrong = _perfect_output(data)
    shift = se3.make_transform(torch.eye(3, dtype=torch.float64).expand(2, 3, 3), torch.tensor([0.05, 0.0, 0.0]).double().expand(2, 3))
    wrong.transform = shift @ wrong.transform
    wrong.diagnostics = {k: (v + 0.05 if v.shape[-1] == 3 and v.dim() == 3 else v) for k, v in wrong.diagnostics.items()}
    wrong.diagnostics["taxpose_transform"] = wrong.transform
    total_wrong, _ = compute_loss(wrong, data, preset)
    assert total_wrong.item() > 1e-4


def test_presets_use_different_terms():
    used = {name: preset.terms for name, preset in LOSS_PRESETS.items()}
    assert used["wp-og"] == ("point_displacement", "direct_correspondence", "correspondence_consistency", "goal_flow")
    assert used["wp-postsvd"] == ("post_svd_point",)
    assert used["wp-postsvd-t"] == ("post_svd_point", "rotation", "translation")
    assert "goal_flow" not in used["tp"] and used["gf"] == ("goal_flow",)
    assert len(set(used.values())) == len(used)
    assert LOSS_PRESETS["wp-og"].taxpose_pose == "output"


def test_presets_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        LOSS_PRESETS["tp"].point_displacement = 2.0


def test_point_displacement_loss_is_mean_squared_distance():
    data = scene(batch=1, dtype=torch.float64)
    offset = se3.make_transform(torch.eye(3, dtype=torch.float64)[None], torch.tensor([[0.03, 0.04, 0.0]], dtype=torch.float64))
    loss = losses.point_displacement_loss(offset @ data["gt_transform"], data["gt_transform"], data["action"])
    assert loss.item() == pytest.approx(0.05**2)


def test_rotation_and_translation_losses():
    angle = torch.tensor(0.3, dtype=torch.float64)
    c, s = torch.cos(angle), torch.sin(angle)
    R = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)[None]
    T = se3.make_transform(R, torch.zeros(1, 3, dtype=torch.float64))
    I = torch.eye(4, dtype=torch.float64)[None]
    assert losses.rotation_loss(T, I).item() == pytest.approx(8 * torch.sin(angle / 2).item() ** 2)
    # A rotation about the centroid leaves the centroid's goal where it was.
    centroid = torch.tensor([[1.0, 2.0, 0.0]], dtype=torch.float64)
    about_centroid = se3.make_transform(R, (centroid - (R @ centroid[..., None]).squeeze(-1)))
    assert losses.translation_loss(about_centroid, I, centroid).item() == pytest.approx(0.0, abs=1e-20)


def test_preset_that_needs_missing_diagnostic_says_so():
    data = scene(batch=1, dtype=torch.float64)
    with torch.no_grad():
        out = small_model("goalflow")(data["action"], data["anchor"])
    with pytest.raises(ValueError, match="action_targets"):
        compute_loss(out, data, "tp")
    with pytest.raises(ValueError, match="unknown loss preset"):
        compute_loss(out, data, "nope")
    with pytest.raises(ValueError, match="gt_transform"):
        compute_loss(out, {"action": data["action"], "anchor": data["anchor"]}, "gf")


def test_custom_preset_must_use_some_term():
    with pytest.raises(ValueError, match="no term"):
        LossPreset(name="empty")


def _mixing_head_gradient(preset: str) -> float:
    torch.manual_seed(0)
    model = build_model("weightedpose", **small_overrides("weightedpose")).double()
    data = scene(batch=2, dtype=torch.float64)
    total, _ = compute_loss(model(data["action"], data["anchor"]), data, preset)
    total.backward()
    grad = model.goalflow.mixing_head[-1].bias.grad
    return 0.0 if grad is None else grad.abs().sum().item()


def test_every_weightedpose_preset_trains_the_mixing_weight():
    """Each WeightedPose preset has a term on the fused pose, the only path to w."""
    assert _mixing_head_gradient("wp-og") > 0.0
    assert _mixing_head_gradient("wp-postsvd") > 0.0
    assert _mixing_head_gradient("wp-postsvd-t") > 0.0


def _turn_about_z(degrees: float, batch: int) -> torch.Tensor:
    angle = torch.tensor(degrees, dtype=torch.float64).deg2rad()
    c, s = torch.cos(angle), torch.sin(angle)
    R = torch.stack([torch.stack([c, -s, 0 * c]), torch.stack([s, c, 0 * c]), torch.tensor([0.0, 0.0, 1.0]).double()])
    return se3.make_transform(R.expand(batch, 3, 3), torch.zeros(batch, 3, dtype=torch.float64))


def test_the_retarget_gate_decides_whether_another_equivalent_goal_counts():
    """Stored goal T, an equally correct goal T turned 90 deg (as for a cube), a prediction turned
    60 deg: 30 deg from the other goal. A 15 deg gate trains it towards the stored goal; a 180 deg
    gate (always the nearest) towards the other, exactly as if that were the only goal."""
    data = scene(batch=2, dtype=torch.float64)
    T = data["gt_transform"]
    other = T @ _turn_about_z(90.0, 2)
    data["gt_equivalents"] = torch.stack([T, other], dim=1)
    output = _perfect_output(data)
    output.transform = T @ _turn_about_z(60.0, 2)
    stored_only, _ = compute_loss(output, data, "wp-postsvd-t", retarget_within_deg=15.0)
    nearest, _ = compute_loss(output, data, "wp-postsvd-t", retarget_within_deg=180.0)
    only_stored = {k: v for k, v in data.items() if k != "gt_equivalents"}
    against_stored, _ = compute_loss(output, only_stored, "wp-postsvd-t")
    against_other, _ = compute_loss(output, {**only_stored, "gt_transform": other}, "wp-postsvd-t")
    torch.testing.assert_close(stored_only, against_stored)
    torch.testing.assert_close(nearest, against_other)
    assert nearest.item() < stored_only.item()
