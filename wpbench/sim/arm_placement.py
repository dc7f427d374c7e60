"""Where the Panda's base stands for a stage: candidate base poses in front of the
furniture, from the observed clouds and the stage's planned TCP path only (never the
simulator's ground truth). Pure numpy functions.

The rule (docs/executors.md, ``panda``):

- The furniture's front is the horizontal direction from the centre of the observed
  anchor cloud's footprint (the middle of its x-y bounding box) toward the stage's first
  grasp point (a door's handle side, an object standing in front of the furniture).
- The base stands on the floor, facing the middle of the path (the mean of its TCP
  positions, horizontally), at RADII from that middle, in directions turned ANGLES_DEG from
  the front; candidates are ordered by the turn, then by the radius.
- A candidate is kept only when it stands in front of the anchor cloud (further out along
  the front than every anchor point plus BASE_RADIUS) and no obstacle point (the observed
  clouds, and the action cloud swept along its predicted motion) lies within BASE_RADIUS
  horizontally below BASE_HEIGHT: the arm's base and shoulder would stand in it.
- After those come the candidates that stand in front of the anchor's tall part only (its
  points at least BASE_HEIGHT high), with the same obstacle test: beside a part that lies
  low in front of the furniture (an open oven or dishwasher door), not on it.
- Then the points of a GRID_STEP grid within GRID_EXTENT of the middle that pass the same
  obstacle test and stand BASE_RADIUS outside the footprint (convex hull) of the anchor's
  tall part (beside the furniture, not only in front of it), nearest reach first (the farthest wrist of the path
  from the shoulder; see below), at most MAX_GRID of them.
- Last, the points of a STRIP_STEP grid within GRID_EXTENT of the middle that stand further
  out than the anchor points within STRIP_HALF_WIDTH of them across the front, plus
  BASE_RADIUS (in front of a fridge's opening, beside its door open at a right angle), with
  the same obstacle test, nearest reach first, at most MAX_GRID of them.
- Every candidate must reach the path: for each TCP pose, the wrist (WRIST_BACK behind the
  TCP along its approach) lies within MAX_WRIST_REACH of the shoulder (SHOULDER_HEIGHT above
  the base) and at least MIN_WRIST_RADIUS from the base's vertical axis horizontally. This
  only drops placements the arm's links cannot span; the planner decides the rest.

The executor takes the first candidate from which the planner reaches every pose of the path.
"""

from __future__ import annotations

import numpy as np

ANGLES_DEG = (0.0, 25.0, -25.0, 50.0, -50.0, 75.0, -75.0)
RADII = (0.55, 0.7, 0.4, 0.85)          # m, base to the middle of the path
BASE_RADIUS = 0.2                        # m, clear of obstacles around the base (link0 and the shoulder's sweep)
BASE_HEIGHT = 0.45                       # m, up to the shoulder
SHOULDER_HEIGHT = 0.333                  # m, the Panda's joint 2 above its base
WRIST_BACK = 0.21                        # m, TCP to the wrist (joint 6) along the approach
MAX_WRIST_REACH = 0.8                    # m, shoulder to wrist at most (upper arm 0.33 + forearm 0.39 + offsets)
MIN_WRIST_RADIUS = 0.15                  # m, a wrist closer to the base's axis would be inside link 0-1
GRID_STEP = 0.1                          # m
GRID_EXTENT = 1.0                        # m
MAX_GRID = 8
STRIP_HALF_WIDTH = 0.3                   # m, the anchor points a base must stand in front of: those this near it across the front
STRIP_STEP = 0.05                        # m, the grid of such bases


def _check(points: np.ndarray, name: str) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"{name} must be a non-empty (N, 3) cloud, got shape {p.shape}")
    return p


def front_direction(anchor_points: np.ndarray, grasp_point: np.ndarray) -> np.ndarray:
    """(3,) horizontal unit vector from the anchor footprint's centre toward ``grasp_point`` (3,)."""
    anchor = _check(anchor_points, "anchor_points")
    centre = (anchor[:, :2].min(0) + anchor[:, :2].max(0)) / 2
    d = np.asarray(grasp_point, dtype=np.float64)[:2] - centre
    if np.linalg.norm(d) < 1e-6:
        d = np.array([1.0, 0.0])
    d = d / np.linalg.norm(d)
    return np.array([d[0], d[1], 0.0])


def base_pose(position_xy: np.ndarray, facing_xy: np.ndarray) -> np.ndarray:
    """(4, 4) base on the floor at ``position_xy`` with its x axis toward ``facing_xy``."""
    d = np.asarray(facing_xy, dtype=np.float64) - np.asarray(position_xy, dtype=np.float64)
    yaw = float(np.arctan2(d[1], d[0]))
    T = np.eye(4)
    T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    T[:2, 3] = position_xy
    return T


def wrist_reach(base_xy: np.ndarray, tcps: np.ndarray) -> tuple[float, float]:
    """(the farthest wrist from the shoulder, the nearest wrist to the base's axis horizontally),
    in m, over the TCP poses ``tcps`` (K, 4, 4) for a base standing at ``base_xy`` (2,)."""
    wrist = tcps[:, :3, 3] - WRIST_BACK * tcps[:, :3, 2]
    d = wrist - np.array([base_xy[0], base_xy[1], SHOULDER_HEIGHT])
    return float(np.linalg.norm(d, axis=1).max()), float(np.linalg.norm(d[:, :2], axis=1).min())


def _reaches(base_xy: np.ndarray, tcps: np.ndarray) -> bool:
    far, near = wrist_reach(base_xy, tcps)
    return far <= MAX_WRIST_REACH and near >= MIN_WRIST_RADIUS


def _free(xy: np.ndarray, low: np.ndarray, centre: np.ndarray, front: np.ndarray, front_edge: float) -> bool:
    if (xy - centre) @ front < front_edge + BASE_RADIUS:
        return False
    return not (len(low) and np.min(np.linalg.norm(low - xy, axis=1)) < BASE_RADIUS)


def _hull_test(points: np.ndarray):
    """A test ``inside(xy (M, 2)) -> (M,) bool`` for the convex hull of the points' footprint,
    or None when they span no area."""
    from scipy.spatial import Delaunay, QhullError

    xy = np.unique(np.round(points[:, :2], 3), axis=0)
    if len(xy) < 3:
        return None
    try:
        tri = Delaunay(xy)
    except QhullError:
        return None
    return lambda q: tri.find_simplex(q) >= 0


def _reachable_grid(middle: np.ndarray, step: float, tcps: np.ndarray, low: np.ndarray):
    """Yield ``(farthest wrist distance, xy)`` for the points of a ``step`` grid within GRID_EXTENT
    of ``middle`` from which every TCP pose is within the wrist's reach and that stand
    BASE_RADIUS clear of the low obstacle points ``low`` (K, 2)."""
    g = np.arange(-GRID_EXTENT, GRID_EXTENT + 1e-9, step)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    for p in xy[np.linalg.norm(xy, axis=1) <= GRID_EXTENT] + middle:
        far, near = wrist_reach(p, tcps)
        if far > MAX_WRIST_REACH or near < MIN_WRIST_RADIUS:
            continue
        if len(low) and np.min(np.linalg.norm(low - p, axis=1)) < BASE_RADIUS:
            continue
        yield far, p


def _candidates(anchor: np.ndarray, obstacles: np.ndarray, tcps: np.ndarray, grasp_point: np.ndarray,
                front_from: np.ndarray, grid: bool = False) -> list[np.ndarray]:
    front = front_direction(anchor, grasp_point)[:2]
    centre = (anchor[:, :2].min(0) + anchor[:, :2].max(0)) / 2
    front_edge = float(((front_from[:, :2] - centre) @ front).max()) if len(front_from) else -np.inf
    middle = tcps[:, :2, 3].mean(0)
    low = obstacles[obstacles[:, 2] < BASE_HEIGHT, :2]
    out = []
    if grid:
        inside = _hull_test(front_from)
        ring = BASE_RADIUS * np.array([[np.cos(a), np.sin(a)] for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)])
        scored = []
        for far, p in _reachable_grid(middle, GRID_STEP, tcps, low):
            if inside is not None and inside(np.vstack([p, p + ring])).any():
                continue
            scored.append((far, tuple(p)))
        return [base_pose(np.array(p), middle) for _, p in sorted(scored)[:MAX_GRID]]
    for angle in np.radians(ANGLES_DEG):
        c, s = np.cos(angle), np.sin(angle)
        direction = np.array([c * front[0] - s * front[1], s * front[0] + c * front[1]])
        for radius in RADII:
            xy = middle + radius * direction
            if _free(xy, low, centre, front, front_edge) and _reaches(xy, tcps):
                out.append(base_pose(xy, middle))
    return out


def base_candidates(anchor_points: np.ndarray, obstacle_points: np.ndarray, path_tcps: np.ndarray,
                    grasp_point: np.ndarray) -> list[np.ndarray]:
    """Base poses (4, 4) in the order they are tried (see the module docstring): those in front
    of every anchor point first, then those in front of the anchor's tall part only."""
    anchor = _check(anchor_points, "anchor_points")
    obstacles = _check(obstacle_points, "obstacle_points")
    tcps = np.asarray(path_tcps, dtype=np.float64).reshape(-1, 4, 4)
    strict = _candidates(anchor, obstacles, tcps, grasp_point, anchor)
    tall = anchor[anchor[:, 2] >= BASE_HEIGHT]
    beside = [b for b in _candidates(anchor, obstacles, tcps, grasp_point, tall)
              if not any(np.allclose(b, a) for a in strict)]
    grid = [b for b in _candidates(anchor, obstacles, tcps, grasp_point, tall, grid=True)
            if not any(np.allclose(b[:2, 3], a[:2, 3], atol=0.05) for a in strict + beside)]
    strip = [b for b in _strip_candidates(anchor, obstacles, tcps, grasp_point)
             if not any(np.allclose(b[:2, 3], a[:2, 3], atol=0.05) for a in strict + beside + grid)]
    return strict + beside + grid + strip


def _strip_candidates(anchor: np.ndarray, obstacles: np.ndarray, tcps: np.ndarray,
                      grasp_point: np.ndarray) -> list[np.ndarray]:
    """Bases on a STRIP_STEP grid within GRID_EXTENT of the path's middle that stand in front of
    the anchor points within STRIP_HALF_WIDTH of them across the front (plus BASE_RADIUS), not of
    the whole anchor: in front of a fridge's opening, beside its door open at a right angle, which
    stands further out. The same obstacle and reach tests; those whose farthest wrist is nearest
    first, MAX_GRID at most."""
    front = front_direction(anchor, grasp_point)[:2]
    lateral = np.array([-front[1], front[0]])
    middle = tcps[:, :2, 3].mean(0)
    low = obstacles[obstacles[:, 2] < BASE_HEIGHT, :2]
    scored = []
    for far, p in _reachable_grid(middle, STRIP_STEP, tcps, low):
        d = anchor[:, :2] - p
        strip = np.abs(d @ lateral) < STRIP_HALF_WIDTH
        if strip.any() and float((d[strip] @ front).max()) > -BASE_RADIUS:
            continue
        scored.append((far, tuple(p)))
    return [base_pose(np.array(p), middle) for _, p in sorted(scored)[:MAX_GRID]]
