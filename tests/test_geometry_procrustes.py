"""Weighted Procrustes, TAX-Pose dual-flow SVD and the WeightedPose SVD (the J(R, t) of docs/design.md)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import roma
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from wpbench.bench.svd import run
from wpbench.geometry import se3
from wpbench.geometry.procrustes import dual_flow_svd, weighted_pose_svd, weighted_procrustes

DTYPES = [torch.float32, torch.float64]
SETTINGS = settings(max_examples=50, deadline=None)
seeds = st.integers(0, 2**31 - 1)


# ----------------------------------------------------------------- helpers
def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation about unit ``axis`` by ``angle``, written out independently of the library."""
    axis = axis / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _objective(R, t, p, v, a, u, q, b, d, w) -> float:
    """The J(R, t) of docs/design.md for one sample, in numpy float64, straight from the formula.

    ``w`` scalar (the paper) or (NA,) (per-point variant: action pair i weighted
    (1 - w_i) a_i, flow pair i weighted w_i c_i, anchor block (1 - mean w)).
    """
    a = a / a.sum() / 2 if a.sum() > 0 else a
    b = b / b.sum() / 2 if b.sum() > 0 else b
    c = 1.0 / len(p)
    w = np.broadcast_to(np.asarray(w, dtype=np.float64), (len(p),))
    action_res = ((p @ R.T + t - v) ** 2).sum(-1)
    anchor_res = ((u @ R.T + t - q) ** 2).sum(-1)
    flow_res = ((p @ R.T + t - (p + d)) ** 2).sum(-1)
    return float(((1 - w) * a * action_res).sum() + (1 - w.mean()) * (b * anchor_res).sum() + (w * c * flow_res).sum())


def _pose_problem(generator: torch.Generator, B: int, NA: int, NB: int, dtype=torch.float64, noise: float = 0.3):
    """Random TAX-Pose / Goal Flow outputs roughly consistent with one rigid motion plus noise."""
    T = se3.make_transform(
        se3.random_rotation(B, generator=generator, dtype=dtype), torch.randn(B, 3, generator=generator, dtype=dtype)
    )
    p = torch.randn(B, NA, 3, generator=generator, dtype=dtype)
    q = torch.randn(B, NB, 3, generator=generator, dtype=dtype)
    v = se3.apply(T, p) + noise * torch.randn(B, NA, 3, generator=generator, dtype=dtype)
    u = se3.apply(se3.invert(T), q) + noise * torch.randn(B, NB, 3, generator=generator, dtype=dtype)
    d = se3.apply(T, p) - p + noise * torch.randn(B, NA, 3, generator=generator, dtype=dtype)
    a = torch.rand(B, NA, generator=generator, dtype=dtype)
    b = torch.rand(B, NB, generator=generator, dtype=dtype)
    return p, v, a, u, q, b, d


def _numpy_sample(tensors, i):
    return [x[i].detach().numpy().astype(np.float64) for x in tensors]


# ------------------------------------------------------ weighted Procrustes
@SETTINGS
@given(seed=seeds, dtype=st.sampled_from(DTYPES), n=st.integers(4, 60), offset=st.floats(-5.0, 5.0))
def test_exact_recovery_without_noise(seed: int, dtype: torch.dtype, n: int, offset: float) -> None:
    generator = torch.Generator().manual_seed(seed)
    R = se3.random_rotation(3, generator=generator, dtype=dtype)
    t = torch.randn(3, 3, generator=generator, dtype=dtype)
    source = torch.randn(3, n, 3, generator=generator, dtype=dtype) + offset
    target = source @ R.transpose(-1, -2) + t[:, None]
    weights = torch.rand(3, n, generator=generator, dtype=dtype) + 0.05
    T = weighted_procrustes(source, target, weights)
    tol = 5e-5 * (1 + abs(offset)) if dtype == torch.float32 else 1e-9
    assert T.dtype == dtype and T.shape == (3, 4, 4)
    torch.testing.assert_close(T[:, :3, :3], R, atol=tol, rtol=0)
    torch.testing.assert_close(T[:, :3, 3], t, atol=tol, rtol=0)


def test_matches_roma_reference() -> None:
    generator = torch.Generator().manual_seed(7)
    source = torch.randn(16, 30, 3, generator=generator, dtype=torch.float64)
    target = torch.randn(16, 30, 3, generator=generator, dtype=torch.float64)
    weights = torch.rand(16, 30, generator=generator, dtype=torch.float64)
    R_ref, t_ref = roma.rigid_points_registration(source, target, weights)
    T = weighted_procrustes(source, target, weights)
    torch.testing.assert_close(T[:, :3, :3], R_ref, atol=1e-9, rtol=0)
    torch.testing.assert_close(T[:, :3, 3], t_ref, atol=1e-9, rtol=0)


@SETTINGS
@given(seed=seeds, outliers=st.integers(1, 20))
def test_zero_weight_outliers_are_ignored(seed: int, outliers: int) -> None:
    generator = torch.Generator().manual_seed(seed)
    R = se3.random_rotation(2, generator=generator, dtype=torch.float64)
    source = torch.randn(2, 10, 3, generator=generator, dtype=torch.float64)
    target = source @ R.transpose(-1, -2)
    junk_source = 100 * torch.randn(2, outliers, 3, generator=generator, dtype=torch.float64)
    junk_target = 100 * torch.randn(2, outliers, 3, generator=generator, dtype=torch.float64)
    weights = torch.cat([torch.ones(2, 10, dtype=torch.float64), torch.zeros(2, outliers, dtype=torch.float64)], 1)
    T = weighted_procrustes(torch.cat([source, junk_source], 1), torch.cat([target, junk_target], 1), weights)
    torch.testing.assert_close(T[:, :3, :3], R, atol=1e-9, rtol=0)
    torch.testing.assert_close(T[:, :3, 3], torch.zeros(2, 3, dtype=torch.float64), atol=1e-9, rtol=0)


def test_only_weight_ratios_matter() -> None:
    generator = torch.Generator().manual_seed(2)
    source, target = torch.randn(2, 2, 12, 3, generator=generator, dtype=torch.float64)
    weights = torch.rand(2, 12, generator=generator, dtype=torch.float64)
    torch.testing.assert_close(
        weighted_procrustes(source, target, weights), weighted_procrustes(source, target, 1000 * weights)
    )


@SETTINGS
@given(seed=seeds, n=st.integers(4, 30))
def test_rotation_is_proper_even_when_the_best_fit_is_a_reflection(seed: int, n: int) -> None:
    generator = torch.Generator().manual_seed(seed)
    source = torch.randn(1, n, 3, generator=generator, dtype=torch.float64)
    mirror = torch.diag(torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64))
    target = source @ mirror @ se3.random_rotation(1, generator=generator, dtype=torch.float64).transpose(-1, -2)
    weights = torch.rand(1, n, generator=generator, dtype=torch.float64) + 0.1
    T = weighted_procrustes(source, target, weights)
    R = T[0, :3, :3]
    assert abs(float(torch.linalg.det(R)) - 1.0) < 1e-9
    torch.testing.assert_close(R @ R.T, torch.eye(3, dtype=torch.float64), atol=1e-9, rtol=0)
    # Global optimality over SO(3): no random rotation (with its own best t) does better.
    s, y, wt = (x[0].numpy() for x in (source, target, weights / weights.sum()))

    def cost(rotation: np.ndarray) -> float:
        t = wt @ y - rotation @ (wt @ s)
        return float((wt * ((s @ rotation.T + t - y) ** 2).sum(-1)).sum())

    best = cost(R.numpy())
    candidates = se3.random_rotation(2000, generator=generator, dtype=torch.float64).numpy()
    assert min(cost(c) for c in candidates) >= best - 1e-12


# ------------------------------------------------- WeightedPose / TAX-Pose
@SETTINGS
@given(seed=seeds, NA=st.integers(3, 20), NB=st.integers(3, 30), per_point=st.booleans())
def test_solution_minimises_J(seed: int, NA: int, NB: int, per_point: bool) -> None:
    generator = torch.Generator().manual_seed(seed)
    p, v, a, u, q, b, d = _pose_problem(generator, 2, NA, NB)
    w = torch.rand((2, NA) if per_point else (2,), generator=generator, dtype=torch.float64)
    T = weighted_pose_svd(p, v, a, u, q, b, d, w)
    rng = np.random.default_rng(seed)
    for i in range(2):
        sample = _numpy_sample((p, v, a, u, q, b, d), i)
        R, t = T[i, :3, :3].numpy(), T[i, :3, 3].numpy()
        best = _objective(R, t, *sample, w[i].numpy())
        for scale in (1e-4, 1e-2, 0.3):
            for _ in range(5):
                dR = _rodrigues(rng.normal(size=3), scale * rng.uniform(0.1, 1.0))
                dt = scale * rng.normal(size=3)
                for R2, t2 in ((dR @ R, t), (R, t + dt), (dR @ R, t + dt)):
                    assert _objective(R2, t2, *sample, w[i].numpy()) >= best - 1e-12 * (1 + best)


@SETTINGS
@given(seed=seeds)
def test_w_zero_is_dual_flow_svd(seed: int) -> None:
    generator = torch.Generator().manual_seed(seed)
    p, v, a, u, q, b, d = _pose_problem(generator, 3, 12, 25)
    expected = dual_flow_svd(p, v, a, u, q, b)
    torch.testing.assert_close(weighted_pose_svd(p, v, a, u, q, b, d, torch.zeros(3, dtype=torch.float64)), expected)
    torch.testing.assert_close(weighted_pose_svd(p, v, a, u, q, b, d, torch.zeros(3, 12, dtype=torch.float64)), expected)
    # dual_flow_svd weighs the two directions equally: duplicating every anchor pair changes nothing.
    doubled = dual_flow_svd(p, v, a, torch.cat([u, u], 1), torch.cat([q, q], 1), torch.cat([b, b], 1))
    torch.testing.assert_close(doubled, expected)


@SETTINGS
@given(seed=seeds)
def test_w_one_is_kabsch_on_the_goal_flow(seed: int) -> None:
    generator = torch.Generator().manual_seed(seed)
    p, v, a, u, q, b, d = _pose_problem(generator, 3, 12, 25)
    expected = weighted_procrustes(p, p + d, torch.ones(3, 12, dtype=torch.float64))
    ones = torch.ones(3, dtype=torch.float64)
    torch.testing.assert_close(weighted_pose_svd(p, v, a, u, q, b, d, ones), expected)
    # With w = 1 the TAX-Pose weights are unused, so all-zero ones are allowed.
    torch.testing.assert_close(
        weighted_pose_svd(p, v, torch.zeros_like(a), u, q, torch.zeros_like(b), d, ones), expected
    )
    R_ref, t_ref = roma.rigid_points_registration(p, p + d)
    torch.testing.assert_close(expected[:, :3, :3], R_ref)
    torch.testing.assert_close(expected[:, :3, 3], t_ref)


@SETTINGS
@given(seed=seeds, dtype=st.sampled_from(DTYPES))
def test_per_point_w_equals_per_sample_w_when_all_equal(seed: int, dtype: torch.dtype) -> None:
    generator = torch.Generator().manual_seed(seed)
    p, v, a, u, q, b, d = _pose_problem(generator, 3, 10, 20, dtype=dtype)
    w = torch.rand(3, generator=generator, dtype=dtype)
    per_sample = weighted_pose_svd(p, v, a, u, q, b, d, w)
    per_point = weighted_pose_svd(p, v, a, u, q, b, d, w[:, None].expand(3, 10).contiguous())
    tol = 1e-5 if dtype == torch.float32 else 1e-12
    torch.testing.assert_close(per_point, per_sample, atol=tol, rtol=0)


def test_per_point_w_moves_the_answer_towards_the_flow_where_w_is_high() -> None:
    # Goal Flow says "translate by +x", TAX-Pose says "stay". Raising w on every point
    # must move the solution monotonically from TAX-Pose's answer to Goal Flow's.
    p = torch.randn(1, 8, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    shift = torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)
    args = (p, p.clone(), torch.ones(1, 8, dtype=torch.float64), p.clone(), p.clone(), torch.ones(1, 8, dtype=torch.float64))
    flow = shift.expand(1, 8, 3)
    xs = [float(weighted_pose_svd(*args, flow, torch.full((1, 8), level, dtype=torch.float64))[0, 0, 3]) for level in (0.0, 0.25, 0.5, 0.75, 1.0)]
    assert xs[0] == pytest.approx(0.0, abs=1e-12) and xs[-1] == pytest.approx(1.0, abs=1e-12)
    assert all(later > earlier for earlier, later in zip(xs, xs[1:]))


# --------------------------------------------------------------- gradients
def test_gradcheck_weighted_procrustes() -> None:
    generator = torch.Generator().manual_seed(0)
    source = torch.randn(3, 9, 3, generator=generator, dtype=torch.float64, requires_grad=True)
    target = torch.randn(3, 9, 3, generator=generator, dtype=torch.float64, requires_grad=True)
    weights = (torch.rand(3, 9, generator=generator, dtype=torch.float64) + 0.1).requires_grad_(True)
    assert torch.autograd.gradcheck(weighted_procrustes, (source, target, weights))


@pytest.mark.parametrize("per_point", [False, True])
def test_gradcheck_weighted_pose_svd(per_point: bool) -> None:
    generator = torch.Generator().manual_seed(1)
    inputs = list(_pose_problem(generator, 2, 6, 7))
    inputs[2] = inputs[2] + 0.1
    inputs[5] = inputs[5] + 0.1
    w = torch.rand((2, 6) if per_point else (2,), generator=generator, dtype=torch.float64) * 0.8 + 0.1
    inputs = [x.clone().requires_grad_(True) for x in inputs + [w]]
    assert torch.autograd.gradcheck(weighted_pose_svd, tuple(inputs))


def test_gradient_is_finite_where_singular_values_repeat() -> None:
    # A square of points: two equal singular values. torch.linalg.svd's own backward
    # gives NaN here although the rotation is unique; ours must stay finite and correct.
    square = torch.tensor([[1.0, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], dtype=torch.float64)[None]
    R = se3.random_rotation(1, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    target = (square @ R.transpose(-1, -2)).requires_grad_(True)
    weights = torch.ones(1, 4, dtype=torch.float64)
    T = weighted_procrustes(square, target, weights)
    T.square().sum().backward()
    assert bool(torch.isfinite(target.grad).all())
    assert torch.autograd.gradcheck(lambda y: weighted_procrustes(square, y, weights), (target.detach().requires_grad_(True),))


def test_gradient_is_finite_for_collinear_points() -> None:
    line = torch.linspace(-1, 1, 6, dtype=torch.float64)[:, None] * torch.tensor([[1.0, 2.0, 0.5]], dtype=torch.float64)
    target = (line[None] + 0.3).requires_grad_(True)
    weighted_procrustes(line[None], target, torch.ones(1, 6, dtype=torch.float64)).sum().backward()
    assert bool(torch.isfinite(target.grad).all())


# ---------------------------------------------------------- degenerate input
def test_all_zero_weights_raise_with_the_fix() -> None:
    source = torch.randn(2, 5, 3)
    weights = torch.ones(2, 5)
    weights[1] = 0
    with pytest.raises(ValueError, match=r"samples \[1\].*positive weight"):
        weighted_procrustes(source, source, weights)
    with pytest.raises(ValueError, match="negative"):
        weighted_procrustes(source, source, -torch.ones(2, 5))


def test_zero_tax_pose_weights_raise_only_when_their_block_counts() -> None:
    p, v, a, u, q, b, d = _pose_problem(torch.Generator().manual_seed(0), 2, 5, 6)
    with pytest.raises(ValueError, match="action_weights sum to zero"):
        weighted_pose_svd(p, v, torch.zeros_like(a), u, q, b, d, torch.full((2,), 0.5, dtype=torch.float64))
    with pytest.raises(ValueError, match="anchor_weights sum to zero"):
        dual_flow_svd(p, v, a, u, q, torch.zeros_like(b))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        weighted_pose_svd(p, v, a, u, q, b, d, torch.full((2,), 1.5, dtype=torch.float64))


def test_nan_sample_gives_nan_output_and_leaves_others_alone() -> None:
    generator = torch.Generator().manual_seed(0)
    source = torch.randn(3, 6, 3, generator=generator, dtype=torch.float64)
    target = torch.randn(3, 6, 3, generator=generator, dtype=torch.float64)
    weights = torch.rand(3, 6, generator=generator, dtype=torch.float64)
    clean = weighted_procrustes(source, target, weights)
    target_nan = target.clone()
    target_nan[1, 2, 0] = float("nan")
    T = weighted_procrustes(source, target_nan, weights)
    assert bool(T[1].isnan().all())
    torch.testing.assert_close(T[[0, 2]], clean[[0, 2]])
    weights_nan = weights.clone()
    weights_nan[2, 0] = float("nan")
    assert bool(weighted_procrustes(source, target, weights_nan)[2].isnan().all())
    flow = torch.zeros(3, 6, 3, dtype=torch.float64)
    flow[0, 0, 0] = float("nan")
    w = torch.full((3,), 0.5, dtype=torch.float64)
    out = weighted_pose_svd(source, target, weights, source, target, weights, flow, w)
    assert bool(out[0].isnan().all()) and not bool(out[1:].isnan().any())


@pytest.mark.parametrize("dtype", DTYPES)
def test_collinear_and_coincident_points_give_a_valid_rotation(dtype: torch.dtype) -> None:
    direction = torch.tensor([1.0, 2.0, 2.0], dtype=dtype) / 3
    line = torch.linspace(-1, 1, 7, dtype=dtype)[:, None] * direction
    R_true = se3.random_rotation(1, generator=torch.Generator().manual_seed(5), dtype=dtype)[0]
    target = line @ R_true.T + torch.tensor([0.5, -1.0, 2.0], dtype=dtype)
    weights = torch.ones(1, 7, dtype=dtype)
    T = weighted_procrustes(line[None], target[None], weights)[0]
    R = T[:3, :3]
    tol = 1e-5 if dtype == torch.float32 else 1e-10
    assert bool(torch.isfinite(T).all())
    assert abs(float(torch.linalg.det(R)) - 1) < tol
    torch.testing.assert_close(se3.apply(T, line), target, atol=tol * 10, rtol=0)  # the line itself is matched
    same_point = torch.ones(1, 5, 3, dtype=dtype)
    T_point = weighted_procrustes(same_point, same_point + 2, torch.ones(1, 5, dtype=dtype))[0]
    assert abs(float(torch.linalg.det(T_point[:3, :3])) - 1) < tol
    torch.testing.assert_close(se3.apply(T_point, same_point[0]), same_point[0] + 2, atol=tol * 10, rtol=0)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((torch.zeros(5, 3), torch.zeros(5, 3), torch.ones(5)), "source must have shape"),
        ((torch.zeros(1, 5, 3), torch.zeros(1, 4, 3), torch.ones(1, 5)), "target must have shape"),
        ((torch.zeros(1, 5, 3), torch.zeros(1, 5, 3), torch.ones(1, 4)), "weights must have shape"),
        ((torch.zeros(1, 5, 3), torch.zeros(1, 5, 3, dtype=torch.float64), torch.ones(1, 5)), "share one dtype"),
        ((torch.zeros(1, 0, 3), torch.zeros(1, 0, 3), torch.ones(1, 0)), "no points"),
    ],
)
def test_bad_shapes_raise(args, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        weighted_procrustes(*args)


def test_bad_pose_shapes_raise() -> None:
    p, v, a, u, q, b, d = _pose_problem(torch.Generator().manual_seed(0), 2, 5, 6)
    with pytest.raises(ValueError, match="anchor_sources must have shape"):
        weighted_pose_svd(p, v, a, u[:, :4], q, b, d, torch.zeros(2, dtype=torch.float64))
    with pytest.raises(ValueError, match="flow must have shape"):
        weighted_pose_svd(p, v, a, u, q, b, d[:, :3], torch.zeros(2, dtype=torch.float64))
    with pytest.raises(ValueError, match=r"w must be a tensor of shape \(B,\)"):
        weighted_pose_svd(p, v, a, u, q, b, d, torch.zeros(2, 4, dtype=torch.float64))


def test_svd_benchmark_runs_and_agrees_with_roma(tmp_path, capsys) -> None:
    out = tmp_path / "svd.json"
    results = run(batch=4, points=50, repeats=2, json_path=out)
    written = json.loads(out.read_text())
    for key in ("batch", "points", "wpbench_ms", "roma_ms", "max_abs_diff", "dtype", "torch_threads"):
        assert key in written
    assert written["batch"] == 4 and written["points"] == 50
    assert results["max_abs_diff"] < 1e-9 and results["wpbench_ms"] > 0
    assert "roma.rigid_points_registration" in capsys.readouterr().out


@given(seed=st.integers(0, 2**31 - 1), k=st.integers(1, 5))
@settings(deadline=None)
def test_fusing_identical_predictions_returns_that_prediction(seed, k):
    from wpbench.models.subset_ensemble import fuse_goal_clouds

    g = torch.Generator().manual_seed(seed)
    points = torch.randn(2, 30, 3, generator=g, dtype=torch.float64)
    T = se3.make_transform(roma.random_rotmat(2, dtype=torch.float64), torch.randn(2, 3, generator=g, dtype=torch.float64))
    fused = fuse_goal_clouds(points, T.expand(k, -1, -1, -1))
    torch.testing.assert_close(fused, T, atol=1e-8, rtol=0)


def test_fusing_two_translations_gives_their_mean_and_two_turns_the_half_turn():
    from wpbench.models.subset_ensemble import fuse_goal_clouds

    # A box's corners: its covariance is diagonal, so averaging two opposite turns only shrinks it.
    corners = torch.tensor([[x, y, z] for x in (-1, 1) for y in (-2, 2) for z in (-3, 3)], dtype=torch.float64)
    points = (0.1 * corners + torch.tensor([0.5, -0.2, 0.8], dtype=torch.float64))[None]
    a, b = torch.eye(4, dtype=torch.float64), torch.eye(4, dtype=torch.float64)
    a[:3, 3] = torch.tensor([0.2, 0.0, 0.0], dtype=torch.float64)
    b[:3, 3] = torch.tensor([0.0, 0.4, 0.0], dtype=torch.float64)
    fused = fuse_goal_clouds(points, torch.stack([a, b])[:, None])
    torch.testing.assert_close(fused[0, :3, 3], torch.tensor([0.1, 0.2, 0.0], dtype=torch.float64), atol=1e-9, rtol=0)
    torch.testing.assert_close(fused[0, :3, :3], torch.eye(3, dtype=torch.float64), atol=1e-9, rtol=0)
    # Turns of +-20 deg about z through the cloud's centroid average to no turn.
    c = points[0].mean(dim=0)
    turns = []
    for angle in (0.35, -0.35):
        R = roma.rotvec_to_rotmat(torch.tensor([0.0, 0.0, angle], dtype=torch.float64))
        turns.append(se3.make_transform(R, c - R @ c))
    fused = fuse_goal_clouds(points, torch.stack(turns)[:, None])
    torch.testing.assert_close(fused[0], torch.eye(4, dtype=torch.float64), atol=1e-9, rtol=0)


def _turn_about(c: torch.Tensor, angle_rad: float) -> torch.Tensor:
    R = roma.rotvec_to_rotmat(torch.tensor([0.0, 0.0, angle_rad], dtype=torch.float64))
    return se3.make_transform(R, c - R @ c)


def test_consensus_averages_half_of_the_subsets_but_at_least_two():
    from wpbench.models.subset_ensemble import consensus_size

    assert [consensus_size(k) for k in (1, 2, 3, 4, 5, 8)] == [1, 2, 2, 2, 2, 4]


def test_fusing_keeps_one_of_two_equivalent_goals_instead_of_their_midpoint():
    from wpbench.models.subset_ensemble import fuse_goal_clouds

    # A cube's goals a quarter turn apart: two subsets answer +40 deg, two -40 deg. The plain
    # mean of the four goal clouds would be the 0 deg turn, 40 deg from both correct answers.
    g = torch.Generator().manual_seed(3)
    points = torch.randn(1, 40, 3, generator=g, dtype=torch.float64)
    c = points[0].mean(dim=0)
    plus, minus = _turn_about(c, math.radians(40.0)), _turn_about(c, math.radians(-40.0))
    fused = fuse_goal_clouds(points, torch.stack([plus, minus, minus, plus])[:, None])[0]
    assert min(torch.dist(fused, plus), torch.dist(fused, minus)) < 1e-9


def test_fusing_ignores_a_subset_that_disagrees():
    from wpbench.models.subset_ensemble import fuse_goal_clouds

    g = torch.Generator().manual_seed(5)
    points = torch.randn(1, 40, 3, generator=g, dtype=torch.float64)
    c = points[0].mean(dim=0)
    close = [_turn_about(c, math.radians(a)) for a in (29.8, 30.0, 30.2)]
    fused = fuse_goal_clouds(points, torch.stack([close[0], _turn_about(c, math.radians(-60.0)), *close[1:]])[:, None])
    angle = math.degrees(math.atan2(fused[0, 1, 0].item(), fused[0, 0, 0].item()))
    assert 29.8 <= angle <= 30.2


@given(seed=st.integers(0, 2**31 - 1), k=st.integers(1, 6))
@settings(deadline=None, max_examples=30)
def test_fusing_does_not_depend_on_the_order_of_the_subsets(seed, k):
    from wpbench.models.subset_ensemble import fuse_goal_clouds

    g = torch.Generator().manual_seed(seed)
    points = torch.randn(2, 30, 3, generator=g, dtype=torch.float64)
    T = se3.make_transform(roma.random_rotmat(k * 2, dtype=torch.float64), torch.randn(k * 2, 3, generator=g, dtype=torch.float64))
    T = T.reshape(k, 2, 4, 4)
    order = torch.randperm(k, generator=g)
    torch.testing.assert_close(fuse_goal_clouds(points, T[order]), fuse_goal_clouds(points, T), atol=1e-9, rtol=0)


def test_fusing_checks_shapes():
    from wpbench.models.subset_ensemble import fuse_goal_clouds

    with pytest.raises(ValueError, match="points"):
        fuse_goal_clouds(torch.zeros(5, 3), torch.eye(4)[None, None])
    with pytest.raises(ValueError, match="transforms"):
        fuse_goal_clouds(torch.zeros(2, 5, 3), torch.eye(4)[None, None])
    with pytest.raises(ValueError, match="at least one"):
        fuse_goal_clouds(torch.zeros(1, 5, 3), torch.zeros(0, 1, 4, 4))
