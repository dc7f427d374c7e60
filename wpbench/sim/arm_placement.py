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

The executor takes the first candidate from which the planner reaches every pose of the path.
"""

from __future__ import annotations

import numpy as np

ANGLES_DEG = (0.0, 25.0, -25.0, 50.0, -50.0, 75.0, -75.0)
RADII = (0.55, 0.7, 0.4, 0.85)          # m, base to the middle of the path
BASE_RADIUS = 0.2                        # m, clear of obstacles around the base (link0 and the shoulder's sweep)
BASE_HEIGHT = 0.45                       # m, up to the shoulder


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


def _candidates(anchor: np.ndarray, obstacles: np.ndarray, tcps: np.ndarray, grasp_point: np.ndarray,
                front_from: np.ndarray) -> list[np.ndarray]:
    front = front_direction(anchor, grasp_point)[:2]
    centre = (anchor[:, :2].min(0) + anchor[:, :2].max(0)) / 2
    front_edge = float(((front_from[:, :2] - centre) @ front).max()) if len(front_from) else -np.inf
    middle = tcps[:, :2, 3].mean(0)
    low = obstacles[obstacles[:, 2] < BASE_HEIGHT, :2]
    out = []
    for angle in np.radians(ANGLES_DEG):
        c, s = np.cos(angle), np.sin(angle)
        direction = np.array([c * front[0] - s * front[1], s * front[0] + c * front[1]])
        for radius in RADII:
            xy = middle + radius * direction
            if (xy - centre) @ front < front_edge + BASE_RADIUS:
                continue
            if len(low) and np.min(np.linalg.norm(low - xy, axis=1)) < BASE_RADIUS:
                continue
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
    return strict + beside
