"""The path a cross-pose implies: screw interpolation from the identity to T.

Every rigid motion T = (R, t) is a screw: a rotation by ``angle`` about a line (unit
``axis`` through ``point``) combined with a slide of ``slide`` metres along that line
(Chasles). Its interpolation ``T(s) = exp(s log T)``, s in [0, 1], moves a point on an
arc about the line (a door's hinge) or, when the rotation vanishes, on a straight line
(a drawer's slide). Pure numpy functions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

MIN_ANGLE = 1e-6   # rad: a rotation smaller than this is treated as a pure translation


@dataclass(frozen=True)
class Screw:
    """A rigid motion as a screw. ``angle`` in [0, pi], ``axis`` (3,) unit, ``point`` (3,)
    on the axis (the point of the axis nearest the origin), ``slide`` metres along ``axis``.
    For a pure translation ``angle`` is 0, ``axis`` the direction of motion and ``slide`` its length."""

    angle: float
    axis: np.ndarray
    point: np.ndarray
    slide: float


def _check(T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"expected a (4, 4) rigid transform, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError("transform contains NaN or inf")
    return T


def screw_of(T: np.ndarray) -> Screw:
    """(4, 4) rigid transform -> its :class:`Screw`."""
    T = _check(T)
    rotvec = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    angle = float(np.linalg.norm(rotvec))
    t = T[:3, 3]
    if angle < MIN_ANGLE:
        length = float(np.linalg.norm(t))
        axis = t / length if length > 0 else np.array([0.0, 0.0, 1.0])
        return Screw(0.0, axis, np.zeros(3), length)
    axis = rotvec / angle
    slide = float(axis @ t)
    # (I - R) q = t - slide * axis has a line of solutions along the axis; lstsq gives
    # the one orthogonal to it (the point of the axis nearest the origin).
    point = np.linalg.lstsq(np.eye(3) - T[:3, :3], t - slide * axis, rcond=None)[0]
    point = point - (point @ axis) * axis
    return Screw(angle, axis, point, slide)


def screw_at(screw: Screw, s: np.ndarray | float) -> np.ndarray:
    """The motion a fraction ``s`` (scalar or (K,)) of the way along ``screw``: (4, 4) or (K, 4, 4)."""
    s_arr = np.atleast_1d(np.asarray(s, dtype=np.float64))
    out = np.tile(np.eye(4), (len(s_arr), 1, 1))
    R = Rotation.from_rotvec(np.outer(s_arr * screw.angle, screw.axis)).as_matrix()
    out[:, :3, :3] = R
    out[:, :3, 3] = screw.point - np.einsum("kij,j->ki", R, screw.point) + np.outer(s_arr * screw.slide, screw.axis)
    return out[0] if np.ndim(s) == 0 else out


def interpolate(T: np.ndarray, s: np.ndarray | float) -> np.ndarray:
    """``exp(s log T)``: (4, 4) T and fraction(s) ``s`` -> (4, 4) or (K, 4, 4); s = 0 is the
    identity and s = 1 is T."""
    return screw_at(screw_of(T), s)


def path_length(T: np.ndarray, point: np.ndarray) -> float:
    """Length (m) of the path a point (3,) travels along T's screw (arc plus slide)."""
    screw = screw_of(T)
    p = np.asarray(point, dtype=np.float64)
    radial = (p - screw.point) - ((p - screw.point) @ screw.axis) * screw.axis
    return float(np.hypot(screw.angle * np.linalg.norm(radial), screw.slide))


def velocity_at_start(T: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(3,) direction and speed (per unit s) in which a point (3,) starts to move along T's screw."""
    screw = screw_of(T)
    p = np.asarray(point, dtype=np.float64)
    return screw.angle * np.cross(screw.axis, p - screw.point) + screw.slide * screw.axis
