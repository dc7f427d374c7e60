"""Where and how the hand grasps, chosen from an observed cloud and the predicted
cross-pose alone (never from the simulator's ground truth). Pure numpy functions.

Frames follow wpbench.sim.gripper: a grasp is a (4, 4) TCP pose whose z axis is the
approach direction and whose y axis is the direction the fingers close along.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wpbench.sim.screw_path import screw_of

MOVING_QUANTILE = 0.6      # candidates: action points whose predicted motion is in the top 40%
HANDLE_BAND = 0.015        # m: points this close to the most protruding one form the handle
HANDLE_RADIUS = 0.04       # m: ... and lie within this distance of it
PAD_DEPTH = 0.012          # m: the pads' centre sits this far behind the outermost surface
TOP_GRASP_DEPTH = 0.02     # m: a top grasp holds an object this far below its top
MAX_GRASP_WIDTH = 0.075    # m: the widest thing the fingers close around (8 cm stroke, minus margin)
MIN_MOTION = 0.005         # m: a predicted motion smaller than this moves nothing


@dataclass(frozen=True)
class Grasp:
    """A TCP pose (4, 4) and the approach direction (3,) it is reached along (TCP z)."""

    tcp: np.ndarray
    approach: np.ndarray
    width: float        # m, observed width of what the fingers close on


def _frame(z: np.ndarray, y_hint: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """(4, 4) frame with z axis ``z``, y axis as close to ``y_hint`` as orthogonality allows."""
    z = z / np.linalg.norm(z)
    y = y_hint - (y_hint @ z) * z
    if np.linalg.norm(y) < 1e-6:
        y = np.cross(z, [1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.cross(z, [0.0, 1.0, 0.0])
    y = y / np.linalg.norm(y)
    x = np.cross(y, z)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, origin
    return T


def _check_cloud(points: np.ndarray, name: str) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"{name} must be a non-empty (N, 3) cloud, got shape {p.shape}")
    return p


def predicted_motion(cross_pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) how far each point (N, 3) moves under the cross-pose (4, 4)."""
    p = _check_cloud(points, "points")
    return np.linalg.norm(p @ cross_pose[:3, :3].T + cross_pose[:3, 3] - p, axis=1)


def articulated_grasp(action_points: np.ndarray, cross_pose: np.ndarray) -> Grasp | None:
    """Grasp on the moving part where the predicted motion is largest.

    The approach is against the direction those points start to move in (the outward
    normal of a door's free edge, the pull of a drawer); the grasp point is the point
    that sticks out furthest that way (a handle, when there is one). The fingers close
    across the handle's long axis. None when the prediction moves nothing.
    """
    a = _check_cloud(action_points, "action_points")
    motion = predicted_motion(cross_pose, a)
    if motion.max() < MIN_MOTION:
        return None
    movers = a[motion >= np.quantile(motion, MOVING_QUANTILE)]
    screw = screw_of(cross_pose)
    start_velocity = screw.angle * np.cross(screw.axis, movers - screw.point) + screw.slide * screw.axis
    outward = start_velocity.mean(0)
    if np.linalg.norm(outward) < 1e-9:
        return None
    outward /= np.linalg.norm(outward)
    height = (movers - movers.mean(0)) @ outward
    top = movers[int(np.argmax(height))]
    near = movers[(height >= height.max() - HANDLE_BAND) & (np.linalg.norm(movers - top, axis=1) < HANDLE_RADIUS)]
    centre = near.mean(0)
    flat = (near - centre) - np.outer((near - centre) @ outward, outward)
    if len(near) >= 3 and np.linalg.norm(flat) > 1e-6:
        long_axis = np.linalg.svd(flat, full_matrices=False)[2][0]
    else:
        long_axis = screw.axis if screw.angle > 0 else np.cross(outward, [0.0, 0.0, 1.0])
    close_dir = np.cross(outward, long_axis)
    width = float(np.ptp(flat @ close_dir)) if len(near) > 1 else 0.0
    surface = centre + (top - centre) @ outward * outward
    tcp = _frame(-outward, close_dir, surface - PAD_DEPTH * outward)
    return Grasp(tcp, -outward, width)


FACE_BIN = 0.005           # m: height bins in which a door's outer face is found


def suction_point(action_points: np.ndarray, cross_pose: np.ndarray) -> Grasp | None:
    """A suction grasp on the moving part's outer face, where the predicted motion is large.

    The approach is as in :func:`articulated_grasp`; the face is the most populated
    height band (along the outward direction) in the upper half of the moving points,
    so a handle standing off the face is not chosen. None when the prediction moves nothing.
    """
    a = _check_cloud(action_points, "action_points")
    motion = predicted_motion(cross_pose, a)
    if motion.max() < MIN_MOTION:
        return None
    keep = motion >= np.quantile(motion, MOVING_QUANTILE)
    movers, moving = a[keep], motion[keep]
    screw = screw_of(cross_pose)
    outward = (screw.angle * np.cross(screw.axis, movers - screw.point) + screw.slide * screw.axis).mean(0)
    if np.linalg.norm(outward) < 1e-9:
        return None
    outward /= np.linalg.norm(outward)
    height = (movers - movers.mean(0)) @ outward
    upper = height >= np.median(height)
    bins = np.floor(height[upper] / FACE_BIN).astype(int)
    face_bin = np.bincount(bins - bins.min()).argmax() + bins.min()
    face = np.flatnonzero(upper)[bins == face_bin]
    # Not the very edge (the cup needs the face all round it): the face point nearest
    # the 75th percentile of the face's motion.
    target = np.quantile(moving[face], 0.75)
    k = face[int(np.argmin(np.abs(moving[face] - target)))]
    surface = movers[k] - (height[k] - height[face].max()) * outward
    tcp = _frame(-outward, np.cross(outward, screw.axis if screw.angle > 0 else [0.0, 0.0, 1.0]), surface)
    return Grasp(tcp, -outward, 0.0)


CUP_FOOTPRINT = 0.05       # m: no observed door point within this of a cup grasp (across the approach) ...
CUP_PROUD = 0.01           # m: ... stands further out than the face (a handle the closed fingers would strike)
MIN_CLEAR_POINTS = 20      # door points at least, clear of protrusions, for a cup grasp to be chosen among them


def proud_near(door_points: np.ndarray, grasp: Grasp, candidates: np.ndarray) -> np.ndarray:
    """(M,) bool: for each of ``candidates`` (M, 3), whether a point of ``door_points`` (N, 3)
    within CUP_FOOTPRINT of it across ``grasp``'s approach stands more than CUP_PROUD out of
    the face the grasp's TCP is on, or the candidate itself stands that far out."""
    door = _check_cloud(door_points, "door_points")
    c = np.asarray(candidates, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 3:
        raise ValueError(f"candidates must be an (M, 3) array, got shape {c.shape}")
    out = -np.asarray(grasp.approach, dtype=np.float64)
    face = float(grasp.tcp[:3, 3] @ out)
    proud = door[door @ out > face + CUP_PROUD]
    if len(proud) == 0:
        return np.zeros(len(c), dtype=bool)
    d = c[:, None, :] - proud[None, :, :]
    d = d - (d @ out)[..., None] * out
    return (np.linalg.norm(d, axis=-1).min(1) < CUP_FOOTPRINT) | (c @ out > face + CUP_PROUD)


def clear_suction_point(action_points: np.ndarray, cross_pose: np.ndarray,
                        door_points: np.ndarray | None = None) -> tuple[Grasp | None, bool]:
    """:func:`suction_point` on ``action_points`` (N, 3) under ``cross_pose`` (4, 4), kept
    clear of protrusions of the observed door ``door_points`` (K, 3; default the action
    points themselves): when one (a handle) stands within CUP_FOOTPRINT of that choice, the
    choice is made again among the action points with no protrusion within the footprint
    (when at least MIN_CLEAR_POINTS are left). The hand's closed fingers, as wide as the
    cup, would otherwise strike the handle on the way in and shove the door before the cup
    touches its face.

    Returns (grasp, moved): the grasp (None when the prediction moves nothing) and whether
    it was chosen again away from a protrusion.
    """
    a = _check_cloud(action_points, "action_points")
    door = a if door_points is None else _check_cloud(door_points, "door_points")
    T = np.asarray(cross_pose, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"cross_pose must be a (4, 4) transform, got shape {T.shape}")
    grasp = suction_point(a, T)
    if grasp is None or not proud_near(door, grasp, grasp.tcp[None, :3, 3])[0]:
        return grasp, False
    clear = a[~proud_near(door, grasp, a)]
    if len(clear) < MIN_CLEAR_POINTS:
        return grasp, False
    moved = suction_point(clear, T)
    return (grasp, False) if moved is None else (moved, True)


def top_suction_point(object_points: np.ndarray) -> Grasp:
    """A suction grasp on the middle of the object's top."""
    p = _check_cloud(object_points, "object_points")
    centre = np.array([*(p[:, :2].min(0) + p[:, :2].max(0)) / 2, p[:, 2].max()])
    down = np.array([0.0, 0.0, -1.0])
    return Grasp(_frame(down, np.array([0.0, 1.0, 0.0]), centre), down, 0.0)


def top_grasp(object_points: np.ndarray) -> Grasp | None:
    """Grasp from above, across the object's narrower horizontal extent; None when even
    that is wider than the fingers open."""
    p = _check_cloud(object_points, "object_points")
    xy = p[:, :2] - p[:, :2].mean(0)
    axes = np.linalg.svd(xy, full_matrices=False)[2]
    extents = [float(np.ptp(xy @ ax)) for ax in axes]
    k = int(np.argmin(extents))
    if extents[k] > MAX_GRASP_WIDTH:
        return None
    lo, hi = p.min(0), p.max(0)
    centre = np.array([*(p[:, :2].min(0) + p[:, :2].max(0)) / 2, 0.0])
    depth = min(TOP_GRASP_DEPTH, (hi[2] - lo[2]) / 2)
    centre[2] = hi[2] - depth
    close_dir = np.array([axes[k][0], axes[k][1], 0.0])
    down = np.array([0.0, 0.0, -1.0])
    return Grasp(_frame(down, close_dir, centre), down, extents[k])


CARRY_MARGIN = 0.02        # m: the carried object and hand keep this far from the observed anchor
HAND_HEIGHT = 0.16         # m: the hand reaches this far above the top of what it carries from above
MAX_CARRY_RISE = 0.4       # m: the highest carry considered above the goal
CARRY_STEP = 0.01          # m


def carry_height(object_points: np.ndarray, anchor_points: np.ndarray, start: np.ndarray, goal: np.ndarray) -> float | None:
    """The lowest rise (m) above the goal at which an object, carried from above in a
    straight line from over ``start`` (3,) to over ``goal`` (3,) (its positions at the
    grasp), clears every observed anchor point; None when no rise up to MAX_CARRY_RISE does.

    The swept volume is the object's horizontal radius plus CARRY_MARGIN around the path,
    from the object's bottom minus the margin to its top plus HAND_HEIGHT.
    """
    obj = _check_cloud(object_points, "object_points")
    anchor = _check_cloud(anchor_points, "anchor_points")
    below = start[2] - obj[:, 2].min()
    above = obj[:, 2].max() - start[2]
    centre = (obj[:, :2].min(0) + obj[:, :2].max(0)) / 2
    radius = float(np.linalg.norm(obj[:, :2] - centre, axis=1).max()) + CARRY_MARGIN
    a, b = np.asarray(start[:2], float), np.asarray(goal[:2], float)
    ab = b - a
    u = np.clip(((anchor[:, :2] - a) @ ab) / max(ab @ ab, 1e-12), 0.0, 1.0)
    near = np.linalg.norm(anchor[:, :2] - (a + u[:, None] * ab), axis=1) < radius
    z = anchor[near, 2]
    for rise in np.arange(0.0, MAX_CARRY_RISE + 1e-9, CARRY_STEP):
        level = goal[2] + rise
        lo, hi = level - below - CARRY_MARGIN, level + above + HAND_HEIGHT
        if not np.any((z > lo) & (z < hi)):
            return float(rise)
    return None
