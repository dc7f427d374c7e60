"""Pose metrics and symmetry groups: rotation error (with symmetry), translation and point errors."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from wpbench.geometry import se3
from wpbench.geometry.metrics import (
    point_error,
    raw_translation_error,
    rotation_angle,
    rotation_error_deg,
    translation_error,
)
from wpbench.geometry.symmetry import Symmetry

SETTINGS = settings(max_examples=50, deadline=None)
seeds = st.integers(0, 2**31 - 1)
F64 = torch.float64


def _rodrigues(axis, angle: float) -> torch.Tensor:
    """Rotation about ``axis`` by ``angle`` (float64), written out independently of the library."""
    axis = torch.as_tensor(axis, dtype=F64)
    axis = axis / axis.norm()
    K = torch.tensor([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]], dtype=F64)
    return torch.eye(3, dtype=F64) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _acos_error_deg(R_pred: torch.Tensor, R_gt: torch.Tensor) -> torch.Tensor:
    """The textbook formula verbatim: acos(clip((trace(R_pred^T R_gt) - 1) / 2, -1, 1))."""
    cosine = ((R_pred.transpose(-1, -2) @ R_gt).diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2
    return torch.rad2deg(torch.acos(cosine.clamp(-1, 1)))


def _brute_force_deg(R_pred, R_gt, R_o, group_elements) -> torch.Tensor:
    """min over explicit group elements S of the world-frame error against R_gt R_o S R_o^T."""
    R_o = R_o.unsqueeze(-3)  # (B, 1, 3, 3) against the elements (M, 3, 3)
    equivalent_gt = R_gt.unsqueeze(-3) @ R_o @ group_elements @ R_o.transpose(-1, -2)  # (B, M, 3, 3)
    return _acos_error_deg(R_pred.unsqueeze(-3), equivalent_gt).amin(-1)


# --------------------------------------------------------- plain rotation
@SETTINGS
@given(seed=seeds)
def test_rotation_error_equals_design_formula(seed: int) -> None:
    generator = torch.Generator().manual_seed(seed)
    R_pred, R_gt = se3.random_rotation(2 * 16, generator=generator, dtype=F64).split(16)
    torch.testing.assert_close(rotation_error_deg(R_pred, R_gt), _acos_error_deg(R_pred, R_gt), atol=1e-6, rtol=0)


@pytest.mark.parametrize("degrees", [0.0, 1e-3, 0.5, 30.0, 90.0, 179.0, 180.0])
def test_rotation_error_of_a_known_turn(degrees: float) -> None:
    R_gt = se3.random_rotation(1, generator=torch.Generator().manual_seed(0), dtype=F64)
    R_pred = R_gt @ _rodrigues([1.0, -2.0, 0.5], math.radians(degrees))
    assert float(rotation_error_deg(R_pred, R_gt)[0]) == pytest.approx(degrees, abs=1e-7)
    # float32 keeps small errors too (acos of a rounded cosine would not).
    error32 = float(rotation_error_deg(R_pred.float(), R_gt.float())[0])
    assert error32 == pytest.approx(degrees, abs=2e-3)


def test_rotation_angle_shapes_and_gradient_at_zero() -> None:
    R = se3.random_rotation(6, generator=torch.Generator().manual_seed(1), dtype=F64).reshape(2, 3, 3, 3)
    assert rotation_angle(R).shape == (2, 3)
    R_pred = R[0].clone().requires_grad_(True)
    rotation_error_deg(R_pred, R[0].detach()).sum().backward()
    assert bool(torch.isfinite(R_pred.grad).all())


# ----------------------------------------------------------- symmetry
def test_ready_made_groups() -> None:
    cube = Symmetry.cube()
    assert cube.order == 24 and cube.axis is None
    assert len({tuple(np.round(m.numpy(), 6).ravel()) for m in cube.discrete}) == 24
    torch.testing.assert_close(cube.discrete[0], torch.eye(3, dtype=F64))
    assert Symmetry.none().is_trivial and not cube.is_trivial
    assert Symmetry.box().order == 4
    cylinder = Symmetry.cylinder((0.0, 2.0, 0.0))
    torch.testing.assert_close(cylinder.axis, torch.tensor([0.0, 1.0, 0.0], dtype=F64))
    assert cylinder.order == 2
    torch.testing.assert_close(cylinder.discrete[1] @ cylinder.axis, -cylinder.axis, atol=1e-12, rtol=0)
    axial = Symmetry.axial((1.0, 1.0, 0.0))
    assert axial.order == 1 and axial.axis is not None
    half_turn = torch.diag(torch.tensor([-1.0, -1.0, 1.0], dtype=F64))
    assert Symmetry.from_discrete([half_turn]).order == 2  # identity added


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: Symmetry(torch.diag(torch.tensor([-1.0, -1.0, 1.0], dtype=F64))[None]), "identity"),
        (lambda: Symmetry(torch.stack([torch.eye(3, dtype=F64), _rodrigues([0, 0, 1], 1.0)])), "closed"),
        (lambda: Symmetry(torch.stack([torch.eye(3, dtype=F64), -torch.eye(3, dtype=F64)])), "rotations"),
        (lambda: Symmetry(torch.eye(3, dtype=F64)[None], axis=(0.0, 0.0, 0.0)), "non-zero"),
        (lambda: Symmetry(torch.zeros(2, 3), axis=None), r"\(K, 3, 3\)"),
        (lambda: Symmetry.from_discrete([_rodrigues([1, 0, 0], math.pi)]).__class__(
            Symmetry.from_discrete([_rodrigues([1, 0, 0], math.pi)]).discrete, axis=(1.0, 1.0, 0.0)), "axis"),
    ],
)
def test_invalid_groups_raise(make, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make()


@SETTINGS
@given(seed=seeds, use_object_rotation=st.booleans())
def test_discrete_symmetric_error_equals_brute_force(seed: int, use_object_rotation: bool) -> None:
    generator = torch.Generator().manual_seed(seed)
    R_pred, R_gt, R_o = se3.random_rotation(3 * 8, generator=generator, dtype=F64).split(8)
    if not use_object_rotation:
        R_o = torch.eye(3, dtype=F64).expand(8, 3, 3)
    for symmetry in (Symmetry.cube(), Symmetry.box()):
        got = rotation_error_deg(R_pred, R_gt, symmetry, R_o if use_object_rotation else None)
        torch.testing.assert_close(got, _brute_force_deg(R_pred, R_gt, R_o, symmetry.discrete), atol=1e-6, rtol=0)
        assert bool((got <= rotation_error_deg(R_pred, R_gt) + 1e-9).all())


@settings(max_examples=25, deadline=None)
@given(seed=seeds, flip=st.booleans())
def test_continuous_symmetric_error_equals_brute_force_over_the_twist(seed: int, flip: bool) -> None:
    generator = torch.Generator().manual_seed(seed)
    R_pred, R_gt, R_o = se3.random_rotation(3 * 4, generator=generator, dtype=F64).split(4)
    axis = torch.randn(3, generator=generator, dtype=F64)
    symmetry = Symmetry.cylinder(axis) if flip else Symmetry.axial(axis)
    # Brute force: every group element S_k Rot(axis, theta) on a 0.05 degree grid.
    thetas = torch.linspace(0, 2 * math.pi, 7201, dtype=F64)[:-1, None, None]
    a = symmetry.axis
    K = torch.tensor([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]], dtype=F64)
    twists = torch.eye(3, dtype=F64) + torch.sin(thetas) * K + (1 - torch.cos(thetas)) * (K @ K)  # Rodrigues, batched
    elements = (symmetry.discrete[:, None] @ twists[None]).reshape(-1, 3, 3)
    brute = _brute_force_deg(R_pred, R_gt, R_o, elements)
    got = rotation_error_deg(R_pred, R_gt, symmetry, R_o)
    assert bool((got <= brute + 1e-9).all())  # closed form is the exact minimum, below any grid point
    assert bool((brute - got <= 0.03).all())  # and the grid gets within half a step of it


@SETTINGS
@given(seed=seeds)
def test_symmetric_cube_pose_scores_zero_and_the_frame_matters(seed: int) -> None:
    """Physical check: a prediction that puts the cube's corners exactly where the truth
    puts them (as a set) scores 0, although its rotation differs; symmetries applied in
    the wrong frame (world instead of object) would not produce the same corners."""
    generator = torch.Generator().manual_seed(seed)
    R_gt, R_o = se3.random_rotation(2, generator=generator, dtype=F64)
    corners_object = torch.tensor(list(itertools.product((-1.0, 1.0), repeat=3)), dtype=F64) * 0.05
    corners_now = corners_object @ R_o.T  # the cube as it sits in the world

    def same_set(a: torch.Tensor, b: torch.Tensor) -> bool:
        return bool((torch.cdist(a, b).amin(1) < 1e-9).all())

    cube = Symmetry.cube()
    S = cube.discrete[int(torch.randint(1, 24, (1,), generator=generator))]
    R_pred = R_gt @ R_o @ S @ R_o.T
    assert same_set(corners_now @ R_pred.T, corners_now @ R_gt.T)
    error = rotation_error_deg(R_pred[None], R_gt[None], cube, R_o[None])
    assert float(error[0]) == pytest.approx(0.0, abs=1e-6)
    assert float(rotation_error_deg(R_pred[None], R_gt[None])[0]) > 1.0
    wrong_frame = R_gt @ S  # the tempting but wrong product: S applied in the world frame
    assert not same_set(corners_now @ wrong_frame.T, corners_now @ R_gt.T)
    assert float(rotation_error_deg(wrong_frame[None], R_gt[None], cube, R_o[None])[0]) > 1e-3


def test_cylinder_equivalents_score_zero() -> None:
    generator = torch.Generator().manual_seed(3)
    R_gt, R_o = se3.random_rotation(2, generator=generator, dtype=F64)
    symmetry = Symmetry.cylinder((0.0, 0.0, 1.0))
    for S in (_rodrigues([0, 0, 1], 1.234), symmetry.discrete[1] @ _rodrigues([0, 0, 1], -2.0)):
        R_pred = R_gt @ R_o @ S @ R_o.T
        assert float(rotation_error_deg(R_pred[None], R_gt[None], symmetry, R_o[None])[0]) == pytest.approx(0.0, abs=1e-6)
    # A tilt of the axis by 10 degrees is a real error of 10 degrees, whatever the twist.
    tilt = R_gt @ R_o @ _rodrigues([1, 0, 0], math.radians(10)) @ _rodrigues([0, 0, 1], 0.7) @ R_o.T
    assert float(rotation_error_deg(tilt[None], R_gt[None], symmetry, R_o[None])[0]) == pytest.approx(10.0, abs=1e-6)


# ------------------------------------------------ translation and points
@SETTINGS
@given(seed=seeds, dtype=st.sampled_from([torch.float32, F64]))
def test_translation_error_is_goal_centroid_distance_and_origin_free(seed: int, dtype: torch.dtype) -> None:
    generator = torch.Generator().manual_seed(seed)
    def transforms():
        return se3.make_transform(
            se3.random_rotation(5, generator=generator, dtype=dtype), torch.randn(5, 3, generator=generator, dtype=dtype)
        )
    T_pred, T_gt, shift = transforms(), transforms(), transforms()
    centroid = torch.randn(5, 3, generator=generator, dtype=dtype)
    expected = (
        (T_pred[:, :3, :3] @ centroid[..., None] + T_pred[:, :3, 3:]) - (T_gt[:, :3, :3] @ centroid[..., None] + T_gt[:, :3, 3:])
    ).squeeze(-1).norm(dim=-1)
    tol = 1e-5 if dtype == torch.float32 else 1e-12
    torch.testing.assert_close(translation_error(T_pred, T_gt, centroid), expected, atol=tol, rtol=0)
    torch.testing.assert_close(raw_translation_error(T_pred, T_gt), (T_pred[:, :3, 3] - T_gt[:, :3, 3]).norm(dim=-1))
    # Re-express everything in another world frame: the centroid metric does not change.
    moved = [shift @ T @ se3.invert(shift) for T in (T_pred, T_gt)]
    moved_centroid = se3.apply(shift, centroid[:, None])[:, 0]
    torch.testing.assert_close(translation_error(*moved, moved_centroid), expected, atol=tol * 20, rtol=0)


@SETTINGS
@given(seed=seeds)
def test_point_error_mean_and_mse(seed: int) -> None:
    generator = torch.Generator().manual_seed(seed)
    T_pred, T_gt = (
        se3.make_transform(se3.random_rotation(3, generator=generator, dtype=F64), torch.randn(3, 3, generator=generator, dtype=F64))
        for _ in range(2)
    )
    points = torch.randn(3, 11, 3, generator=generator, dtype=F64)
    mean_err, mse = point_error(T_pred, T_gt, points)
    for b in range(3):
        distances = [
            float(np.linalg.norm((T_pred[b, :3, :3] @ p + T_pred[b, :3, 3] - T_gt[b, :3, :3] @ p - T_gt[b, :3, 3]).numpy()))
            for p in points[b]
        ]
        assert float(mean_err[b]) == pytest.approx(np.mean(distances), abs=1e-12)
        assert float(mse[b]) == pytest.approx(np.mean(np.square(distances)), abs=1e-12)
    # A pure offset delta moves every point by |delta|.
    delta = torch.tensor([0.03, -0.04, 0.0], dtype=F64)
    offset = T_gt.clone()
    offset[:, :3, 3] += delta
    mean_err, mse = point_error(offset, T_gt, points)
    torch.testing.assert_close(mean_err, torch.full((3,), 0.05, dtype=F64))
    torch.testing.assert_close(mse, torch.full((3,), 0.0025, dtype=F64))


def test_perfect_prediction_scores_zero_with_finite_gradients() -> None:
    T = se3.make_transform(se3.random_rotation(2, generator=torch.Generator().manual_seed(0), dtype=F64), torch.ones(2, 3, dtype=F64))
    T_pred = T.clone().requires_grad_(True)
    points = torch.randn(2, 4, 3, dtype=F64)
    mean_err, mse = point_error(T_pred, T, points)
    total = mean_err.sum() + mse.sum() + translation_error(T_pred, T, points[:, 0]).sum()
    total = total + rotation_error_deg(T_pred[:, :3, :3], T[:, :3, :3], Symmetry.cylinder()).sum()
    assert float(total.detach()) == pytest.approx(0.0, abs=1e-6)
    total.backward()
    assert bool(torch.isfinite(T_pred.grad).all())


# ------------------------------------------------------------ NaN policy
@pytest.mark.parametrize("symmetry", [None, Symmetry.cube(), Symmetry.cylinder(), Symmetry.axial()])
def test_nan_in_gives_nan_out(symmetry) -> None:
    T = se3.make_transform(se3.random_rotation(3, generator=torch.Generator().manual_seed(0)), torch.zeros(3, 3))
    T_nan = T.clone()
    T_nan[1, 0, 0] = float("nan")
    T_nan[1, 0, 3] = float("nan")
    rotation = rotation_error_deg(T_nan[:, :3, :3], T[:, :3, :3], symmetry)
    assert bool(rotation[1].isnan()) and not bool(rotation[[0, 2]].isnan().any())
    assert bool(translation_error(T_nan, T, torch.ones(3, 3))[1].isnan())
    assert bool(raw_translation_error(T_nan, T)[1].isnan())
    mean_err, mse = point_error(T_nan, T, torch.ones(3, 5, 3))
    assert bool(mean_err[1].isnan()) and bool(mse[1].isnan())
    assert not bool(mean_err[[0, 2]].isnan().any())


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: rotation_error_deg(torch.eye(4)[None], torch.eye(3)[None]), "R_pred must have shape"),
        (lambda: rotation_error_deg(torch.eye(3)[None], torch.eye(3)[None], symmetry="cube"), "Symmetry"),
        (lambda: rotation_error_deg(torch.eye(3)[None], torch.eye(3)[None], None, torch.eye(4)), "object_rotation"),
        (lambda: translation_error(torch.eye(4)[None], torch.eye(4)[None], torch.zeros(1, 4)), "centroid"),
        (lambda: point_error(torch.eye(4)[None], torch.eye(4)[None], torch.zeros(1, 0, 3)), "N >= 1"),
        (lambda: point_error(torch.eye(4)[None], torch.eye(4, dtype=F64)[None], torch.zeros(1, 2, 3)), "dtype"),
    ],
)
def test_bad_input_raises(call, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        call()
