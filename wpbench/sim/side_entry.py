"""A path that puts a free object into a cavity from the side, through its opening.

The hand holds the object by suction on the face that, at the predicted goal, looks
out of the cavity; it carries the object to a staging pose in front of the opening at
the goal's height, slides it in horizontally, and lowers it onto the goal. Only the
observed object cloud, the observed anchor cloud and the predicted cross-pose are
used. Collision checks are against the anchor cloud: the object (its observed
bounding box in the hand's frame) and the hand (a box around the palm) must keep
CLEARANCE from every anchor point at every sampled pose of the path.
Pure numpy functions.

Frames follow wpbench.sim.gripper: the TCP's z axis is the approach direction (into
the face), its y axis lies along the face (horizontal here).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

# The Panda hand's palm in the TCP frame (from the bundled URDF's collision mesh).
HAND_HALF_THICKNESS = 0.033   # m, along TCP x
HAND_HALF_WIDTH = 0.105       # m, along TCP y
HAND_BACK = 0.13              # m, the palm reaches this far behind the TCP (along -z)
CLEARANCE = 0.012             # m, object and hand keep this far from every anchor point
FLOOR_GAP = 0.006             # m, the palm keeps this far above the floor the object stands on
CUP_EDGE = 0.012              # m, the cup keeps this far from the face's top edge
INSERT_LIFT = 0.006           # m, the object slides in this far above its goal plus the clearance, then is lowered
MAX_INSERT_RISE = 0.16        # m, the highest slide above the lowest one tried
INSERT_RISE_STEP = 0.01       # m
PICK_LIFT = 0.04              # m, lifted this far off the floor before anything else
PREGRASP = 0.10               # m, the hand starts this far back from the face
FACE_ANGLE_STEP_DEG = 1.0     # resolution of the search for the object's side faces
STAGING_STEP = 0.02           # m
MAX_STAGING = 0.7             # m, the farthest staging pose from the goal
TRAVEL_STEP = 0.05            # m
MAX_CANDIDATES = 3            # insertion directions tried for a pick and a carry
LEAD_INS = (0.0, 0.2, 0.4, 0.6, 0.8)   # m: the carry comes down this much further out, then moves in
SPACING_SHARE = 0.5           # an anchor point stands for the surface up to this share of the cloud's spacing
MAX_TRAVEL_RISE = 1.5         # m, the highest carry above the higher end of the carry
PATH_STEP = 0.01              # m between checked poses (and PATH_STEP_ANGLE rad)
PATH_STEP_ANGLE = 0.08
MAX_UPWARD_APPROACH = 0.5     # the pick's approach may point at most this much upward (z of a unit vector)
REGRASP_ANGLES = np.radians(np.arange(30, 360, 30))   # turns tried when the face cannot be reached


@dataclass(frozen=True)
class SidePlan:
    """The side-entry path. TCP poses are (4, 4); ``direction`` (3,) is horizontal, out of
    the cavity; ``regrasp_turn`` (rad) is a turn about the vertical through the object's
    top centre made (by a top suction grasp) before the side pick, 0 when not needed."""

    pick: np.ndarray
    goal: np.ndarray
    direction: np.ndarray
    staging_distance: float
    travel_z: float
    regrasp_turn: float
    lead_in: float = 0.0
    insert_lift: float = INSERT_LIFT

    def carry_waypoints(self) -> list[np.ndarray]:
        """TCP poses from the pick to the goal (the hand holds the object between them): up,
        across at ``travel_z`` to above a point ``lead_in`` further out than the staging pose,
        down, in to the staging pose, slide in, lower."""
        lifted = _shifted(self.pick, [0.0, 0.0, PICK_LIFT])
        high_pick = _with_z(lifted, max(self.travel_z, lifted[2, 3]))
        inserted = _shifted(self.goal, [0.0, 0.0, self.insert_lift])
        stage = _shifted(inserted, self.staging_distance * self.direction)
        lead = _shifted(stage, self.lead_in * self.direction)
        high_lead = _with_z(lead, max(self.travel_z, lead[2, 3]))
        return [self.pick, lifted, high_pick, high_lead, lead, stage, inserted, self.goal]

    def retreat(self) -> np.ndarray:
        """Where the hand backs off to after letting go: the staging pose, without the object."""
        return _shifted(self.goal, self.staging_distance * self.direction + np.array([0.0, 0.0, self.insert_lift]))


def _check_cloud(points: np.ndarray, name: str) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"{name} must be a non-empty (N, 3) cloud, got shape {p.shape}")
    return p


def _shifted(T: np.ndarray, offset) -> np.ndarray:
    out = T.copy()
    out[:3, 3] = out[:3, 3] + np.asarray(offset, dtype=np.float64)
    return out


def _with_z(T: np.ndarray, z: float) -> np.ndarray:
    out = T.copy()
    out[2, 3] = z
    return out


def _transform(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ T[:3, :3].T + T[:3, 3]


def hand_box() -> tuple[np.ndarray, np.ndarray]:
    """(lo (3,), hi (3,)): the palm and fingers in the TCP frame."""
    return (np.array([-HAND_HALF_THICKNESS, -HAND_HALF_WIDTH, -HAND_BACK]),
            np.array([HAND_HALF_THICKNESS, HAND_HALF_WIDTH, 0.0]))


def held_box(object_points: np.ndarray, tcp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo (3,), hi (3,)): the object's observed bounding box in the frame of a TCP (4, 4) that holds it."""
    local = _transform(np.linalg.inv(tcp), _check_cloud(object_points, "object_points"))
    return local.min(0), local.max(0)


def poses_hit(anchor_points: np.ndarray, poses: np.ndarray, boxes: list[tuple[np.ndarray, np.ndarray]],
              clearance: float = CLEARANCE) -> bool:
    """True when some anchor point (N, 3) lies within ``clearance`` of one of the ``boxes``
    (each (lo, hi) in the TCP frame) at one of the TCP ``poses`` (K, 4, 4)."""
    anchor = _check_cloud(anchor_points, "anchor_points")
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    # Anchor points in each pose's frame: (K, N, 3).
    local = np.einsum("kji,knj->kni", poses[:, :3, :3], anchor[None] - poses[:, None, :3, 3])
    for lo, hi in boxes:
        inside = np.all((local > lo - clearance) & (local < hi + clearance), axis=-1)
        if inside.any():
            return True
    return False


def segment_poses(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(K, 4, 4) poses along the straight line and slerp from a to b, PATH_STEP apart (both ends included)."""
    d = float(np.linalg.norm(b[:3, 3] - a[:3, 3]))
    ang = float(np.linalg.norm(Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).as_rotvec()))
    n = max(1, int(np.ceil(max(d / PATH_STEP, ang / PATH_STEP_ANGLE))))
    u = np.linspace(0.0, 1.0, n + 1)
    out = np.tile(np.eye(4), (n + 1, 1, 1))
    out[:, :3, :3] = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([a[:3, :3], b[:3, :3]])))(u).as_matrix()
    out[:, :3, 3] = (1 - u)[:, None] * a[:3, 3] + u[:, None] * b[:3, 3]
    return out


def path_poses(waypoints: list[np.ndarray]) -> np.ndarray:
    """(K, 4, 4) poses along a polyline of TCP waypoints."""
    return np.concatenate([segment_poses(a, b) for a, b in zip(waypoints[:-1], waypoints[1:])])


def face_yaws(points: np.ndarray) -> np.ndarray:
    """(4,) yaws (rad) of the outward normals of the sides of the smallest-area horizontal
    rectangle around ``points`` (N, 3): the directions in which a cup meets a side face flat."""
    p = _check_cloud(points, "points")[:, :2]
    angles = np.radians(np.arange(0.0, 90.0, FACE_ANGLE_STEP_DEG))
    c, s = np.cos(angles), np.sin(angles)
    u = p @ np.stack([c, s])            # (N, K) coordinates along each candidate axis
    v = p @ np.stack([-s, c])
    area = np.ptp(u, axis=0) * np.ptp(v, axis=0)
    best = float(angles[int(np.argmin(area))])
    return best + np.arange(4) * np.pi / 2


def _face_tcp(points: np.ndarray, out: np.ndarray, floor: float, tilt: float = 0.0) -> np.ndarray | None:
    """TCP (4, 4) of a cup on the face of ``points`` (N, 3) that looks along the horizontal
    ``out`` (3,), at the face's middle, high enough that the palm clears ``floor`` even when
    the hand is tilted by ``tilt`` (rad; the cross-pose's tilt, by which the hand holding the
    object level at the goal is tilted at the pick); None when the face is too low for the palm."""
    side = np.cross([0.0, 0.0, 1.0], out)
    along, lateral, z = points @ out, points @ side, points[:, 2]
    tilt_drop = np.sin(min(abs(tilt), np.pi / 2)) * (HAND_HALF_WIDTH + HAND_BACK)
    low = max((z.min() + z.max()) / 2, floor + HAND_HALF_THICKNESS + FLOOR_GAP + tilt_drop)
    if low > z.max() - CUP_EDGE:
        return None
    centre = (lateral.min() + lateral.max()) / 2
    T = np.eye(4)
    T[:3, 2] = -out
    T[:3, 1] = side
    T[:3, 0] = np.cross(side, -out)
    T[:3, 3] = along.max() * out + centre * side + np.array([0.0, 0.0, low])
    return T


def surface_clearance(anchor_points: np.ndarray) -> float:
    """CLEARANCE, widened to SPACING_SHARE of the cloud's median nearest-neighbour spacing
    (a sparse cloud leaves gaps in a wall that a thin box could pass through)."""
    anchor = _check_cloud(anchor_points, "anchor_points")
    if len(anchor) < 2:
        return CLEARANCE
    from scipy.spatial import cKDTree

    spacing = cKDTree(anchor).query(anchor, k=2)[0][:, 1]
    return max(CLEARANCE, SPACING_SHARE * float(np.median(spacing)))


def _staging_distance(anchor: np.ndarray, boxes, inserted: np.ndarray, out: np.ndarray,
                      clearance: float) -> tuple[float, bool] | None:
    """(distance, overhung): the least distance out along ``out`` at which the held object and
    hand have slid clear of the cavity: the straight slide from there to ``inserted`` hits no
    anchor point, and nothing is above the staging pose (the carry comes down onto it);
    overhung False. When something stays above every clear staging pose (an open door's edge,
    a lip), the farthest clear one with overhung True: the carry then has to come in level from
    a lead-in, which the carry check decides. None when the slide is blocked at the goal itself.

    ``inserted`` is a side-entry TCP pose (x up, z = -out), so the slide sweeps each box
    along its own z axis and the column above it extends the box along x.
    """
    local = (anchor - inserted[:3, 3]) @ inserted[:3, :3]
    farthest_clear = None
    for distance in np.arange(0.0, MAX_STAGING + 1e-9, STAGING_STEP):
        slide_hit = column_hit = False
        for lo, hi in boxes:
            across = np.all((local[:, 1:2] > lo[1] - clearance) & (local[:, 1:2] < hi[1] + clearance), axis=1)
            up = local[:, 0] > lo[0] - clearance
            level = up & (local[:, 0] < hi[0] + clearance)
            slide_hit |= bool(np.any(across & level & (local[:, 2] > lo[2] - distance - clearance)
                                     & (local[:, 2] < hi[2] + clearance)))
            column_hit |= bool(np.any(across & up & (local[:, 2] > lo[2] - distance - clearance)
                                      & (local[:, 2] < hi[2] - distance + clearance)))
        if slide_hit:            # a longer slide sweeps this one too
            return None if farthest_clear is None else (farthest_clear, True)
        if not column_hit:
            return float(distance), False
        farthest_clear = float(distance)
    return None if farthest_clear is None else (farthest_clear, True)


def _approach_poses(pick: np.ndarray) -> np.ndarray:
    """(K, 4, 4) TCP poses of the hand coming in along the pick's approach from PREGRASP back."""
    return segment_poses(_shifted(pick, -PREGRASP * pick[:3, 2]), pick)


def _lowest_hand_z(poses: np.ndarray) -> float:
    """The lowest height any corner of the hand box reaches over the TCP ``poses`` (K, 4, 4)."""
    lo, hi = hand_box()
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return float((np.einsum("kj,nj->kn", poses[:, 2, :3], corners) + poses[:, 2, 3:4]).min())


def _lift_clear_of_floor(goal: np.ndarray, cross_pose: np.ndarray, floor: float, top: float) -> np.ndarray | None:
    """The goal TCP (4, 4), raised just so far that at the pick (``inv(cross_pose) @ goal``) the
    hand's whole approach keeps FLOOR_GAP above ``floor``; None when that puts the cup above
    ``top`` (the face's top edge less CUP_EDGE). Exact, so the pick check below, which asks for
    half that gap, is never decided by millimetres of the predicted pose."""
    pick = np.linalg.inv(cross_pose) @ goal
    deficit = floor + FLOOR_GAP - _lowest_hand_z(_approach_poses(pick))
    if deficit <= 0.0:
        return goal
    # Raising the goal by h raises the pick by h * cross_pose[2, 2] (inv's z row of the rotation).
    if cross_pose[2, 2] < 1e-6:
        return None
    raised = _shifted(goal, [0.0, 0.0, deficit / cross_pose[2, 2]])
    return raised if raised[2, 3] <= top else None


def _pick_reachable(anchor: np.ndarray, pick: np.ndarray, floor: float, clearance: float = CLEARANCE) -> bool:
    """The hand can come in along the pick's approach without touching the anchor or the floor."""
    if pick[2, 2] > MAX_UPWARD_APPROACH:
        return False
    poses = _approach_poses(pick)
    return _lowest_hand_z(poses) > floor + FLOOR_GAP / 2 and not poses_hit(anchor, poses, [hand_box()], clearance)


def _turn_about_vertical(angle: float, point: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix()
    T[:3, 3] = point - T[:3, :3] @ point
    return T


def regrasp_centre(object_points: np.ndarray) -> np.ndarray:
    """(3,) the middle of the object's top, where a top suction grasp turns it."""
    p = _check_cloud(object_points, "object_points")
    return np.array([*(p[:, :2].min(0) + p[:, :2].max(0)) / 2, p[:, 2].max()])


def is_roofed(object_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray) -> bool:
    """True when some observed anchor point lies above the object at its predicted goal
    (within its horizontal footprint plus CLEARANCE): the goal is under a roof, so the way
    in is from the side. An open top (a drawer, a shelf) is entered from above."""
    goal = _transform(np.asarray(cross_pose, dtype=np.float64), _check_cloud(object_points, "object_points"))
    anchor = _check_cloud(anchor_points, "anchor_points")
    centre = (goal[:, :2].min(0) + goal[:, :2].max(0)) / 2
    radius = float(np.linalg.norm(goal[:, :2] - centre, axis=1).max()) + CLEARANCE
    over = np.linalg.norm(anchor[:, :2] - centre, axis=1) < radius
    return bool(np.any(anchor[over, 2] > goal[:, 2].max() + CLEARANCE))


def plan_side_entry(object_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray,
                    viewpoint: np.ndarray | None = None) -> SidePlan | None:
    """The side-entry path for the object (observed cloud (N, 3)) to the predicted goal
    ``cross_pose @ now`` among the observed anchor (M, 3); None when no direction gives a
    clear slide in, a reachable face and a clear carry.

    Directions whose slide is clear are tried nearest first to the camera's side when
    ``viewpoint`` (3,), where the clouds were seen from, is given: the camera saw the
    opening, while a wall it saw edge-on or not at all may show no points to stop a slide.
    Without it, the shortest slide first."""
    obj = _check_cloud(object_points, "object_points")
    anchor = _check_cloud(anchor_points, "anchor_points")
    T = np.asarray(cross_pose, dtype=np.float64)
    goal_points = _transform(T, obj)
    floor = float(obj[:, 2].min())
    tilt = float(np.arccos(np.clip(T[2, 2], -1.0, 1.0)))
    clearance = surface_clearance(anchor)
    lift = clearance + INSERT_LIFT
    candidates = []
    for yaw in face_yaws(goal_points):
        out = np.array([np.cos(yaw), np.sin(yaw), 0.0])
        goal = _face_tcp(goal_points, out, float(goal_points[:, 2].min()), tilt)
        if goal is not None:
            goal = _lift_clear_of_floor(goal, T, floor, float(goal_points[:, 2].max()) - CUP_EDGE)
        if goal is None:
            continue
        boxes = [held_box(goal_points, goal), hand_box()]
        # A cavity whose floor lies below its opening's sill (a tub) is entered higher up,
        # then the object is lowered onto its goal. The lowest slide clear above its staging
        # pose is taken; failing that, the lowest overhung one.
        overhung = None
        for rise in np.arange(0.0, MAX_INSERT_RISE + 1e-9, INSERT_RISE_STEP):
            inserted = _shifted(goal, [0.0, 0.0, lift + rise])
            if rise and poses_hit(anchor, segment_poses(inserted, _shifted(goal, [0.0, 0.0, lift])), boxes, clearance):
                break
            staging = _staging_distance(anchor, boxes, inserted, out, clearance)
            if staging is None:
                continue
            candidate = (staging[0], yaw, out, goal, boxes, lift + rise, staging[1])
            if not staging[1]:
                candidates.append(candidate)
                overhung = None
                break
            overhung = overhung or candidate
        if overhung is not None:
            candidates.append(overhung)
    # Slides whose staging pose is clear above come first; overhung ones only fill what is left.
    if viewpoint is not None:
        toward = np.asarray(viewpoint, dtype=np.float64)[:2] - goal_points[:, :2].mean(0)
        seen_yaw = float(np.arctan2(toward[1], toward[0]))
        candidates.sort(key=lambda c: (c[6], abs(np.angle(np.exp(1j * (c[1] - seen_yaw)))), c[0]))
    else:
        # Shortest slide first; ties go to the direction in the middle of the clear ones.
        candidates.sort(key=lambda c: (c[6], c[0], abs(np.angle(np.exp(1j * (c[1] - _mean_yaw(candidates)))))))
    for distance, _, out, goal, boxes, lift, _ in candidates[:MAX_CANDIDATES]:
        pick = np.linalg.inv(T) @ goal
        turn = 0.0
        if not _pick_reachable(anchor, pick, floor, clearance):
            centre = regrasp_centre(obj)
            turns = [a for a in REGRASP_ANGLES if _pick_reachable(anchor, _turn_about_vertical(a, centre) @ pick, floor, clearance)]
            if not turns:
                continue
            turn = float(min(turns, key=lambda a: abs(np.angle(np.exp(1j * a)))))
            pick = _turn_about_vertical(turn, centre) @ pick
        way = SidePlan(pick, goal, out, distance, 0.0, turn, 0.0, lift).carry_waypoints()
        base = max(way[1][2, 3], way[5][2, 3])
        for rise in np.arange(0.0, MAX_TRAVEL_RISE + 1e-9, TRAVEL_STEP):
            for lead_in in LEAD_INS:
                plan = SidePlan(pick, goal, out, distance, float(base + rise), turn, float(lead_in), lift)
                if not poses_hit(anchor, path_poses(plan.carry_waypoints()[1:6]), boxes, clearance):
                    return plan
    return None


def _mean_yaw(candidates) -> float:
    if not candidates:
        return 0.0
    return float(np.angle(np.mean([np.exp(1j * c[1]) for c in candidates])))
