"""SE(3) helpers: rigid transforms as 4x4 homogeneous matrices.

Convention (docs/design.md): a pose / cross-pose ``T`` is a 4x4 matrix acting on
column vectors, ``p' = R p + t`` with ``R = T[..., :3, :3]`` and
``t = T[..., :3, 3]``; the last row is ``[0, 0, 0, 1]``. Quaternions are
``(w, x, y, z)`` as in SAPIEN. Point clouds are row-stacked ``(..., N, 3)``.

All functions are pure tensor maths: batched over any leading dimensions
``...`` (broadcast where two inputs meet), float32 or float64, differentiable,
and raise ``ValueError`` on a bad shape or dtype.

Library choice: quaternion <-> matrix conversions and random rotations use
``roma`` (``unitquat_to_rotmat``, ``rotmat_to_unitquat``, ``random_rotmat``),
which are differentiable and batched; roma stores quaternions as (x, y, z, w),
so this module rolls the last axis at the boundary.
"""

from __future__ import annotations

import roma
import torch

from wpbench.geometry._checks import require_same_dtype, require_trailing

__all__ = [
    "make_transform",
    "invert",
    "compose",
    "apply",
    "rotation_part",
    "translation_part",
    "quat_wxyz_to_matrix",
    "matrix_to_quat_wxyz",
    "random_rotation",
]


def _require_transform(name: str, T: torch.Tensor) -> None:
    require_trailing(name, T, (4, 4), "(..., 4, 4)")


def rotation_part(T: torch.Tensor) -> torch.Tensor:
    """Rotation block of ``T`` (..., 4, 4) -> (..., 3, 3) (a view)."""
    _require_transform("T", T)
    return T[..., :3, :3]


def translation_part(T: torch.Tensor) -> torch.Tensor:
    """Translation column of ``T`` (..., 4, 4) -> (..., 3) (a view)."""
    _require_transform("T", T)
    return T[..., :3, 3]


def make_transform(R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Build ``T`` (..., 4, 4) from rotation ``R`` (..., 3, 3) and translation ``t`` (..., 3).

    Leading dimensions of ``R`` and ``t`` broadcast. ``R`` is not checked for
    orthonormality (that would cost a sync per call); pass a rotation.
    """
    require_trailing("R", R, (3, 3), "(..., 3, 3)")
    require_trailing("t", t, (3,), "(..., 3)")
    require_same_dtype(R=R, t=t)
    batch = torch.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    top = torch.cat([R.expand(*batch, 3, 3), t.expand(*batch, 3).unsqueeze(-1)], dim=-1)
    bottom = torch.zeros(*batch, 1, 4, dtype=R.dtype, device=R.device)
    bottom[..., 0, 3] = 1.0
    return torch.cat([top, bottom], dim=-2)


def invert(T: torch.Tensor) -> torch.Tensor:
    """Inverse of a rigid transform ``T`` (..., 4, 4) -> (..., 4, 4).

    Uses ``R^T`` and ``-R^T t`` (exact for rigid transforms, cheaper and more
    accurate than a general matrix inverse).
    """
    _require_transform("T", T)
    R_inv = T[..., :3, :3].transpose(-1, -2)
    t_inv = -(R_inv @ T[..., :3, 3:4]).squeeze(-1)
    return make_transform(R_inv, t_inv)


def compose(A: torch.Tensor, B: torch.Tensor) -> torch.Tensor:
    """``A @ B`` for transforms (..., 4, 4): apply ``B`` first, then ``A``."""
    _require_transform("A", A)
    _require_transform("B", B)
    require_same_dtype(A=A, B=B)
    return A @ B


def apply(T: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Transform row-stacked ``points`` (..., N, 3) by ``T`` (..., 4, 4) -> (..., N, 3).

    Computes ``R p + t`` for every point; leading dimensions broadcast, so one
    transform (4, 4) can move a batch of clouds (B, N, 3) and vice versa.
    """
    _require_transform("T", T)
    require_trailing("points", points, (3,), "(..., N, 3)")
    if points.dim() < 2:
        raise ValueError(f"points must have shape (..., N, 3), got {tuple(points.shape)}; use points[None] for one point")
    require_same_dtype(T=T, points=points)
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    return points @ R.transpose(-1, -2) + t.unsqueeze(-2)


def quat_wxyz_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) from quaternions ``q`` (..., 4) in (w, x, y, z) order.

    ``q`` is normalised first, so any non-zero scaling of a quaternion gives
    the same rotation; ``q`` and ``-q`` give the same rotation. A zero
    quaternion has no rotation and raises ValueError; NaN in gives NaN out.
    """
    require_trailing("q", q, (4,), "(..., 4)")
    norm = torch.linalg.vector_norm(q, dim=-1, keepdim=True)
    if bool((norm == 0).any()):
        raise ValueError("q contains a zero quaternion, which is no rotation; use (1, 0, 0, 0) for the identity")
    unit_xyzw = roma.quat_wxyz_to_xyzw(q / norm)
    return roma.unitquat_to_rotmat(unit_xyzw)


def matrix_to_quat_wxyz(R: torch.Tensor) -> torch.Tensor:
    """Unit quaternions (..., 4) in (w, x, y, z) order from rotation matrices ``R`` (..., 3, 3).

    The sign is canonicalised to ``w >= 0`` (the hemisphere SAPIEN and most
    tools print), so round trips are stable.
    """
    require_trailing("R", R, (3, 3), "(..., 3, 3)")
    wxyz = roma.quat_xyzw_to_wxyz(roma.rotmat_to_unitquat(R))
    # Multiply by +-1 instead of indexing so the op stays differentiable and sync-free.
    sign = torch.where(wxyz[..., :1] < 0, -1.0, 1.0).to(wxyz.dtype)
    return wxyz * sign


def random_rotation(
    n: int,
    generator: torch.Generator | None = None,
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """``n`` rotations (n, 3, 3) drawn uniformly (Haar measure) from SO(3).

    Uses ``roma.random_rotmat`` (uniform unit quaternions, Shoemake's method);
    pass a seeded ``torch.Generator`` for reproducible draws.
    """
    if not isinstance(n, int) or isinstance(n, bool) or n < 0:
        raise ValueError(f"n must be a non-negative int, got {n!r}")
    if dtype not in (torch.float32, torch.float64):
        raise ValueError(f"dtype must be torch.float32 or torch.float64, got {dtype}")
    device = generator.device if generator is not None else None
    return roma.random_rotmat(n, dtype=dtype, device=device, generator=generator)

