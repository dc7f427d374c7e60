"""Each model can fit one fixed sample: a few dozen Adam steps take its pose error from decimetres to < 1 cm."""

from __future__ import annotations

import pytest
import torch

from models_helpers import scene, small_overrides
from wpbench.geometry import metrics
from wpbench.models import build_model
from wpbench.models.loss_presets import compute_loss


@pytest.fixture
def one_thread():
    """One intra-op thread: these tiny models are faster without thread hand-offs, on a busy CPU too."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def _pose_error(model, data) -> float:
    with torch.no_grad():
        T = model(data["action"], data["anchor"]).transform
    return metrics.point_error(T, data["gt_transform"], data["action"])[0].item()


@pytest.mark.parametrize(
    "name, preset",
    [("taxpose", "tp"), ("goalflow", "gf"), ("weightedpose", "wp-postsvd"), ("weightedpose", "wp-og")],
)
def test_overfits_one_sample(name, preset, one_thread):
    torch.manual_seed(0)
    model = build_model(name, **small_overrides(name))
    data = scene(batch=1, action_points=64, anchor_points=256)
    before = _pose_error(model.eval(), data)
    model.train()
    steps = 80
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-2)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, steps)
    for _ in range(steps):
        total, _ = compute_loss(model(data["action"], data["anchor"]), data, preset)
        optimizer.zero_grad()
        total.backward()
        optimizer.step()
        schedule.step()
    after = _pose_error(model.eval(), data)
    assert before > 0.05, f"the sample should start far from its goal, got {before:.3f} m"
    assert after < 0.01, f"{name} with {preset}: mean point error {before:.3f} m -> {after:.4f} m"
