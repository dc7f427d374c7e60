"""Weighted Procrustes (Kabsch) and the WeightedPose weighted SVD.

Convention: transforms are 4x4 homogeneous matrices on column vectors,
``p' = R p + t`` (see ``se3``); point clouds are row-stacked ``(B, N, 3)``.

``weighted_procrustes`` solves

    min_{R in SO(3), t}  sum_i w_i |R s_i + t - y_i|^2

with weighted centroids, the weighted cross-covariance
``M = sum_i w_i (y_i - y_bar)(s_i - s_bar)^T = U S V^T``, the reflection fix
``R = U diag(1, 1, det(U V^T)) V^T`` (so ``det(R) = +1`` even when the best
orthogonal fit is a reflection) and ``t = y_bar - R s_bar``.

``dual_flow_svd`` (TAX-Pose, ``w = 0``) and ``weighted_pose_svd`` (WeightedPose)
build one stacked Procrustes problem (derived in docs/design.md):

    J(R, t) = (1 - w) [ sum_i a_i |R p_i + t - v_i|^2 + sum_j b_j |R u_j + t - q_j|^2 ]
            +  w      sum_i c_i |R p_i + t - (p_i + d_i)|^2

with ``a`` and ``b`` each normalised to sum 1/2, ``c_i = 1 / N_A``, on
``source = [p; u; p]`` and ``target = [v; q; p + d]``.

Degenerate input (decided here, tested in tests/test_geometry_procrustes.py):

- negative weights, or a sample whose weights are all zero (nothing to fit):
  ``ValueError`` naming the samples and the fix;
- any NaN/inf in a sample's points or weights (even on a zero-weight point,
  since 0 * NaN is NaN): that sample's whole 4x4 output is NaN, the other
  samples are unaffected. Never a silent identity;
- collinear or coincident points (rotation not unique): a valid rotation
  (``det = +1``, finite) chosen by the SVD; the translation still maps the
  weighted source centroid onto the target centroid.

Gradients: ``torch.linalg.svd``'s backward divides by ``s_i^2 - s_j^2`` and
returns inf/NaN whenever two singular values coincide (e.g. a symmetric point
set), although the rotation itself is perfectly smooth there. This module
differentiates the rotation directly instead (a custom autograd Function):
with the signed singular values ``s' = (s1, s2, det * s3)`` the derivative of
``R`` only involves ``1 / (s'_i + s'_j)``, which vanishes only where the
rotation is genuinely not unique (collinear points, or a reflection fit with
``s2 = s3``). There ``1/x`` is damped to ``x / (x^2 + eps^2)`` with
``eps = gradient_eps * s1`` (relative, so the damping does not depend on the
object's size), which bounds the gradient instead of producing inf. The SVD and
its backward run in float64 (3x3 matrices, negligible cost) and are cast back.
"""

from __future__ import annotations

import torch
from torch.autograd.function import once_differentiable

from wpbench.geometry._checks import require_same_dtype, require_shape
from wpbench.geometry.se3 import make_transform

__all__ = ["weighted_procrustes", "dual_flow_svd", "weighted_pose_svd", "DEFAULT_GRADIENT_EPS"]

DEFAULT_GRADIENT_EPS = 1e-4
"""Relative damping of the rotation gradient near non-unique solutions (see module docstring)."""

# Keeps the damped inverse finite even when every singular value is zero (all points coincide).
_ABSOLUTE_EPS = 1e-100


def _det3(A: torch.Tensor) -> torch.Tensor:
    """Determinant of (B, 3, 3) matrices as a triple product (batched LU is ~100x slower for 3x3)."""
    return (A[:, 0] * torch.linalg.cross(A[:, 1], A[:, 2])).sum(-1)


class _RotationFromCovariance(torch.autograd.Function):
    """``R = argmax_{R in SO(3)} tr(R^T M)`` for ``M`` (B, 3, 3) float64, with a damped backward.

    Derivation of the backward: with ``M = R P`` (``P = V diag(s') V^T``
    symmetric) and ``dR = R Omega`` (``Omega`` skew), the skew part of
    ``R^T dM`` gives ``Omega~_ij (s'_i + s'_j) = X_ij`` in the ``V`` basis,
    ``X = V^T (R^T dM - dM^T R) V``. Pulling a gradient ``G = dL/dR`` back
    gives ``dL/dM = R V K V^T`` with ``A = V^T R^T G V`` and
    ``K_ij = (A_ij - A_ji) / (s'_i + s'_j)``.
    """

    @staticmethod
    def forward(ctx, M: torch.Tensor, relative_eps: float) -> torch.Tensor:  # type: ignore[override]
        U, S, Vh = torch.linalg.svd(M)
        reflection = _det3(U) * _det3(Vh) < 0
        last = torch.where(reflection, -1.0, 1.0).to(M.dtype).unsqueeze(-1)
        flip = torch.cat([torch.ones_like(S[:, :2]), last], dim=-1)  # (B, 3) = diag(1, 1, det)
        R = (U * flip.unsqueeze(-2)) @ Vh
        ctx.save_for_backward(R, Vh, S * flip)
        ctx.relative_eps = relative_eps
        return R

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_R: torch.Tensor) -> tuple[torch.Tensor, None]:  # type: ignore[override]
        R, Vh, signed = ctx.saved_tensors
        V = Vh.transpose(-1, -2)
        A = Vh @ R.transpose(-1, -2) @ grad_R @ V
        pair_sums = signed.unsqueeze(-1) + signed.unsqueeze(-2)
        eps = ctx.relative_eps * signed[:, :1].abs().unsqueeze(-1) + _ABSOLUTE_EPS
        damped_inverse = pair_sums / (pair_sums.square() + eps.square())
        K = (A - A.transpose(-1, -2)) * damped_inverse
        return R @ V @ K @ Vh, None


def _check_weights_usable(weights: torch.Tensor, name: str) -> torch.Tensor:
    """Raise on negative weights or on samples whose weights sum to zero; return the sums (B,)."""
    # amin is one reduction (cheaper than a (B, N) comparison + any); NaN < 0 is False, NaN then flows to the output.
    if bool(weights.amin() < 0):
        raise ValueError(f"{name} has negative entries; weights must be >= 0 (e.g. softmax or sigmoid outputs)")
    totals = weights.sum(dim=-1)
    empty = (totals <= 0).nonzero().flatten().tolist()
    if empty:
        raise ValueError(
            f"{name} sum to zero in samples {empty[:10]}{' ...' if len(empty) > 10 else ''}: "
            "nothing to fit. Give every sample at least one positive weight "
            "(e.g. weights.clamp_min(1e-8), or softmax outputs)"
        )
    return totals


def weighted_procrustes(
    source: torch.Tensor,
    target: torch.Tensor,
    weights: torch.Tensor,
    *,
    gradient_eps: float = DEFAULT_GRADIENT_EPS,
) -> torch.Tensor:
    """Rigid transform ``T`` (B, 4, 4) minimising ``sum_i w_i |R s_i + t - y_i|^2``.

    Args:
        source: ``s`` (B, N, 3).
        target: ``y`` (B, N, 3), paired row by row with ``source``.
        weights: ``w`` (B, N), non-negative, at least one positive per sample;
            only their ratios matter (they are normalised to sum 1).
        gradient_eps: relative damping of the rotation gradient near
            non-unique solutions (module docstring); forward is unaffected.

    Returns:
        ``T`` (B, 4, 4), same dtype as the inputs, ``det(R) = +1``; a sample
        with any NaN/inf input is all NaN.

    Raises:
        ValueError: bad shapes/dtypes, negative weights, or an all-zero sample.
    """
    require_shape("source", source, (None, None, 3), "(B, N, 3)")
    require_shape("target", target, tuple(source.shape), f"(B, N, 3) = {tuple(source.shape)} like source")
    require_shape("weights", weights, tuple(source.shape[:2]), f"(B, N) = {tuple(source.shape[:2])}")
    dtype = require_same_dtype(source=source, target=target, weights=weights)
    if source.shape[1] == 0:
        raise ValueError("source has no points (N = 0); pass at least one point per sample")
    if not gradient_eps >= 0:
        raise ValueError(f"gradient_eps must be >= 0, got {gradient_eps}")

    totals = _check_weights_usable(weights, "weights").reshape(-1, 1, 1)  # (B, 1, 1)
    # Normalising the small results instead of the (B, N) weights saves a full pass over the data.
    row_weights = weights.unsqueeze(-2)  # (B, 1, N)
    source_centroid = (row_weights @ source) / totals  # (B, 1, 3)
    target_centroid = (row_weights @ target) / totals  # (B, 1, 3)
    # Centre both clouds before forming the covariance: the shortcut
    # sum w y s^T - y_bar s_bar^T loses ~3 digits in float32 for clouds far from the origin.
    weighted_target = (target - target_centroid) * weights.unsqueeze(-1)
    covariance = (weighted_target.transpose(-1, -2) @ (source - source_centroid)) / totals  # (B, 3, 3) = M

    finite = torch.isfinite(covariance).flatten(1).all(dim=1)  # (B,)
    finite = finite & torch.isfinite(source_centroid).flatten(1).all(1) & torch.isfinite(target_centroid).flatten(1).all(1)
    # LAPACK may raise on NaN input, so non-finite samples get a harmless stand-in and are NaN-ed afterwards.
    eye = torch.eye(3, dtype=dtype, device=source.device).expand_as(covariance)
    safe_covariance = torch.where(finite[:, None, None], covariance, eye)

    R = _RotationFromCovariance.apply(safe_covariance.double(), float(gradient_eps)).to(dtype)
    t = target_centroid.squeeze(-2) - (R @ source_centroid.transpose(-1, -2)).squeeze(-1)
    T = make_transform(R, t)
    return torch.where(finite[:, None, None], T, torch.full_like(T, float("nan")))


def _half_normalised(weights: torch.Tensor, needed: torch.Tensor, name: str) -> torch.Tensor:
    """``weights`` (B, M) rescaled to sum 1/2 per sample.

    ``needed`` (B,) marks samples whose block carries weight in J; only those
    must have a positive sum (a block multiplied by zero may be all zero).
    """
    if bool(weights.amin() < 0):
        raise ValueError(f"{name} has negative entries; weights must be >= 0 (e.g. softmax outputs)")
    totals = weights.sum(dim=-1)
    empty = (needed & (totals <= 0)).nonzero().flatten().tolist()
    if empty:
        raise ValueError(
            f"{name} sum to zero in samples {empty[:10]} although their block has weight (1 - w) > 0; "
            "give it a positive sum (softmax outputs, or weights.clamp_min(1e-8))"
        )
    safe_totals = torch.where(totals > 0, totals, torch.ones_like(totals))
    return 0.5 * weights / safe_totals.unsqueeze(-1)


def _check_pose_inputs(
    action: torch.Tensor,
    action_targets: torch.Tensor,
    action_weights: torch.Tensor,
    anchor_sources: torch.Tensor,
    anchor: torch.Tensor,
    anchor_weights: torch.Tensor,
) -> tuple[int, int, int]:
    """Validate the TAX-Pose blocks; return (B, N_A, N_B)."""
    require_shape("action", action, (None, None, 3), "(B, NA, 3)")
    B, NA = action.shape[:2]
    require_shape("action_targets", action_targets, (B, NA, 3), f"(B, NA, 3) = {(B, NA, 3)}")
    require_shape("action_weights", action_weights, (B, NA), f"(B, NA) = {(B, NA)}")
    require_shape("anchor", anchor, (B, None, 3), f"(B, NB, 3) with B = {B}")
    NB = anchor.shape[1]
    require_shape("anchor_sources", anchor_sources, (B, NB, 3), f"(B, NB, 3) = {(B, NB, 3)}")
    require_shape("anchor_weights", anchor_weights, (B, NB), f"(B, NB) = {(B, NB)}")
    require_same_dtype(
        action=action,
        action_targets=action_targets,
        action_weights=action_weights,
        anchor_sources=anchor_sources,
        anchor=anchor,
        anchor_weights=anchor_weights,
    )
    if NA == 0 or NB == 0:
        raise ValueError(f"need at least one action and one anchor point, got NA={NA}, NB={NB}")
    return B, NA, NB


def dual_flow_svd(
    action: torch.Tensor,
    action_targets: torch.Tensor,
    action_weights: torch.Tensor,
    anchor_sources: torch.Tensor,
    anchor: torch.Tensor,
    anchor_weights: torch.Tensor,
    *,
    gradient_eps: float = DEFAULT_GRADIENT_EPS,
) -> torch.Tensor:
    """TAX-Pose's dual-flow SVD: ``weighted_pose_svd`` with ``w = 0``.

    Minimises ``sum_i a_i |R p_i + t - v_i|^2 + sum_j b_j |R u_j + t - q_j|^2``
    with ``a`` and ``b`` each normalised to sum 1/2 (so both directions count
    equally whatever N_A and N_B are).

    Args:
        action: ``p`` (B, NA, 3) action points.
        action_targets: ``v`` (B, NA, 3) where each action point should go.
        action_weights: ``a`` (B, NA) >= 0, positive sum per sample.
        anchor_sources: ``u`` (B, NB, 3) action-frame points that should land on the anchor points.
        anchor: ``q`` (B, NB, 3) anchor points.
        anchor_weights: ``b`` (B, NB) >= 0, positive sum per sample.

    Returns:
        ``T`` (B, 4, 4) with ``p_goal = T p``.
    """
    B, _, _ = _check_pose_inputs(action, action_targets, action_weights, anchor_sources, anchor, anchor_weights)
    every_sample = torch.ones(B, dtype=torch.bool, device=action.device)
    a_half = _half_normalised(action_weights, every_sample, "action_weights")
    b_half = _half_normalised(anchor_weights, every_sample, "anchor_weights")
    return weighted_procrustes(
        torch.cat([action, anchor_sources], dim=1),
        torch.cat([action_targets, anchor], dim=1),
        torch.cat([a_half, b_half], dim=1),
        gradient_eps=gradient_eps,
    )


def weighted_pose_svd(
    action: torch.Tensor,
    action_targets: torch.Tensor,
    action_weights: torch.Tensor,
    anchor_sources: torch.Tensor,
    anchor: torch.Tensor,
    anchor_weights: torch.Tensor,
    flow: torch.Tensor,
    w: torch.Tensor,
    *,
    gradient_eps: float = DEFAULT_GRADIENT_EPS,
) -> torch.Tensor:
    """WeightedPose: one weighted Procrustes mixing TAX-Pose and Goal Flow by ``w``.

    Minimises ``J(R, t)`` (module docstring) on the stacked pairs
    ``source = [p; u; p]``, ``target = [v; q; p + d]`` with per-pair weights

    - per-sample ``w`` (B,) (the paper): ``(1 - w) a_hat_i``, ``(1 - w) b_hat_j``,
      ``w / N_A``, where ``a_hat``, ``b_hat`` sum to 1/2;
    - per-point ``w`` (B, NA) (variant): action pair i gets ``(1 - w_i) a_hat_i``,
      flow pair i gets ``w_i / N_A``, and the anchor block, which has no action
      point of its own, gets ``(1 - mean_i w_i) b_hat_j``. With all ``w_i``
      equal this is exactly the per-sample case. These weights need not sum
      to 1 (``weighted_procrustes`` only uses their ratios).

    ``w = 0`` is ``dual_flow_svd``; ``w = 1`` is Kabsch on ``(p, p + d)`` with
    uniform weights (then ``a`` and ``b`` may be all zero).

    Args:
        action, action_targets, action_weights, anchor_sources, anchor, anchor_weights:
            as in ``dual_flow_svd``: (B, NA, 3), (B, NA, 3), (B, NA), (B, NB, 3), (B, NB, 3), (B, NB).
        flow: ``d`` (B, NA, 3) Goal Flow per action point.
        w: (B,) or (B, NA) mixing weight in [0, 1].

    Returns:
        ``T`` (B, 4, 4) with ``p_goal = T p``; NaN for a sample with NaN input.
    """
    B, NA, _ = _check_pose_inputs(action, action_targets, action_weights, anchor_sources, anchor, anchor_weights)
    require_shape("flow", flow, (B, NA, 3), f"(B, NA, 3) = {(B, NA, 3)}")
    if not isinstance(w, torch.Tensor) or w.shape not in ((B,), (B, NA)):
        shape = tuple(w.shape) if isinstance(w, torch.Tensor) else type(w).__name__
        raise ValueError(f"w must be a tensor of shape (B,) = {(B,)} or (B, NA) = {(B, NA)}, got {shape}")
    require_same_dtype(action=action, flow=flow, w=w)
    if bool(((w < 0) | (w > 1)).any()):
        raise ValueError("w must lie in [0, 1] (a mixing proportion); squash it with torch.sigmoid")

    per_point_w = w.unsqueeze(-1).expand(B, NA) if w.dim() == 1 else w  # (B, NA)
    anchor_w = w if w.dim() == 1 else w.mean(dim=-1)  # (B,)
    a_half = _half_normalised(action_weights, (1 - per_point_w).amax(dim=-1) > 0, "action_weights")
    b_half = _half_normalised(anchor_weights, (1 - anchor_w) > 0, "anchor_weights")
    weights = torch.cat(
        [(1 - per_point_w) * a_half, (1 - anchor_w).unsqueeze(-1) * b_half, per_point_w / NA],
        dim=1,
    )
    return weighted_procrustes(
        torch.cat([action, anchor_sources, action], dim=1),
        torch.cat([action_targets, anchor, action + flow], dim=1),
        weights,
        gradient_eps=gradient_eps,
    )
