"""Building models by name, config overrides, and WeightedPose.from_pretrained."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import pytest
import torch

from models_helpers import scene, small_overrides
from wpbench.models import MODEL_CONFIGS, build_model, model_config
from wpbench.models.configs import GoalFlowConfig, TaxPoseConfig, WeightedPoseConfig
from wpbench.models.goalflow import GoalFlow
from wpbench.models.taxpose import TaxPose
from wpbench.models.weightedpose import WeightedPose


def test_registry_names_and_classes():
    assert set(MODEL_CONFIGS) == {"taxpose", "goalflow", "weightedpose"}
    assert isinstance(build_model("taxpose", **small_overrides("taxpose")), TaxPose)
    assert isinstance(build_model("goalflow", **small_overrides("goalflow")), GoalFlow)
    assert isinstance(build_model("weightedpose", **small_overrides("weightedpose")), WeightedPose)


def test_nested_overrides_change_only_what_they_name():
    config = model_config("weightedpose", taxpose={"encoder": {"k": 5}}, w_mode="per_point")
    assert config.taxpose.encoder.k == 5
    assert config.goalflow.encoder.k == WeightedPoseConfig().goalflow.encoder.k
    assert config.goalflow_branch.mixing_weight == "per_point"
    assert model_config("taxpose", encoder={"edge_channels": [8, 8]}).encoder.edge_channels == (8, 8)


def test_unknown_names_and_options_are_rejected_with_the_valid_choices():
    with pytest.raises(ValueError, match="choose one of"):
        build_model("pointnet")
    with pytest.raises(ValueError, match="valid options"):
        build_model("taxpose", hidden=3)
    with pytest.raises(ValueError, match="w_mode"):
        build_model("weightedpose", w_mode="per_object")


def test_reference_configs_are_the_published_size():
    for config in (TaxPoseConfig.reference(), GoalFlowConfig.reference()):
        assert config.encoder.emb_dim == 512 and config.encoder.k == 20 and config.encoder.dynamic_graph
        assert config.encoder.edge_channels == (64, 64, 128, 256)


def test_importing_the_registry_does_not_import_torch():
    code = "import sys, wpbench.models.registry, wpbench.models; print('torch' in sys.modules)"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "False"


def _trained_like_branches(seed: int = 1):
    """Branches with non-default weights, so loading them is observable."""
    torch.manual_seed(seed)
    config = model_config("weightedpose", **small_overrides("weightedpose"))
    goalflow, taxpose = GoalFlow(config.goalflow_branch), TaxPose(config.taxpose)
    with torch.no_grad():
        for parameter in [*goalflow.parameters(), *taxpose.parameters()]:
            parameter.add_(0.05 * torch.randn_like(parameter))
    return config, goalflow, taxpose


def test_from_pretrained_loads_both_branches():
    config, goalflow, taxpose = _trained_like_branches()
    model = WeightedPose.from_pretrained(goalflow.state_dict(), taxpose.state_dict(), config)
    for key, value in goalflow.state_dict().items():
        assert torch.equal(model.goalflow.state_dict()[key], value), key
    for key, value in taxpose.state_dict().items():
        assert torch.equal(model.taxpose.state_dict()[key], value), key
    data = scene(batch=1)
    with torch.no_grad():
        out = model.eval()(data["action"], data["anchor"])
        assert torch.allclose(out.diagnostics["flow"], goalflow.eval()(data["action"], data["anchor"]).diagnostics["flow"])
        tp = taxpose.eval()(data["action"], data["anchor"])
    assert torch.allclose(out.diagnostics["taxpose_transform"], tp.transform, atol=1e-6)


def test_from_pretrained_with_wrong_sizes_says_which_config_to_fix():
    config, goalflow, taxpose = _trained_like_branches()
    bigger = model_config("weightedpose", config, taxpose={"head_hidden": 48})
    with pytest.raises(ValueError, match="config.taxpose"):
        WeightedPose.from_pretrained(goalflow.state_dict(), taxpose.state_dict(), bigger)


def test_from_pretrained_per_point_keeps_a_fresh_mixing_head_and_warns():
    config, goalflow, taxpose = _trained_like_branches()
    per_point = model_config("weightedpose", config, w_mode="per_point")
    with pytest.warns(UserWarning, match="mixing head"):
        model = WeightedPose.from_pretrained(goalflow.state_dict(), taxpose.state_dict(), per_point)
    assert torch.equal(model.goalflow.flow_head[0].weight, goalflow.flow_head[0].weight)
    assert torch.count_nonzero(model.goalflow.mixing_head[-1].weight) == 0  # fresh: w starts at 0.5


def test_a_saved_config_without_the_newer_fields_builds_the_network_it_was_trained_as():
    """Weights saved before heading_source / anchor_extent existed were trained with the
    centroid heading and no extent input, whatever today's defaults are."""
    from wpbench.models.registry import saved_model_config

    old_goalflow = {"affine_flow": True, "head_hidden": 16, "heading_frame": True, "position_scale": 10.0}
    legacy = saved_model_config("goalflow", old_goalflow)
    assert (legacy.heading_source, legacy.anchor_extent) == ("centroids", False)
    assert legacy.head_hidden == 16
    nested = saved_model_config("weightedpose", {"goalflow": old_goalflow, "w_mode": "per_sample"})
    assert (nested.goalflow.heading_source, nested.goalflow.anchor_extent) == ("centroids", False)
    # A saved value always wins, and a config saved with every field is rebuilt exactly.
    assert saved_model_config("goalflow", {"heading_source": "action_panel"}).heading_source == "action_panel"
    today = model_config("goalflow")
    assert saved_model_config("goalflow", dataclasses.asdict(today)) == today
    # The legacy network has no extent inputs: its flow head is 6 inputs narrower.
    with_extent = dataclasses.replace(legacy, anchor_extent=True)
    assert GoalFlow(with_extent).flow_head[0].in_features - GoalFlow(legacy).flow_head[0].in_features == 6
