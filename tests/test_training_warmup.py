"""The WeightedPose mixing warm-up: the branches stay frozen, only w learns, then everything."""

from __future__ import annotations

import time

import pytest
import torch

from wpbench.models.configs import DGCNNConfig, GoalFlowConfig, TaxPoseConfig, WeightedPoseConfig
from wpbench.models.taxpose import TaxPose
from wpbench.models.weightedpose import WeightedPose
from wpbench.training.loop import phase_lr
from wpbench.training.specs import get_spec
from wpbench.training.warmup import MIXING_HEAD, in_warmup, set_phase

from tests.test_training import _config, _rows, data_root  # noqa: F401  (the module's tiny data fixture)
from wpbench.training.loop import train

TINY = DGCNNConfig(k=4, edge_channels=(8, 8), emb_dim=16, groups=4)


def _tiny_wp() -> WeightedPose:
    return WeightedPose(WeightedPoseConfig(goalflow=GoalFlowConfig(encoder=TINY, head_hidden=16),
                                           taxpose=TaxPoseConfig(encoder=TINY, attention_heads=2, head_hidden=16)))


def test_set_phase_freezes_everything_but_the_mixing_head_and_back():
    model = _tiny_wp()
    set_phase(model, mixing_only=True)
    trainable = {name for name, p in model.named_parameters() if p.requires_grad}
    assert trainable and all(name.startswith(MIXING_HEAD) for name in trainable)
    assert any(name.startswith("taxpose.") for name, _ in model.named_parameters())
    set_phase(model, mixing_only=False)
    assert all(p.requires_grad for p in model.parameters())


def test_a_model_without_a_mixing_head_cannot_warm_up():
    model = TaxPose(TaxPoseConfig(encoder=TINY, attention_heads=2, head_hidden=16))
    with pytest.raises(ValueError, match="mixing_warmup to 0"):
        set_phase(model, mixing_only=True)


def test_warmup_boundary_and_learning_rates():
    assert in_warmup(24.9, 100.0, 0.25) and not in_warmup(25.0, 100.0, 0.25)
    assert not in_warmup(0.0, 100.0, 0.0)
    spec = get_spec("wp-postsvd")
    assert phase_lr(spec, 1e-4, "cosine", 10.0, 100.0, 0.25) == spec.mixing_learning_rate
    # The cosine restarts at the end of the warm-up and ends at 5% of the base rate.
    assert phase_lr(spec, 1e-4, "cosine", 25.0, 100.0, 0.25) == pytest.approx(1e-4)
    assert phase_lr(spec, 1e-4, "cosine", 100.0, 100.0, 0.25) == pytest.approx(5e-6)
    assert phase_lr(spec, 1e-4, "cosine", 62.5, 100.0, 0.25) == pytest.approx(1e-4 * (0.05 + 0.95 * 0.5))


def _states(data_root, policy, warmup):  # noqa: F811
    _train_baselines_once(data_root)
    config = _config(data_root, policy, mixing_warmup=warmup, out=data_root / f"{policy}-{warmup}")
    train(config, echo=lambda _: None)
    gf = torch.load(data_root / "runs" / "gf" / "model.pt", weights_only=True)
    tp = torch.load(data_root / "runs" / "tp" / "model.pt", weights_only=True)
    after = torch.load(config.out / "model.pt", weights_only=True)
    return config, gf, tp, after


def _changed(before: dict, after: dict, prefix: str) -> set[str]:
    return {key for key, value in before.items() if not torch.equal(value, after[prefix + key])}


def test_a_warmup_run_changes_the_mixing_head_and_nothing_else(data_root):  # noqa: F811
    config, gf, tp, after = _states(data_root, "wp-postsvd", 0.99)
    assert not _changed(tp, after, "taxpose.")
    changed = _changed(gf, after, "goalflow.")
    assert changed and all(key.startswith("mixing_head.") for key in changed)
    assert {row["mixing_only"] for row in _rows(config.out)} == {"1"}


def test_without_warmup_the_branches_train_too(data_root):  # noqa: F811
    config, gf, tp, after = _states(data_root, "wp-postsvd", 0.0)
    assert _changed(tp, after, "taxpose.")
    assert any(not key.startswith("mixing_head.") for key in _changed(gf, after, "goalflow."))
    assert {row["mixing_only"] for row in _rows(config.out)} == {"0"}


def _step_budget_run(data_root, out, echo=lambda _: None, **kw):  # noqa: F811
    """A wp-postsvd run of 4 steps (half of them warm-up) under a 30-minute cap; ``kw`` changes it."""
    _train_baselines_once(data_root)
    settings = {"max_steps": None, "steps": 4, "minutes": 30.0, "mixing_warmup": 0.5, **kw}
    config = _config(data_root, "wp-postsvd", out=out, **settings)
    metrics = train(config, echo=echo)
    return config, metrics


def _train_baselines_once(data_root):  # noqa: F811
    for baseline in ("gf", "tp"):
        if not (data_root / "runs" / baseline / "model.pt").is_file():
            train(_config(data_root, baseline), echo=lambda _: None)


def test_a_step_budget_runs_warmup_and_schedule_over_steps(data_root, tmp_path):  # noqa: F811
    config, metrics = _step_budget_run(data_root, tmp_path / "steps")
    rows = _rows(config.out)
    spec = get_spec("wp-postsvd")
    base = spec.learning_rate
    assert metrics["steps"] == 4 and [int(r["step"]) for r in rows] == [1, 2, 3, 4]
    assert [r["mixing_only"] for r in rows] == ["1", "1", "0", "0"]  # half of 4 steps, not half of 30 min
    # One step per epoch logs that step's rate: the cosine over the 2 joint steps starts at the base.
    lrs = [float(r["lr"]) for r in rows]
    assert lrs[:2] == [pytest.approx(spec.mixing_learning_rate)] * 2
    assert lrs[2:] == [pytest.approx(base), pytest.approx(base * (0.05 + 0.95 * 0.5))]


def test_a_step_budget_gives_the_same_weights_on_a_slow_machine(data_root, tmp_path, monkeypatch):  # noqa: F811
    """What the budget is for: the same weights whether the run had the machine alone or not."""
    from wpbench.training import log as train_log

    fast, _ = _step_budget_run(data_root, tmp_path / "fast")
    write_log = train_log.write_log

    def slow_write_log(out, rows):
        write_log(out, rows)
        time.sleep(0.3)

    monkeypatch.setattr(train_log, "write_log", slow_write_log)
    slow, metrics = _step_budget_run(data_root, tmp_path / "slow")
    assert metrics["train_wall_s"] >= 1.2
    a = torch.load(fast.out / "model.pt", weights_only=True)
    b = torch.load(slow.out / "model.pt", weights_only=True)
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_a_step_budget_cut_by_the_minutes_cap_says_so(data_root, tmp_path):  # noqa: F811
    messages = []
    _, metrics = _step_budget_run(data_root, tmp_path / "cut", echo=messages.append, steps=10_000, minutes=1.0 / 60)
    assert metrics["steps"] < 10_000
    assert any("cap stopped the run" in m and "10000-step budget" in m for m in messages)
    with pytest.raises(ValueError, match="steps must be >= 1"):
        _config(data_root, "wp-postsvd", steps=0)
