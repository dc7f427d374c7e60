"""SE(3) helpers: transforms, inverse, composition, quaternions (w, x, y, z), random rotations."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from wpbench.geometry import se3

DTYPES = [torch.float32, torch.float64]
TOL = {torch.float32: 1e-5, torch.float64: 1e-12}
SETTINGS = settings(max_examples=50, deadline=None)


def _random_transform(batch: int, generator: torch.Generator, dtype: torch.dtype) -> torch.Tensor:
    R = se3.random_rotation(batch, generator=generator, dtype=dtype)
    t = torch.randn(batch, 3, generator=generator, dtype=dtype)
    return se3.make_transform(R, t)


@SETTINGS
@given(seed=st.integers(0, 2**31 - 1), dtype=st.sampled_from(DTYPES))
def test_apply_is_R_p_plus_t(seed: int, dtype: torch.dtype) -> None:
    generator = torch.Generator().manual_seed(seed)
    T = _random_transform(4, generator, dtype)
    points = torch.randn(4, 7, 3, generator=generator, dtype=dtype)
    expected = torch.einsum("bij,bnj->bni", T[:, :3, :3], points) + T[:, None, :3, 3]
    torch.testing.assert_close(se3.apply(T, points), expected, atol=TOL[dtype], rtol=0)
    assert T.dtype == dtype
    torch.testing.assert_close(T[:, 3], torch.tensor([0, 0, 0, 1], dtype=dtype).expand(4, 4))


@SETTINGS
@given(seed=st.integers(0, 2**31 - 1), dtype=st.sampled_from(DTYPES))
def test_invert_and_compose(seed: int, dtype: torch.dtype) -> None:
    generator = torch.Generator().manual_seed(seed)
    A = _random_transform(3, generator, dtype)
    B = _random_transform(3, generator, dtype)
    points = torch.randn(3, 5, 3, generator=generator, dtype=dtype)
    eye = torch.eye(4, dtype=dtype).expand(3, 4, 4)
    torch.testing.assert_close(se3.compose(A, se3.invert(A)), eye, atol=TOL[dtype] * 10, rtol=0)
    torch.testing.assert_close(se3.compose(se3.invert(A), A), eye, atol=TOL[dtype] * 10, rtol=0)
    # compose(A, B) applies B first, then A.
    torch.testing.assert_close(
        se3.apply(se3.compose(A, B), points), se3.apply(A, se3.apply(B, points)), atol=TOL[dtype] * 10, rtol=0
    )
    torch.testing.assert_close(se3.apply(se3.invert(A), se3.apply(A, points)), points, atol=TOL[dtype] * 10, rtol=0)


def test_broadcasting_one_transform_over_a_batch_of_clouds() -> None:
    generator = torch.Generator().manual_seed(0)
    T = _random_transform(1, generator, torch.float64)[0]  # (4, 4)
    clouds = torch.randn(5, 6, 3, generator=generator, dtype=torch.float64)
    moved = se3.apply(T, clouds)
    assert moved.shape == (5, 6, 3)
    torch.testing.assert_close(moved[2], se3.apply(T, clouds[2]))
    # make_transform broadcasts one rotation against many translations.
    many = se3.make_transform(T[:3, :3], torch.zeros(5, 3, dtype=torch.float64))
    assert many.shape == (5, 4, 4)


def test_quaternion_order_is_wxyz() -> None:
    # A quarter turn about z written by hand: (w, x, y, z) = (cos 45deg, 0, 0, sin 45deg).
    half = math.pi / 4
    q = torch.tensor([math.cos(half), 0.0, 0.0, math.sin(half)], dtype=torch.float64)
    expected = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    torch.testing.assert_close(se3.quat_wxyz_to_matrix(q), expected, atol=1e-12, rtol=0)
    torch.testing.assert_close(se3.matrix_to_quat_wxyz(expected), q, atol=1e-12, rtol=0)
    identity = se3.quat_wxyz_to_matrix(torch.tensor([1.0, 0.0, 0.0, 0.0]))
    torch.testing.assert_close(identity, torch.eye(3))


@SETTINGS
@given(seed=st.integers(0, 2**31 - 1), dtype=st.sampled_from(DTYPES), scale=st.floats(0.1, 10.0))
def test_quaternion_round_trip(seed: int, dtype: torch.dtype, scale: float) -> None:
    generator = torch.Generator().manual_seed(seed)
    q = torch.randn(8, 4, generator=generator, dtype=dtype)
    unit = q / q.norm(dim=-1, keepdim=True)
    canonical = unit * torch.where(unit[:, :1] < 0, -1.0, 1.0).to(dtype)
    R = se3.quat_wxyz_to_matrix(q * scale)  # scaling a quaternion does not change its rotation
    torch.testing.assert_close(R @ R.transpose(-1, -2), torch.eye(3, dtype=dtype).expand(8, 3, 3), atol=TOL[dtype] * 10, rtol=0)
    back = se3.matrix_to_quat_wxyz(R)
    assert bool((back[:, 0] >= 0).all())
    torch.testing.assert_close(back, canonical, atol=TOL[dtype] * 30, rtol=0)
    torch.testing.assert_close(se3.quat_wxyz_to_matrix(-q), R, atol=TOL[dtype], rtol=0)


def test_random_rotation_is_a_reproducible_rotation() -> None:
    for dtype in DTYPES:
        R = se3.random_rotation(64, generator=torch.Generator().manual_seed(3), dtype=dtype)
        again = se3.random_rotation(64, generator=torch.Generator().manual_seed(3), dtype=dtype)
        assert R.shape == (64, 3, 3) and R.dtype == dtype
        torch.testing.assert_close(R, again, atol=0, rtol=0)
        torch.testing.assert_close(R @ R.transpose(-1, -2), torch.eye(3, dtype=dtype).expand(64, 3, 3), atol=TOL[dtype] * 10, rtol=0)
        torch.testing.assert_close(torch.linalg.det(R), torch.ones(64, dtype=dtype), atol=TOL[dtype] * 10, rtol=0)
    # Uniform on SO(3): the mean of many rotations is close to the zero matrix.
    many = se3.random_rotation(20000, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    assert float(many.mean(0).abs().max()) < 0.03


def test_gradients_flow_through_the_helpers() -> None:
    generator = torch.Generator().manual_seed(0)
    R = se3.random_rotation(2, generator=generator, dtype=torch.float64).requires_grad_(True)
    t = torch.randn(2, 3, generator=generator, dtype=torch.float64, requires_grad=True)
    points = torch.randn(2, 4, 3, generator=generator, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda R_, t_, p_: se3.apply(se3.invert(se3.make_transform(R_, t_)), p_), (R, t, points))
    q = torch.randn(3, 4, generator=generator, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(se3.quat_wxyz_to_matrix, (q,))


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: se3.make_transform(torch.eye(3), torch.zeros(4)), "t must have shape"),
        (lambda: se3.make_transform(torch.eye(4), torch.zeros(3)), "R must have shape"),
        (lambda: se3.make_transform(torch.eye(3), torch.zeros(3, dtype=torch.float64)), "share one dtype"),
        (lambda: se3.apply(torch.eye(3), torch.zeros(5, 3)), "T must have shape"),
        (lambda: se3.apply(torch.eye(4), torch.zeros(5, 2)), "points must have shape"),
        (lambda: se3.apply(torch.eye(4), torch.zeros(3)), "points must have shape"),
        (lambda: se3.invert(torch.eye(4, dtype=torch.int64)), "float32 or float64"),
        (lambda: se3.compose(torch.eye(4), torch.eye(3)), "B must have shape"),
        (lambda: se3.quat_wxyz_to_matrix(torch.zeros(2, 3)), "q must have shape"),
        (lambda: se3.quat_wxyz_to_matrix(torch.zeros(2, 4)), "zero quaternion"),
        (lambda: se3.matrix_to_quat_wxyz(torch.zeros(2, 4)), "R must have shape"),
        (lambda: se3.random_rotation(-1), "non-negative int"),
        (lambda: se3.random_rotation(2, dtype=torch.int32), "dtype"),
        (lambda: se3.apply([[1.0]], torch.zeros(1, 3)), "torch.Tensor"),
    ],
)
def test_bad_input_raises_value_error(call, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        call()


def test_nan_propagates() -> None:
    T = torch.eye(4).expand(2, 4, 4).clone()
    T[0, 0, 3] = float("nan")
    moved = se3.apply(T, torch.zeros(2, 3, 3))
    assert bool(moved[0].isnan().any()) and not bool(moved[1].isnan().any())
    q = torch.tensor([[float("nan"), 0.0, 0.0, 1.0]])
    assert bool(se3.quat_wxyz_to_matrix(q).isnan().all())
