"""The goal a hand can put a free object at, from the predicted cross-pose and the
observed clouds alone (never the simulator's truth). Pure numpy functions.

- Upright equivalent (:func:`upright_equivalent`). A predicted cross-pose may turn a
  cube onto another face: for the space the object takes up at its goal that is the
  same as turning it about the vertical only, but a hand that holds the object by a
  suction cup cannot tumble it. The object's box is read from its observed cloud:
  vertical sides along the smallest-area horizontal rectangle around the points
  (wpbench.sim.side_entry.face_yaws), bottom and top at the lowest and highest points.
  A quarter or half turn S of the box about its own axes that maps its extents onto
  themselves (within EXTENT_TOLERANCE) leaves the box where it was, so ``T @ S`` puts
  the observed box where ``T`` does. ``T`` is kept unless such a turn leaves the object
  less tilted; then the least tilted is chosen, and among equally tilted ones the
  smallest rotation. An object whose box is not symmetric that way (a long block)
  keeps ``T``.
- Resting on the observed support (:func:`rest_on_support`). Putting an object down is
  a guarded move: the hand stops when the object meets the surface under it. A goal
  whose bottom lies up to MAX_SUPPORT_RAISE below the observed surface under its
  footprint is raised onto that surface; a goal deeper in it is left as predicted
  (and the furniture then stops the path).
"""

from __future__ import annotations

import numpy as np

from wpbench.geometry.symmetry import Symmetry
from wpbench.sim.side_entry import face_yaws

EXTENT_TOLERANCE = 0.01      # m, or EXTENT_SHARE of the largest extent if more
EXTENT_SHARE = 0.05
TILT_TIE = 1e-6              # cosines of tilts closer than this count as equal
MAX_SUPPORT_RAISE = 0.03     # m, the deepest a goal may sink into the observed surface under it and be raised onto it
SUPPORT_INSET = 0.01         # m, the footprint is shrunk this much (wall points beside the goal are not the surface under it)
SUPPORT_GAP = 0.002          # m, a raised goal stands this far above the observed surface


# The 24 rotations that map the coordinate axes onto themselves, the identity first.
BOX_ROTATIONS = Symmetry.cube().discrete.numpy()


def observed_box(object_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(frame (4, 4), extents (3,)): the observed object's upright bounding box, its frame
    at the box's centre with z vertical."""
    p = np.asarray(object_points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"object_points must be a non-empty (N, 3) cloud, got shape {p.shape}")
    yaw = float(face_yaws(p)[0])
    R = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    local = p @ R
    lo, hi = local.min(0), local.max(0)
    B = np.eye(4)
    B[:3, :3] = R
    B[:3, 3] = R @ ((lo + hi) / 2)
    return B, hi - lo


def box_symmetries(object_points: np.ndarray) -> list[np.ndarray]:
    """(4, 4) world-frame turns of the observed object's box about its centre that leave
    the box in place (the identity first)."""
    B, extents = observed_box(object_points)
    tol = max(EXTENT_TOLERANCE, EXTENT_SHARE * float(extents.max()))
    B_inv = np.linalg.inv(B)
    out = []
    for P in BOX_ROTATIONS:
        if np.all(np.abs(np.abs(P) @ extents - extents) <= tol):
            S = np.eye(4)
            S[:3, :3] = P
            out.append(B @ S @ B_inv)
    return out


def upright_equivalent(object_points: np.ndarray, cross_pose: np.ndarray) -> np.ndarray:
    """``cross_pose`` itself unless a turn S of the observed box (box_symmetries) leaves the
    object less tilted at its goal; then ``cross_pose @ S`` for the least tilted (the
    smallest rotation among equally tilted ones)."""
    T = np.asarray(cross_pose, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"cross_pose must be (4, 4), got shape {T.shape}")
    turned = [T @ S for S in box_symmetries(object_points)[1:]]
    upright = [C for C in turned if C[2, 2] > T[2, 2] + TILT_TIE]
    if not upright:
        return T
    top = max(C[2, 2] for C in upright)
    return min((C for C in upright if C[2, 2] >= top - TILT_TIE), key=_choice_key)


def _choice_key(T: np.ndarray) -> tuple:
    """The rotation angle of ``T``, then its rotation entries, both rounded so that equal ones tie."""
    angle = float(np.arccos(np.clip((np.trace(T[:3, :3]) - 1) / 2, -1.0, 1.0)))
    return (round(angle, 9), *np.round(T[:3, :3].ravel(), 9))


def rest_on_support(object_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray) -> np.ndarray:
    """``cross_pose`` raised so that the object's observed cloud at its goal stands SUPPORT_GAP
    above the highest observed anchor point (M, 3) under its footprint (its upright box at the
    goal, shrunk by SUPPORT_INSET) that lies at most MAX_SUPPORT_RAISE above the goal's
    bottom; ``cross_pose`` itself when no such point is above the bottom."""
    T = np.asarray(cross_pose, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"cross_pose must be (4, 4), got shape {T.shape}")
    anchor = np.asarray(anchor_points, dtype=np.float64)
    if anchor.ndim != 2 or anchor.shape[1] != 3 or len(anchor) == 0:
        raise ValueError(f"anchor_points must be a non-empty (M, 3) cloud, got shape {anchor.shape}")
    goal = np.asarray(object_points, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]
    B, extents = observed_box(goal)
    local = (anchor - B[:3, 3]) @ B[:3, :3]
    bottom = float(goal[:, 2].min())
    under = np.all(np.abs(local[:, :2]) < extents[:2] / 2 - SUPPORT_INSET, axis=1)
    under &= anchor[:, 2] <= bottom + MAX_SUPPORT_RAISE
    if not under.any() or anchor[under, 2].max() + SUPPORT_GAP <= bottom:
        return T
    raised = T.copy()
    raised[2, 3] += float(anchor[under, 2].max()) + SUPPORT_GAP - bottom
    return raised
