"""The ``panda`` executor: a Panda arm (wpbench.sim.panda_arm) carries out the predicted cross-pose.

It sees what a policy sees (the stage's observed clouds) and the predicted cross-pose,
nothing else, and makes the same grasp and TCP path as the ``gripper`` executor
(wpbench.sim.grasp_choice, wpbench.sim.screw_path, wpbench.sim.side_entry): an arm now
has to reach them.

1. The TCP path is written as a script: free-space moves to a pre-grasp pose, and
   Cartesian pieces (approach, the screw about the predicted hinge or the carry, retreat)
   between grasps and releases. A door is grasped no higher than the arm reaches; a door
   whose face the wrist cannot follow to the end (hinged at its bottom) is pulled part of
   the way, then pushed from its inner side along the rest of the screw (wpbench.sim.door_push).
2. Planning (mplib, wpbench.sim.arm_planner), before anything moves: for each base
   placement (wpbench.sim.arm_placement) the arm's joint path is solved, pose by pose
   along every Cartesian piece (IK seeded with the last pose; no jump, within the joint
   limits, the arm's links clear of the observed anchor cloud), and every free-space move
   is a straight joint-space line or an RRTConnect path clear of the observed clouds. The
   first placement that works is used. A door's turn no placement reaches whole is cut up to
   the stall angle short, and the hand lets go there. None reaches the path: ``unreachable``;
   the poses are reached but no collision-free move or chain exists: ``planning_failed``.
3. Execution: the base is placed, the arm starts at its rest pose, and its joint targets
   (pd_joint_pos, velocity feed-forward) follow the planned joint path at the gripper's
   speeds (minimum-jerk timing); grasps, the joint's release and the settle are the
   gripper's. Physics decides: a wrong hinge pulls against the joint and the arm falls
   behind (``stalled_against_hinge``) or the suction gives (``slipped``); furniture in the
   way stops it (``collision``).
4. After the stage the arm is parked far away, as the gripper is.

Nothing raises: a failure is a result with a reason of wpbench.sim.failure.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from wpbench.sim.arm_placement import base_candidates
from wpbench.sim.arm_planner import ARM_LINKS, HAND_LINKS, ArmPlanner, PlannerError
from wpbench.sim.door_push import handover_fraction, push_grip
from wpbench.sim.executor import ExecutionResult, blown_up, simulate_until_still
from wpbench.sim.failure import (BLOW_UP, COLLISION, GRASP_MISSED, PLANNING_FAILED, SLIPPED, STALLED_AGAINST_HINGE,
                                 UNREACHABLE)
from wpbench.sim.grasp_choice import (Grasp, articulated_grasp, carry_height, clear_suction_point, suction_point, top_grasp,
                                      top_suction_point)
from wpbench.sim.gripper import FINGER_OPEN
from wpbench.sim.gripper_executor import (BLOCKED_OPENING, CARRY_CLEARANCE, CLOSE_SECONDS, CUP_REACH, GUARD_SPEED, GUARD_START, HELD_OPENING, HOLD_SECONDS,
                                          LIFT_HEIGHT, PREGRASP_DISTANCE, REGRASP_LIFT, RELEASE_SECONDS,
                                          RETREAT_DISTANCE, STALL_ANGLE, STALL_DISTANCE, SUCTION_PRESS, SUCTION_SLIP,
                                          _below_floor, _pose_distance, _segment_seconds, _smooth)
from wpbench.sim.panda_arm import HOME_QPOS, PandaArm
from wpbench.sim.place_goal import rest_on_support, upright_equivalent
from wpbench.sim.screw_path import interpolate, path_length, screw_of
from wpbench.sim.side_entry import FLOOR_GAP, is_roofed, plan_side_entry, segment_poses

MAX_JOINT_SPEED = 1.0        # rad/s, the fastest joint of a free-space move (mean speed x 1.875 at the peak)
MIN_MOVE_SECONDS = 0.3
MOVE_CLEARANCE = 0.015       # m, free-space moves keep the arm and hand this far from the observed clouds
ARM_CLEARANCE = 0.01         # m, along Cartesian pieces the arm's links keep this far from the observed anchor
JOINT_STALL = 0.25           # rad, a joint this far behind its target on a free-space move has been stopped
SCREW_STEP = 0.01            # m between IK samples along a screw path ...
SCREW_STEP_ANGLE = 0.05      # ... and rad
RRT_SECONDS = 1.0
IK_SEEDS = 8                 # random IK seeds (a fixed generator) besides the rest pose
MAX_RRT_CANDIDATES = 3       # placements for which RRT is tried when no straight move is clear
# Turns of the TCP about its approach tried for the same grasp: the hand is symmetric under
# half a turn (fingers, palm box); a suction cup from above also under a quarter turn.
FLOOR_EXTENT = 1.2           # m, floor points this far around the base ...
FLOOR_SPACING = 0.05         # m ...
FLOOR_FREE_RADIUS = 0.25     # m ... except under the base
MAX_CHAIN_STARTS = 3         # IK solutions of the pre-grasp pose from which the Cartesian chain is tried
SYMMETRIC_ROLLS = (0.0, np.pi)
MAX_GRASP_HEIGHT = 0.9       # m, a door is grasped no higher than this (the arm stands on the floor) ...
MIN_GRASP_HEIGHT = 0.5       # ... and then no lower than this ...
MIN_LOW_POINTS = 20          # ... when it shows at least this many points in between
FLOOR_GRASP_HEIGHT = 0.12    # m, a door point lower than this is grasped only when the door shows no such band above it
HINGE_REACHES = (0.45, 0.3)  # m, a door no placement reaches along its whole arc is grasped this near its hinge (in turn)
# rad, a door whose whole predicted turn the arm reaches from no placement is turned this much less (in turn) and let go
# there: at most STALL_ANGLE, the shortfall every executor already accepts of a door stopped against its stop.
DOOR_SHORTFALLS = (STALL_ANGLE / 2, STALL_ANGLE)
MIN_DOOR_TURN_LEFT = np.radians(30.0)   # rad, a door is turned at least this far when its turn is shortened
PUSH_RETREAT = 0.12          # m, the hand backs off this far from a door it pulled before it pushes
PULL_HOLD = 0.3             # s, the hand holds a pulled door still this long before it lets go of it
PUSH_DOOR_LAG = 0.08         # rad, the move to a push keeps clear of the door up to this far behind its plan
TOP_SUCTION_ROLLS = (0.0, np.pi, np.pi / 2, -np.pi / 2)
RELAY_LEADS = (0.05, 0.2, 0.35)          # m, a relay spot lies this much further out than the slide needs ...
RELAY_OFFSETS = (0.0, 0.3, -0.3, 0.5, -0.5)   # m ... and this far to the side of the goal
RELAY_MARGIN = 0.08          # m, no anchor point this close to the relayed object's footprint (the hand from above)
REST_TURNS = (0.0, np.pi / 2, -np.pi / 2, 2.6, -2.6)   # rad, joint 1 of the rest pose, tried in turn
MAX_RELAYS = 4               # relay spots planned at most
LEDGE_LEADS = (0.1, 0.14, 0.18, 0.22)   # m, a spot on a surface in front of the opening lies this much further out than the slide needs
MAX_LEDGE_RELAYS = 2         # such spots planned at most
MIN_SUPPORT_POINTS = 3       # observed anchor points under the footprint at least ...
MIN_SUPPORT_HEIGHT = 0.03    # m ... none lower (the floor is not observed; this is furniture) ...
SUPPORT_FLAT = 0.015         # m ... within this of the highest ...
SUPPORT_SPAN = 0.9           # ... spanning this share of the footprint along and across the opening
SUPPORT_REACH = 0.35         # m, around a relayed object its support is the hand's floor this far
SUPPORT_GAP = 0.002          # m, set down this far above the highest of them
MIN_CUP_RAISE = 0.01         # m, a cup raised less than this up the face is not tried separately
RELEASE_DROP = 0.06          # m, an object slid into a cavity may be let go at most this high above its goal
SLIDE_SHORT = 0.08           # m, ... or, where the forearm meets the furniture, this far short of the slide's end
RELAY_PRESS = 0.02           # m, the cup on a relayed object presses this much further
PIECE_JOINT_STEP = 0.04      # rad, a Cartesian piece's samples further apart in a joint than this get more time
SHOULDER_RADIUS = 0.13       # m, a held object keeps out of this vertical cylinder about the base's axis ...
SHOULDER_TOP = 0.45          # m ... up to this height (the arm's base and shoulder, links 0-2)
HELD_SAMPLES = 64            # held object points checked against it
DOOR_CHECKS = 9              # poses along a door's screw where the arm is checked against the moved door ...
DOOR_ARM_LINKS = tuple(f"panda_link{i}" for i in range(6))   # ... these links (the wrist and hand meet it by design)


@dataclass
class ArmScene:
    """What the executor drives: the arm, its planner, one physics step, and the settle test of the action object."""

    arm: PandaArm
    planner: ArmPlanner
    ms_scene: object
    grasp_mode: str
    step: Callable[[], None]
    timestep: float
    velocities: Callable[[], list[np.ndarray]]
    is_still: Callable[[], bool]
    held_touches_furniture: Callable[[], bool] | None = None


# ---------------------------------------------------------------------------- the script
@dataclass
class Move:
    """A free-space move to the TCP pose ``tcp`` (4, 4), clear of ``obstacles`` (N, 3)."""

    tcp: np.ndarray
    obstacles: np.ndarray


@dataclass
class Path:
    """A Cartesian piece: TCP poses ``poses(u)``, u in [0, 1], over ``seconds``; ``sampled``
    (K, 4, 4) are the poses at u = linspace(0, 1, K), where the planner solves IK."""

    poses: Callable[[float], np.ndarray]
    seconds: float
    sampled: np.ndarray
    check_stall: bool = True
    guarded: bool = False        # stops where the cup first touches something that can move
    release_early: float = 0.0   # m, the arm may stop this far short of the end and let go there
    release_early_fallback: float = 0.0   # m, as far as a second planning pass allows (see _roofed_entry)
    # A door moved along the piece: its observed points (N, 3) and their motion (4, 4) at u.
    carries: tuple[np.ndarray, Callable[[float], np.ndarray]] | None = None

    @property
    def samples(self) -> int:
        return len(self.sampled)


@dataclass
class GraspStep:
    grasp: Grasp
    held: np.ndarray | None = None   # the observed object's points in the TCP frame at the grasp


@dataclass
class ReleaseStep:
    pass


@dataclass
class FreeJointStep:
    pass


@dataclass
class HoldStep:
    """Keep the arm still (the joint targets where they are) for ``seconds``."""

    seconds: float


def _line(a: np.ndarray, b: np.ndarray, check_stall: bool = True) -> Path:
    from scipy.spatial.transform import Rotation, Slerp

    sampled = segment_poses(a, b)
    if len(sampled) < 2:
        sampled = np.stack([a, b])
    slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([a[:3, :3], b[:3, :3]])))

    def pose(u: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = slerp(u).as_matrix()
        T[:3, 3] = (1 - u) * a[:3, 3] + u * b[:3, 3]
        return T

    return Path(pose, _segment_seconds(a, b), sampled, check_stall)


def _screw(cross_pose: np.ndarray, grip: np.ndarray, start: float = 0.0, end: float = 1.0) -> Path:
    """The TCP ``grip`` (4, 4, held with the door as it was) along the predicted screw from
    fraction ``start`` to ``end``."""
    length = path_length(cross_pose, grip[:3, 3]) * (end - start)
    angle = screw_of(cross_pose).angle * (end - start)
    samples = max(2, int(np.ceil(max(length / SCREW_STEP, angle / SCREW_STEP_ANGLE))) + 1)
    seconds = _segment_seconds(np.eye(4), interpolate(cross_pose, end - start), length)
    sampled = interpolate(cross_pose, np.linspace(start, end, samples)) @ grip
    return Path(lambda u: interpolate(cross_pose, start + u * (end - start)) @ grip, seconds, sampled)


def _door_screw(cross_pose: np.ndarray, grip: np.ndarray, door_points: np.ndarray, start: float = 0.0,
                end: float = 1.0) -> Path:
    """:func:`_screw`, carrying the observed door along (for the arm's check against it)."""
    piece = _screw(cross_pose, grip, start, end)
    piece.carries = (door_points, lambda u: interpolate(cross_pose, start + u * (end - start)))
    return piece


def _approach(grasp: Grasp, suction: bool, obstacles: np.ndarray, press: float = SUCTION_PRESS,
              slow: bool = False) -> list:
    """Move to the pre-grasp pose, come in along the approach (a cup ``press`` past the surface;
    with ``slow``, the last GUARD_START before the surface and the press at GUARD_SPEED, so a
    free object is pushed gently rather than knocked away), grasp."""
    pre = grasp.tcp.copy()
    pre[:3, 3] -= PREGRASP_DISTANCE * grasp.approach
    contact = grasp.tcp.copy()
    if suction:
        contact[:3, 3] += press * grasp.approach
    if not slow:
        return [Move(pre, obstacles), _line(pre, contact, check_stall=False), GraspStep(grasp)]
    near = grasp.tcp.copy()
    near[:3, 3] -= GUARD_START * grasp.approach
    creep = _line(near, contact, check_stall=False)
    creep.seconds = max(creep.seconds, float(np.linalg.norm(contact[:3, 3] - near[:3, 3])) / GUARD_SPEED)
    creep.guarded = True
    return [Move(pre, obstacles), _line(pre, near, check_stall=False), creep, GraspStep(grasp)]


def _retreat(at: np.ndarray, approach: np.ndarray, retreat_to: np.ndarray | float | None = None) -> list:
    """Let go, back off along the approach (RETREAT_DISTANCE, or ``retreat_to`` metres) or to the pose ``retreat_to``."""
    back = at.copy()
    if retreat_to is None or np.ndim(retreat_to) == 0:
        back[:3, 3] -= (RETREAT_DISTANCE if retreat_to is None else float(retreat_to)) * approach
    else:
        back[:3, 3] = retreat_to[:3, 3]
    return [ReleaseStep(), _line(at, back, check_stall=False)]


# ---------------------------------------------------------------------------- planning
@dataclass
class Segment:
    """A planned motion: joint samples ``q`` (K, 7) at fractions ``grid`` (K,) of ``seconds``
    (default linspace(0, 1, K)); ``poses`` (Cartesian pieces) gives the TCP target of sample
    position s in [0, 1] (sample k at s = k / (K - 1)) for the stall check."""

    q: np.ndarray
    seconds: float
    poses: Callable[[float], np.ndarray] | None = None
    check_stall: bool = True
    guarded: bool = False
    grid: np.ndarray | None = None


@dataclass
class Plan:
    base: np.ndarray
    steps: list = field(default_factory=list)     # Segment | GraspStep | ReleaseStep | FreeJointStep
    script_index: int = 0
    start: np.ndarray = field(default_factory=lambda: HOME_QPOS.copy())   # the rest pose the arm starts from


class _NoPlan(Exception):
    def __init__(self, reason: str, detail: str):
        super().__init__(detail)
        self.reason, self.detail = reason, detail


def _ik_seeds() -> np.ndarray:
    rng = np.random.default_rng(0)
    lo = np.array([-2.8, -1.7, -2.8, -3.0, -2.8, 0.0, -2.8])
    hi = np.array([2.8, 1.7, 2.8, -0.1, 2.8, 3.7, 2.8])
    return np.vstack([HOME_QPOS, rng.uniform(lo, hi, size=(IK_SEEDS, 7))])


def floor_points(base: np.ndarray) -> np.ndarray:
    """The floor as obstacle points (FLOOR_SPACING apart, FLOOR_EXTENT around the base), except
    under the base itself, where the robot stands on it."""
    g = np.arange(-FLOOR_EXTENT, FLOOR_EXTENT + 1e-9, FLOOR_SPACING)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    xy = xy[np.linalg.norm(xy, axis=1) > FLOOR_FREE_RADIUS] + base[:2, 3]
    return np.concatenate([xy, np.full((len(xy), 1), -ARM_CLEARANCE)], axis=1)


def _move_timing(q: np.ndarray) -> tuple[np.ndarray, float]:
    """Joint path (M, 7) -> (samples at uniform u (K, 7), seconds), by joint-space arc length."""
    steps = np.abs(np.diff(q, axis=0)).max(1)
    total = float(steps.sum())
    if total < 1e-9:
        return np.stack([q[0], q[-1]]), MIN_MOVE_SECONDS
    s = np.concatenate([[0.0], np.cumsum(steps)]) / total
    k = max(2, int(np.ceil(total / 0.02)) + 1)
    u = np.linspace(0.0, 1.0, k)
    samples = np.stack([np.interp(u, s, q[:, j]) for j in range(q.shape[1])], axis=1)
    return samples, max(MIN_MOVE_SECONDS, 1.875 * total / MAX_JOINT_SPEED)


def _plan_at(planner: ArmPlanner, base: np.ndarray, script: list, anchor: np.ndarray,
             allow_rrt: bool) -> tuple[Plan | None, str, str, bool]:
    """The joint-space plan of ``script`` from ``base``; (None, reason, detail, cuttable) when it
    fails, where ``cuttable`` says the arm gave out in a piece within its ``release_early_fallback``
    of the end (a second pass that lets the piece end early would plan it differently)."""
    if _held_meets_shoulder(script, base):
        return None, PLANNING_FAILED, "the held object would meet the arm's shoulder", False
    planner.set_base(base)
    floor = floor_points(base)
    anchor = np.concatenate([anchor, floor])
    plan = Plan(base)
    q = HOME_QPOS.copy()
    if isinstance(script[0], Move):
        # The rest pose turned about the base's vertical axis, the first that touches nothing observed.
        planner.set_cloud(np.concatenate([script[0].obstacles, floor]), MOVE_CLEARANCE)
        for turn in REST_TURNS:
            start = HOME_QPOS.copy()
            start[0] = turn
            if not planner.collisions(start, ARM_LINKS + HAND_LINKS):
                q = plan.start = start
                break
    k = 0
    while k < len(script):
        step = script[k]
        if not isinstance(step, Move):
            if isinstance(step, Path):
                return None, PLANNING_FAILED, "a Cartesian piece without a move before it", False
            plan.steps.append(step)
            k += 1
            continue
        # The Cartesian pieces (and the grasps between them) up to the next move.
        j = k + 1
        while j < len(script) and not isinstance(script[j], Move):
            j += 1
        pieces = [s for s in script[k + 1:j] if isinstance(s, Path)]
        tcps = np.concatenate([p.sampled for p in pieces])
        planner.set_cloud(np.concatenate([step.obstacles, floor]), MOVE_CLEARANCE)
        touching = planner.collisions(q, ARM_LINKS + HAND_LINKS)
        if touching:
            return (None, PLANNING_FAILED, f"the arm's start pose touches the observed scene ({', '.join(touching)})",
                    False)
        goals = planner.ik(step.tcp, _ik_seeds(), ARM_LINKS + HAND_LINKS)
        if not goals:
            return None, UNREACHABLE, "no collision-free IK solution for the pre-grasp pose", False
        planner.set_cloud(anchor, ARM_CLEARANCE)
        chain = why = None
        furthest = None
        for goal in sorted(goals, key=lambda g: float(np.abs(g - q).max()))[:MAX_CHAIN_STARTS]:
            chain, why = planner.chain(tcps, goal, ARM_LINKS)
            if chain is not None:
                hit = _arm_meets_door(planner, script[k + 1:j], chain)
                if hit is None and j < len(script):
                    # The next free-space move starts where this chain ends: that pose must clear its obstacles.
                    planner.set_cloud(np.concatenate([script[j].obstacles, floor]), MOVE_CLEARANCE)
                    touching = planner.collisions(chain[-1], ARM_LINKS + HAND_LINKS)
                    if touching:
                        hit = {"ok": False, "why": "collision", "links": touching, "index": len(tcps) - 1}
                if hit is None:
                    break
                chain, why = None, hit
                planner.set_cloud(anchor, ARM_CLEARANCE)
            if furthest is None or why.get("index", 0) > furthest.get("index", 0):
                furthest = why
        if chain is None:
            shorter = _let_go_earlier(script, k + 1, j, furthest.get("index", 0))
            if shorter is not None:
                return _plan_at(planner, base, shorter, anchor[:len(anchor) - len(floor)], allow_rrt)
            cuttable = _let_go_earlier(script, k + 1, j, furthest.get("index", 0), fallback=True) is not None
            why = furthest
            reason = PLANNING_FAILED if why.get("why") == "collision" else UNREACHABLE
            links = f": {', '.join(why['links'])}" if why.get("links") else ""
            return None, reason, (f"the arm cannot follow the path ({why.get('why')}{links} at pose "
                                  f"{why.get('index')} of {len(tcps)})"), cuttable
        planner.set_cloud(np.concatenate([step.obstacles, floor]), MOVE_CLEARANCE)
        if planner.line_clear(q, chain[0], ARM_LINKS + HAND_LINKS):
            joint_path = np.stack([q, chain[0]])
        else:
            if not allow_rrt:
                return None, PLANNING_FAILED, "no straight collision-free move to the pre-grasp pose", False
            joint_path = planner.rrt(q, chain[0], RRT_SECONDS)
            if joint_path is None:
                return None, PLANNING_FAILED, "RRTConnect found no collision-free move to the pre-grasp pose", False
        samples, seconds = _move_timing(joint_path)
        plan.steps.append(Segment(samples, seconds, None, True))
        start = 0
        for s in script[k + 1:j]:
            if isinstance(s, Path):
                q_piece = chain[start:start + s.samples]
                grid, stretch = _piece_timing(q_piece)
                plan.steps.append(Segment(q_piece, s.seconds * stretch, s.poses, s.check_stall, s.guarded, grid))
                start += s.samples
            else:
                plan.steps.append(s)
        q = chain[-1]
        k = j
    return plan, "", "", False


def _piece_timing(q: np.ndarray) -> tuple[np.ndarray, float]:
    """Joint path (K, 7) of a Cartesian piece -> (the fraction of its time at each sample, the
    factor its time grows by): a step between samples that turns a joint more than
    PIECE_JOINT_STEP (where the planner turned the elbow away) gets time in proportion, so
    the joints move no faster there than along the rest of the piece."""
    if len(q) < 2:
        return np.linspace(0.0, 1.0, max(len(q), 2)), 1.0
    steps = np.abs(np.diff(q, axis=0)).max(1)
    weight = np.maximum(1.0, steps / PIECE_JOINT_STEP)
    grid = np.concatenate([[0.0], np.cumsum(weight)]) / weight.sum()
    return grid, float(weight.sum() / len(weight))


def _holding(script: list, object_points: np.ndarray) -> list:
    """``script`` with its grasps marked as holding ``object_points`` (the object's observed cloud
    where it is when grasped)."""
    pts = np.asarray(object_points, dtype=np.float64)
    pts = pts[np.linspace(0, len(pts) - 1, min(len(pts), HELD_SAMPLES)).astype(int)]
    for step in script:
        if isinstance(step, GraspStep):
            inv = np.linalg.inv(step.grasp.tcp)
            step.held = pts @ inv[:3, :3].T + inv[:3, 3]
    return script


def _held_meets_shoulder(script: list, base: np.ndarray) -> bool:
    """Whether an object held along ``script``'s Cartesian pieces comes into the cylinder of the
    arm's base and shoulder (SHOULDER_RADIUS about the base's axis, up to SHOULDER_TOP), which the
    planner's arm-against-cloud checks do not see."""
    held = None
    for step in script:
        if isinstance(step, GraspStep):
            held = step.held
        elif isinstance(step, ReleaseStep):
            held = None
        elif isinstance(step, Path) and held is not None:
            T = step.sampled
            pts = np.einsum("kij,nj->kni", T[:, :3, :3], held) + T[:, None, :3, 3]
            near = np.linalg.norm(pts[..., :2] - base[:2, 3], axis=-1) < SHOULDER_RADIUS
            if np.any(near & (pts[..., 2] < SHOULDER_TOP)):
                return True
    return False


def _arm_meets_door(planner: ArmPlanner, steps: list, chain: np.ndarray) -> dict | None:
    """The first of DOOR_CHECKS poses along each door-moving piece of ``steps`` (joint path
    ``chain``) where an arm link of DOOR_ARM_LINKS comes within ARM_CLEARANCE of the observed
    door moved as the prediction moves it there (the planner's cloud is the anchor, which the
    door is not), as the chain's failure; None when there is none. Leaves the door as the cloud."""
    start = 0
    for piece in steps:
        if not isinstance(piece, Path):
            continue
        if piece.carries is not None:
            points, motion = piece.carries
            for idx in np.unique(np.linspace(0, piece.samples - 1, DOOR_CHECKS).round().astype(int)):
                planner.set_cloud(_moved(points, motion(idx / max(piece.samples - 1, 1))), ARM_CLEARANCE)
                hits = planner.collisions(chain[start + idx], DOOR_ARM_LINKS)
                if hits:
                    return {"ok": False, "why": "collision", "links": hits, "index": start + idx}
        start += piece.samples
    return None


def _let_go_earlier(script: list, first: int, end: int, failed_at: int, fallback: bool = False) -> list | None:
    """``script`` with the piece among ``script[first:end]`` in which the chain failed at pose
    ``failed_at`` cut at the pose before, when that piece may end early (``release_early``, or
    ``release_early_fallback`` with ``fallback``) by what is left of it; the pieces between it
    and the release that follows are left out (the object is let go where the cut piece now
    ends) and the retreat after the release starts there. None when it may not, or when no
    release follows before ``end``."""
    start = 0
    for n in range(first, end):
        piece = script[n]
        if not isinstance(piece, Path):
            continue
        if start <= failed_at < start + piece.samples:
            last = failed_at - start - 1
            allowed = piece.release_early_fallback if fallback else piece.release_early
            if allowed <= 0 or last < 0:
                return None
            end_pose = piece.sampled[last]
            if np.linalg.norm(piece.sampled[-1][:3, 3] - end_pose[:3, 3]) > allowed:
                return None
            out = list(script)
            if last >= 1:
                out[n] = _line(piece.sampled[0], end_pose, piece.check_stall)
            else:
                out[n] = None
            released = False
            for m in range(n + 1, end):
                if isinstance(out[m], ReleaseStep):
                    released = True
                elif isinstance(out[m], Path):
                    if released:
                        out[m] = _line(end_pose, out[m].sampled[-1], check_stall=False)
                        break
                    out[m] = None
            if not released:
                return None
            return [x for x in out if x is not None]
        start += piece.samples
    return None


def plan_script(planner: ArmPlanner, scripts: list[list], anchor: np.ndarray, obstacles: np.ndarray,
                grasp_point: np.ndarray) -> tuple[Plan | None, str, str, int, bool]:
    """Try base placements in order, and at each the scripts in order (the same path with the
    TCP rolled about its approach); straight moves first, then RRT on the first few
    placements that reach the path. Returns (plan or None, reason, detail, placements tried,
    whether some failure was ``cuttable`` as :func:`_plan_at` says); ``plan.script_index`` says
    which script was planned."""
    tcps = []
    for s in scripts[0]:
        if isinstance(s, Move):
            tcps.append(s.tcp)
        elif isinstance(s, Path):
            tcps.extend([s.sampled[0], s.sampled[-1]])
    candidates = base_candidates(anchor, obstacles, np.stack(tcps), grasp_point)
    if not candidates:
        return (None, UNREACHABLE, "no free floor in front of or beside the furniture within the arm's reach of the path",
                0, False)
    reasons = []
    cuttable = False
    retry = []
    for n, base in enumerate(candidates, start=1):
        for index, script in enumerate(scripts):
            plan, reason, detail, cut = _plan_at(planner, base, script, anchor, allow_rrt=False)
            if plan is not None:
                plan.script_index = index
                return plan, "", "", n, cuttable
            reasons.append((reason, detail))
            cuttable = cuttable or cut
            if reason == PLANNING_FAILED and detail.startswith("no straight"):
                retry.append((base, index))
    for base, index in retry[:MAX_RRT_CANDIDATES]:
        plan, reason, detail, cut = _plan_at(planner, base, scripts[index], anchor, allow_rrt=True)
        if plan is not None:
            plan.script_index = index
            return plan, "", "", len(candidates), cuttable
        reasons.append((reason, detail))
        cuttable = cuttable or cut
    # The most telling reason: a placement that reached the poses but found no clear way.
    for wanted in (PLANNING_FAILED, UNREACHABLE):
        hits = [d for r, d in reasons if r == wanted]
        if hits:
            return None, wanted, f"{hits[0]} (all {len(candidates)} base placements failed)", len(candidates), cuttable
    return None, UNREACHABLE, "no base placement reaches the path", len(candidates), cuttable


# ---------------------------------------------------------------------------- execution
class _Abort(Exception):
    def __init__(self, reason: str, detail: str = ""):
        super().__init__(detail)
        self.reason, self.detail = reason, detail


class _Runner:
    def __init__(self, scene: ArmScene, stall_reason: str):
        self.s = scene
        self.seconds = 0.0
        self.stall_reason = stall_reason
        self.holding = False
        self.executed: list[np.ndarray] = []

    def tick(self) -> None:
        self.s.step()
        self.seconds += self.s.timestep
        self.executed.append(self.s.arm.tcp_pose()[:3, 3])
        detail = blown_up(self.s.velocities() + self.s.arm.velocities())
        if detail:
            raise _Abort(BLOW_UP, detail)

    def wait(self, seconds: float) -> None:
        for _ in range(int(round(seconds / self.s.timestep))):
            self.tick()

    def segment(self, seg: Segment) -> None:
        arm = self.s.arm
        n = max(1, int(round(seg.seconds / self.s.timestep)))
        even = np.linspace(0.0, 1.0, len(seg.q))
        grid = even if seg.grid is None or len(seg.grid) != len(seg.q) else seg.grid

        def q_at(u: float) -> np.ndarray:
            return np.array([np.interp(u, grid, seg.q[:, j]) for j in range(seg.q.shape[1])])

        for k in range(1, n + 1):
            u = _smooth(k / n)
            target = q_at(u)
            speed = (q_at(_smooth(min(1.0, (k + 1) / n))) - target) / self.s.timestep
            arm.set_joint_targets(target, speed)
            self.tick()
            if seg.guarded and self._cup_touches():
                arm.set_joint_targets(arm.qpos())
                return
            if self.holding and self._slipped():
                touching = self.s.held_touches_furniture
                if touching is not None and touching():
                    raise _Abort(COLLISION, "the furniture stopped the held object and pulled it off the cup")
                raise _Abort(SLIPPED, "the object left the hand while moving" + self._touching())
            if not seg.check_stall:
                continue
            if seg.poses is not None:
                d, ang = _pose_distance(arm.tcp_pose(), seg.poses(float(np.interp(u, grid, even))))
                if d > STALL_DISTANCE or ang > STALL_ANGLE:
                    raise _Abort(self.stall_reason, f"hand {d * 100:.1f} cm / {np.degrees(ang):.0f} deg behind its target"
                                 + self._touching())
            else:
                lag = float(np.abs(arm.qpos() - target).max())
                if lag > JOINT_STALL:
                    raise _Abort(COLLISION, f"the arm was stopped on its way ({np.degrees(lag):.0f} deg behind)"
                                 + self._touching())
        arm.set_joint_targets(seg.q[-1])

    def _cup_touches(self) -> bool:
        """The cup touches something that can move (not the static ground)."""
        from sapien import physx

        body = self.s.arm.touched_body(self.s.ms_scene.px.get_contacts(), near=CUP_REACH)
        return body is not None and not isinstance(body, physx.PhysxRigidStaticComponent)

    def _touching(self) -> str:
        touching = self.s.arm.contacts_with_others(self.s.ms_scene.px.get_contacts())
        return f"; touching: {', '.join(touching)}" if touching else ""

    def _slipped(self) -> bool:
        arm = self.s.arm
        if self.s.grasp_mode == "suction":
            if arm.suction_stretch() > SUCTION_SLIP:
                arm.detach()
                return True
            return False
        return arm.opening < HELD_OPENING

    def grasp(self, grasp: Grasp) -> None:
        arm = self.s.arm
        if self.s.grasp_mode == "suction":
            self.wait(HOLD_SECONDS)
            body = arm.touched_body(self.s.ms_scene.px.get_contacts())
            if body is None:
                raise _Abort(GRASP_MISSED, "the suction cup touched nothing")
            arm.attach(self.s.ms_scene, body)
        else:
            arm.set_fingers(-0.02)
            self.wait(CLOSE_SECONDS)
            if arm.opening < HELD_OPENING:
                raise _Abort(GRASP_MISSED, "the fingers closed on nothing")
            if arm.opening > BLOCKED_OPENING:
                raise _Abort(GRASP_MISSED, "the fingers could not close (nothing to pinch)")
        self.holding = True

    def release(self) -> None:
        arm = self.s.arm
        self.holding = False
        arm.detach()
        self.wait(HOLD_SECONDS)
        arm.set_fingers(2 * FINGER_OPEN if self.s.grasp_mode != "suction" else 0.0)
        self.wait(RELEASE_SECONDS)


def _settle(scene: ArmScene) -> ExecutionResult:
    return simulate_until_still(scene.step, scene.timestep, scene.velocities, scene.is_still)


def _finish(run: _Runner | None, result: ExecutionResult, extra: dict) -> ExecutionResult:
    if run is not None:
        result.sim_seconds += run.seconds
        result.details["executed_path"] = np.asarray(run.executed[::10]).round(4).tolist()
    result.details.update(extra)
    return result


def _plan(scene: ArmScene, scripts: list[list], anchor: np.ndarray, obstacles: np.ndarray, grasp_point: np.ndarray,
          extra: dict) -> tuple[Plan | None, ExecutionResult | None]:
    """(plan, None), or (None, the failure as a result) when no base placement works; ``extra``
    records ``slide_failed_near_end`` when some placement's arm gave out near a slide's end."""
    try:
        plan, reason, detail, tried, cuttable = plan_script(scene.planner, scripts, anchor, obstacles, grasp_point)
    except PlannerError as err:
        plan, reason, detail, tried, cuttable = None, PLANNING_FAILED, str(err), 0, False
    extra["placements_tried"] = extra.get("placements_tried", 0) + tried
    if cuttable:
        extra["slide_failed_near_end"] = True
    if plan is None:
        return None, ExecutionResult(ok=False, reason=reason, detail=detail)
    return plan, None


def _carry_out(scene: ArmScene, plan: Plan, rolls: tuple[float, ...], extra: dict, stall_reason: str,
               free_joint: Callable[[], None] | None = None,
               hold_joint: Callable[[], None] | None = None) -> ExecutionResult:
    """Execute a plan; a failure stops the arm, lets go, and the scene is scored as it is."""
    extra["arm_base"] = plan.base[:3, 3].round(4).tolist()
    extra["tcp_roll_deg"] = float(np.degrees(rolls[plan.script_index]))
    extra["arm_base_yaw_deg"] = float(np.degrees(np.arctan2(plan.base[1, 0], plan.base[0, 0])))
    arm = scene.arm
    opening = 0.0 if scene.grasp_mode == "suction" else 2 * FINGER_OPEN
    arm.place(plan.base, plan.start, opening)
    run = _Runner(scene, stall_reason)
    try:
        for step in plan.steps:
            if isinstance(step, Segment):
                run.segment(step)
            elif isinstance(step, GraspStep):
                run.grasp(step.grasp)
            elif isinstance(step, ReleaseStep):
                run.release()
            elif isinstance(step, FreeJointStep) and free_joint is not None:
                free_joint()
            elif isinstance(step, HoldStep):
                run.wait(step.seconds)
    except _Abort as abort:
        arm.detach()
        arm.set_fingers(2 * FINGER_OPEN)
        if abort.reason != BLOW_UP:
            try:
                run.wait(RELEASE_SECONDS)
            except _Abort as late:
                # The scene blew up while the hand let go: that is the stage's failure.
                abort = late
        arm.park()
        if hold_joint is not None:
            hold_joint()
        settled = _settle(scene) if abort.reason != BLOW_UP else ExecutionResult(ok=False)
        result = ExecutionResult(ok=abort.reason != BLOW_UP, reason=abort.reason, detail=str(abort.detail),
                                 sim_seconds=settled.sim_seconds, at_rest=settled.at_rest)
        return _finish(run, result, extra)
    arm.park()
    if hold_joint is not None:
        hold_joint()
    return _finish(run, _settle(scene), extra)


def _run(scene: ArmScene, scripts: list[list], rolls: tuple[float, ...], anchor: np.ndarray, obstacles: np.ndarray, grasp_point: np.ndarray,
         extra: dict, stall_reason: str, free_joint: Callable[[], None] | None = None,
         hold_joint: Callable[[], None] | None = None) -> ExecutionResult:
    """Plan the script, then carry it out."""
    plan, failed = _plan(scene, scripts, anchor, obstacles, grasp_point, extra)
    if plan is None:
        return _finish(None, failed, extra)
    return _carry_out(scene, plan, rolls, extra, stall_reason, free_joint, hold_joint)


def _rolled(T: np.ndarray, roll: float) -> np.ndarray:
    """TCP pose ``T`` (4, 4) turned by ``roll`` about its own approach (z) axis."""
    c, s = np.cos(roll), np.sin(roll)
    R = np.eye(4)
    R[:2, :2] = [[c, -s], [s, c]]
    return T @ R


def _rolled_grasp(grasp: Grasp, roll: float) -> Grasp:
    return Grasp(_rolled(grasp.tcp, roll), grasp.approach, grasp.width)


def execute_articulated_panda(scene: ArmScene, action_points: np.ndarray, anchor_points: np.ndarray,
                              cross_pose: np.ndarray, free_joint: Callable[[], None],
                              hold_joint: Callable[[], None]) -> ExecutionResult:
    """Grasp the door or drawer as the gripper does, move it along the predicted screw, release,
    settle. When no grasp reaches the whole turn (``unreachable``), the turn cut DOOR_SHORTFALLS
    short, the first that plans, and the hand lets go there (``let_go_short_deg`` in the result):
    a door aimed past its stop is held by the stop whatever the hand does beyond it, and a door
    aimed short ends shorter still, so a cut does not rescue it. When no cut plans, the full
    turn's failure."""
    suction = scene.grasp_mode == "suction"
    plan, failed, extra = _door_grasps(scene, action_points, anchor_points, cross_pose, suction)
    screw = screw_of(cross_pose)
    tried = extra.get("placements_tried", 0)
    for cut in DOOR_SHORTFALLS:
        if plan is not None or failed is None or failed.reason != UNREACHABLE or screw.angle - cut < MIN_DOOR_TURN_LEFT:
            break
        shorter = interpolate(cross_pose, 1.0 - cut / screw.angle)
        plan2, _, extra2 = _door_grasps(scene, action_points, anchor_points, shorter, suction)
        tried += extra2.get("placements_tried", 0)
        if plan2 is not None:
            plan, extra = plan2, {**extra2, "let_go_short_deg": round(float(np.degrees(cut)), 1)}
    extra["placements_tried"] = tried
    if plan is None:
        if failed is None:   # the prediction moves nothing: the arm has nothing to do
            return _finish(None, _settle(scene), extra)
        return _finish(None, failed, extra)
    return _carry_out(scene, plan, SYMMETRIC_ROLLS, extra, STALLED_AGAINST_HINGE, free_joint, hold_joint)


def _door_grasps(scene: ArmScene, action_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray,
                 suction: bool) -> tuple[Plan | None, ExecutionResult | None, dict]:
    """The door's grasps in turn, planned along ``cross_pose``: (plan or None, the failure or None
    when the prediction moves nothing, what the result records)."""
    if not suction:
        return _door_attempt(scene, articulated_grasp, action_points, anchor_points, cross_pose, suction)
    # First a cup grasp clear of protrusions (a handle); when no placement plans it and
    # it differs from the gripper's choice, that choice.
    plan, failed, extra = _door_attempt(scene, _clear_suction(action_points), action_points, anchor_points,
                                        cross_pose, suction)
    if plan is None and extra.get("grasp_clear_of_handle"):
        plan2, failed2, extra2 = _door_attempt(scene, suction_point, action_points, anchor_points,
                                               cross_pose, suction)
        extra2["placements_tried"] = extra2.get("placements_tried", 0) + extra.get("placements_tried", 0)
        if plan2 is not None:
            plan, failed, extra = plan2, failed2, extra2
    return plan, failed, extra


def _door_attempt(scene: ArmScene, choose: Callable, action_points: np.ndarray, anchor_points: np.ndarray,
                  cross_pose: np.ndarray, suction: bool) -> tuple[Plan | None, ExecutionResult | None, dict]:
    """The door's grasp by ``choose`` (kept within the arm's height, nearer the hinge when the
    whole arc is out of reach), planned: (plan or None, the failure or None when the
    prediction moves nothing, what the result records)."""
    grasp = choose(action_points, cross_pose)
    if grasp is None:
        return None, None, {"grasp_point": None}
    z = action_points[:, 2]
    low = action_points[(z >= MIN_GRASP_HEIGHT) & (z <= MAX_GRASP_HEIGHT)]
    if grasp.tcp[2, 3] > MAX_GRASP_HEIGHT and len(low) >= MIN_LOW_POINTS:
        # A tall door: the same choice among the door points a floor-standing arm reaches well.
        grasp = choose(low, cross_pose) or grasp
    band = action_points[(z >= FLOOR_GRASP_HEIGHT) & (z <= MAX_GRASP_HEIGHT)]
    if grasp.tcp[2, 3] < FLOOR_GRASP_HEIGHT and len(band) >= MIN_LOW_POINTS:
        # A grasp at the floor (the hand and wrist meet the floor about it): the same choice
        # among the door points above the floor and within the arm's height.
        grasp = choose(band, cross_pose) or grasp
    plan, failed, extra = _door_plan(scene, grasp, action_points, anchor_points, cross_pose, suction)
    screw = screw_of(cross_pose)
    if suction and plan is None and failed.reason == UNREACHABLE and screw.angle >= np.radians(10.0):
        # No placement reaches the whole arc: the same choice among the door points nearer the hinge
        # (a shorter arc; the door is pushed with more force at the cup).
        tried = extra.get("placements_tried", 0)
        for reach in HINGE_REACHES:
            near = action_points[np.linalg.norm(np.cross(action_points - screw.point, screw.axis), axis=1) <= reach]
            nz = near[:, 2]
            if grasp.tcp[2, 3] > MAX_GRASP_HEIGHT and np.sum((nz >= MIN_GRASP_HEIGHT) & (nz <= MAX_GRASP_HEIGHT)) >= MIN_LOW_POINTS:
                near = near[(nz >= MIN_GRASP_HEIGHT) & (nz <= MAX_GRASP_HEIGHT)]
            elif np.sum(nz >= FLOOR_GRASP_HEIGHT) >= MIN_LOW_POINTS:
                near = near[nz >= FLOOR_GRASP_HEIGHT]
            closer = choose(near, cross_pose) if len(near) >= MIN_LOW_POINTS else None
            if closer is None:
                continue
            plan2, failed2, extra2 = _door_plan(scene, closer, action_points, anchor_points, cross_pose, suction)
            tried += extra2.get("placements_tried", 0)
            extra2["placements_tried"] = tried
            extra2["grasp_near_hinge"] = True
            if plan2 is not None or failed2.reason != UNREACHABLE:
                plan, failed, extra = plan2, failed2, extra2
                break
    if getattr(choose, "moved", None) is not None and choose.moved[-1]:
        extra["grasp_clear_of_handle"] = True
    return plan, failed, extra


def _clear_suction(action_points: np.ndarray) -> Callable[[np.ndarray, np.ndarray], Grasp | None]:
    """A choice for ``_door_attempt``: wpbench.sim.grasp_choice.clear_suction_point among the
    given door points, with protrusions looked for on the whole observed door
    ``action_points``; ``choose.moved`` records, per call, whether the choice moved off a handle."""
    def choose(points: np.ndarray, cross_pose: np.ndarray) -> Grasp | None:
        grasp, moved = clear_suction_point(points, cross_pose, action_points)
        choose.moved.append(moved)
        return grasp
    choose.moved = []
    return choose


def _door_plan(scene: ArmScene, grasp: Grasp, action_points: np.ndarray, anchor_points: np.ndarray,
               cross_pose: np.ndarray, suction: bool) -> tuple[Plan | None, ExecutionResult | None, dict]:
    """The door's scripts for ``grasp`` (pull along the screw, or pull then push), planned:
    (plan or None, the failure or None, what the result records)."""
    extra = {"grasp_point": grasp.tcp[:3, 3].round(4).tolist(), "grasp_approach": grasp.approach.round(4).tolist(),
             "grasp_width": grasp.width}
    path = interpolate(cross_pose, np.linspace(0, 1, 11)) @ grasp.tcp
    extra["planned_path"] = path[:, :3, 3].round(4).tolist()
    if _below_floor(path):
        return None, ExecutionResult(ok=False, reason=UNREACHABLE, detail="the path goes under the floor"), extra
    scene_points = np.concatenate([anchor_points, action_points])
    # A face the wrist cannot follow to the end (a bottom-hinged door): let go and push the rest.
    handover = handover_fraction(cross_pose, grasp.tcp) if suction else None
    if handover is not None:
        extra["push_from"] = handover
    scripts = []
    for roll in SYMMETRIC_ROLLS:
        g = _rolled_grasp(grasp, roll)
        if handover is None:
            screw = _door_screw(cross_pose, g.tcp, action_points)
            scripts.append([*_approach(g, suction, scene_points), FreeJointStep(), screw,
                            *_retreat(screw.poses(1.0), g.approach)])
            continue
        pull = _door_screw(cross_pose, g.tcp, action_points, 0.0, handover)
        push = _door_screw(cross_pose, push_grip(g.tcp), action_points, handover, 1.0)
        start, end = push.poses(0.0), push.poses(1.0)
        before = start.copy()
        before[:3, 3] -= PREGRASP_DISTANCE * start[:3, 2]
        # The door where the pull left it, or up to PUSH_DOOR_LAG behind (the cup gives a little),
        # filled in between neighbouring points (a sparse cloud leaves gaps the hand could slip through).
        lag = min(handover, PUSH_DOOR_LAG / max(screw_of(cross_pose).angle, 1e-9))
        door_then = np.concatenate([_moved(action_points, M) for M in
                                    interpolate(cross_pose, np.linspace(handover - lag, handover, 4))])
        # The door comes to rest with the hand before the cup lets go (it would coast on, shut).
        scripts.append([*_approach(g, suction, scene_points), FreeJointStep(), pull, HoldStep(PULL_HOLD),
                        *_retreat(pull.poses(1.0), pull.poses(1.0)[:3, 2], PUSH_RETREAT),
                        Move(before, np.concatenate([anchor_points, _densified(door_then)])),
                        _line(before, start, check_stall=False),
                        push, *_retreat(end, end[:3, 2])])
    # The base keeps clear of the door's predicted sweep too.
    swept = np.concatenate([_moved(action_points, T) for T in interpolate(cross_pose, np.linspace(0, 1, 7))])
    plan, failed = _plan(scene, scripts, anchor_points, np.concatenate([anchor_points, swept]), grasp.tcp[:3, 3], extra)
    return plan, failed, extra




def _densified(points: np.ndarray, neighbours: int = 6) -> np.ndarray:
    """The cloud (N, 3) plus the midpoints between each point and its nearest neighbours
    (those within twice the median nearest-neighbour distance)."""
    from scipy.spatial import cKDTree

    d, idx = cKDTree(points).query(points, k=neighbours + 1)
    near = d[:, 1:] <= 2.0 * np.median(d[:, 1])
    a = np.repeat(np.arange(len(points)), neighbours).reshape(-1, neighbours)[near]
    b = idx[:, 1:][near]
    return np.concatenate([points, (points[a] + points[b]) / 2])


def _moved(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    return points @ T[:3, :3].T + T[:3, 3]


def _turn_script(object_points: np.ndarray, anchor: np.ndarray, turn: float, roll: float) -> list:
    """Pick the object by the middle of its top, turn it by ``turn`` about the vertical, put it down, let go."""
    from scipy.spatial.transform import Rotation

    top = _rolled_grasp(top_suction_point(object_points), roll)
    lifted = top.tcp.copy()
    lifted[2, 3] += REGRASP_LIFT
    turned = lifted.copy()
    turned[:3, :3] = Rotation.from_rotvec([0.0, 0.0, turn]).as_matrix() @ lifted[:3, :3]
    down = turned.copy()
    down[2, 3] = top.tcp[2, 3]
    return [*_approach(top, True, np.concatenate([anchor, object_points]), slow=True),
            _line(top.tcp, lifted), _line(lifted, turned), _line(turned, down), *_retreat(down, top.approach)]


def _side_scripts(plan, object_points: np.ndarray, anchor_points: np.ndarray,
                  press: float = SUCTION_PRESS, slow: bool = False, short: bool = False) -> tuple[list[list], dict]:
    """The side-entry plan as scripts (one per TCP roll; the cup ``press`` past the face, slowly
    with ``slow``; the slide may end up to SLIDE_SHORT early with ``short``), and what the stage
    result records of it."""
    from wpbench.sim.side_entry import _turn_about_vertical, regrasp_centre

    waypoints = plan.carry_waypoints()
    extra = {"grasp_point": plan.pick[:3, 3].round(4).tolist(), "grasp_approach": plan.pick[:3, 2].round(4).tolist(),
             "grasp_width": 0.0, "entry": "side",
             "regrasp_turn_deg": float(np.degrees(plan.regrasp_turn)),
             "planned_path": [w[:3, 3].round(4).tolist() for w in waypoints]}
    points_now = object_points
    if plan.regrasp_turn:
        points_now = _moved(object_points, _turn_about_vertical(plan.regrasp_turn, regrasp_centre(object_points)))
    scripts = []
    for roll in SYMMETRIC_ROLLS:   # the palm box side entry checked is symmetric under these
        script = _turn_script(object_points, anchor_points, plan.regrasp_turn, roll) if plan.regrasp_turn else []
        script = _holding(script, object_points)
        pick = Grasp(_rolled(plan.pick, roll), plan.pick[:3, 2].copy(), 0.0)
        way = [_rolled(w, roll) for w in waypoints]
        script += _holding(_approach(pick, True, np.concatenate([anchor_points, points_now]), press, slow), points_now)
        script += [_line(a, b) for a, b in zip(way[:-1], way[1:])]
        # The last piece lowers the object onto its goal after the slide (into a cavity whose floor
        # lies below its sill): where the wrist, still over the sill, stops it, the object is let go higher.
        script[-1].release_early = RELEASE_DROP
        # The slide before it, when allowed: where the forearm meets the furniture near its end, the
        # object is let go there, nearer the opening than predicted; the goal region still decides.
        script[-2].release_early = SLIDE_SHORT if short else 0.0
        script[-2].release_early_fallback = SLIDE_SHORT
        script += _retreat(way[-1], plan.goal[:3, 2], plan.retreat())
        scripts.append(script)
    return scripts, extra


def _top_scripts(object_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray,
                 suction: bool) -> tuple[list[list] | None, tuple[float, ...], dict, str]:
    """Pick from above, carry over the goal at a height that clears the observed anchor, lower,
    let go: (scripts, their TCP rolls, what the result records, why not when scripts is None)."""
    grasp = top_suction_point(object_points) if suction else top_grasp(object_points)
    if grasp is None:
        return None, (), {"grasp_point": None}, "the object is wider than the fingers open"
    start = grasp.tcp
    goal = cross_pose @ start
    rise = carry_height(object_points, anchor_points, start[:3, 3], goal[:3, 3])
    if rise is None:
        return None, (), {"grasp_point": None}, "no carry height clears the observed furniture"
    lifted = start.copy()
    above_goal = goal.copy()
    travel_z = max(start[2, 3] + LIFT_HEIGHT, goal[2, 3] + max(CARRY_CLEARANCE, rise))
    lifted[2, 3] = travel_z
    above_goal[2, 3] = travel_z
    waypoints = [start, lifted, above_goal, goal]
    extra = {"grasp_point": start[:3, 3].round(4).tolist(), "grasp_approach": grasp.approach.round(4).tolist(),
             "grasp_width": grasp.width, "entry": "top",
             "planned_path": [w[:3, 3].round(4).tolist() for w in waypoints]}
    if _below_floor(np.stack(waypoints)):
        return None, (), extra, "the path goes under the floor"
    # A suction cup from above may turn any way about the vertical; fingers only by half a turn.
    rolls = TOP_SUCTION_ROLLS if suction else SYMMETRIC_ROLLS
    scripts = []
    for roll in rolls:
        g = _rolled_grasp(grasp, roll)
        way = [_rolled(w, roll) for w in waypoints]
        scripts.append(_holding([*_approach(g, suction, np.concatenate([anchor_points, object_points]), slow=suction),
                                 *[_line(a, b) for a, b in zip(way[:-1], way[1:])], *_retreat(way[-1], g.approach)],
                                object_points))
    return scripts, rolls, extra, ""


def relay_poses(object_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray,
                side) -> list[np.ndarray]:
    """Where the object may be set down first (motions (4, 4) of the object on the floor it
    stands on), in the order tried: in front of the cavity's opening (``side``, the side-entry
    plan of the direct path, says which way it looks and how far the slide is), further out or
    to either side, turned about the vertical as the goal turns it (so the face the cup holds
    at the goal looks out of the opening), with no observed anchor point over the object's
    footprint widened by RELAY_MARGIN. Pure numpy."""
    obj = np.asarray(object_points, dtype=np.float64)
    anchor = np.asarray(anchor_points, dtype=np.float64)
    T = np.asarray(cross_pose, dtype=np.float64)
    centre = np.array([*(obj[:, :2].min(0) + obj[:, :2].max(0)) / 2, 0.0])
    yaw = float(np.arctan2(T[1, 0], T[0, 0]))
    R = np.eye(4)
    R[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    turned = _moved(obj - centre, R)
    radius = float(np.linalg.norm(turned[:, :2], axis=1).max()) + RELAY_MARGIN
    goal_points = _moved(obj, T)
    goal_centre = (goal_points[:, :2].min(0) + goal_points[:, :2].max(0)) / 2
    out = np.asarray(side.direction, dtype=np.float64)[:2]
    lateral = np.array([-out[1], out[0]])
    reach = side.staging_distance + float(np.abs(turned[:, :2] @ out).max()) + RELAY_MARGIN
    poses = []
    for lead in RELAY_LEADS:
        for offset in RELAY_OFFSETS:
            xy = goal_centre + (reach + lead) * out + offset * lateral
            if np.any(np.linalg.norm(anchor[:, :2] - xy, axis=1) < radius):
                continue
            M = R.copy()
            M[:2, 3] = xy - R[:2, :2] @ centre[:2]
            poses.append(M)
    return poses


def ledge_relay_poses(object_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray,
                      side) -> list[np.ndarray]:
    """Relay spots on an observed flat surface straight in front of the opening (an oven's or a
    dishwasher's open door lying in front of its cavity): motions (4, 4) of the object, turned as
    the goal turns it, further out than the slide needs by LEDGE_LEADS, kept where the observed
    anchor points under the object's footprint within SUPPORT_FLAT of the highest of them (at
    least MIN_SUPPORT_POINTS, none lower than MIN_SUPPORT_HEIGHT), together with those at that
    height within RELAY_MARGIN of the footprint, span SUPPORT_SPAN of the footprint in both
    horizontal directions (those under it half as much), and no anchor point stands above them within RELAY_MARGIN of the footprint. The object is set down SUPPORT_GAP
    above the highest of them. Pure numpy."""
    from scipy.spatial import Delaunay, QhullError

    obj = np.asarray(object_points, dtype=np.float64)
    anchor = np.asarray(anchor_points, dtype=np.float64)
    T = np.asarray(cross_pose, dtype=np.float64)
    centre = np.array([*(obj[:, :2].min(0) + obj[:, :2].max(0)) / 2, obj[:, 2].min()])
    yaw = float(np.arctan2(T[1, 0], T[0, 0]))
    R = np.eye(4)
    R[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    turned = _moved(obj - centre, R)[:, :2]
    ring = RELAY_MARGIN * np.array([[np.cos(a), np.sin(a)] for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)])
    grown = (turned[:, None, :] + ring[None]).reshape(-1, 2)
    try:
        inside_foot, inside_grown = Delaunay(turned), Delaunay(grown)
    except QhullError:
        return []
    goal_points = _moved(obj, T)
    goal_centre = (goal_points[:, :2].min(0) + goal_points[:, :2].max(0)) / 2
    out = np.asarray(side.direction, dtype=np.float64)[:2]
    reach = side.staging_distance
    poses = []
    for lead in LEDGE_LEADS:
        xy = goal_centre + (reach + lead) * out
        local = anchor[:, :2] - xy
        near = inside_grown.find_simplex(local) >= 0
        under = near & (inside_foot.find_simplex(local) >= 0)
        if not under.any():
            continue
        # The surface is the top layer under the footprint (a door's underside may be observed too);
        # it must span most of the footprint in both directions.
        level = anchor[:, 2] >= anchor[under, 2].max() - SUPPORT_FLAT
        top = under & level
        z = anchor[top, 2]
        if top.sum() < MIN_SUPPORT_POINTS or z.min() < MIN_SUPPORT_HEIGHT:
            continue
        # The surface at that height spans the footprint (a sparse cloud: counted out to RELAY_MARGIN around it).
        axes = np.stack([out, [-out[1], out[0]]])
        if np.any(np.ptp(local[near & level] @ axes.T, axis=0) < SUPPORT_SPAN * np.ptp(turned @ axes.T, axis=0)):
            continue
        if np.any(np.ptp(local[top] @ axes.T, axis=0) < SUPPORT_SPAN / 2 * np.ptp(turned @ axes.T, axis=0)):
            continue
        if np.any(anchor[near, 2] > z.max() + SUPPORT_FLAT):
            continue
        M = R.copy()
        M[:2, 3] = xy - R[:2, :2] @ centre[:2]
        M[2, 3] = z.max() + SUPPORT_GAP - centre[2]
        poses.append(M)
    return poses


def _without_support(anchor_points: np.ndarray, object_points: np.ndarray) -> np.ndarray:
    """The anchor cloud without the surface the object stands on: its points within SUPPORT_REACH
    of the object's footprint (the hand comes in from beside it) no higher than SUPPORT_FLAT above
    the object's bottom."""
    from scipy.spatial import Delaunay, QhullError

    ring = SUPPORT_REACH * np.array([[np.cos(a), np.sin(a)] for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)])
    grown = (object_points[:, None, :2] + ring[None]).reshape(-1, 2)
    try:
        inside = Delaunay(grown).find_simplex(anchor_points[:, :2]) >= 0
    except QhullError:
        return anchor_points
    keep = ~(inside & (anchor_points[:, 2] <= object_points[:, 2].min() + SUPPORT_FLAT))
    return anchor_points[keep] if keep.any() else anchor_points


def _support_floor(anchor_points: np.ndarray, around: np.ndarray) -> np.ndarray:
    """The points of ``anchor_points`` that :func:`_without_support` left out of ``around`` (the
    surface a relayed object stands on), filled in between neighbours and lowered by
    MOVE_CLEARANCE - FLOOR_GAP: an obstacle a free-space move keeps the palm FLOOR_GAP above
    (the side entry's own gap above the surface)."""
    if len(around) == len(anchor_points):
        return np.empty((0, 3))
    rows = {tuple(p) for p in np.round(around, 6)}
    surface = anchor_points[[tuple(p) not in rows for p in np.round(anchor_points, 6)]]
    if len(surface) > 7:
        surface = _densified(surface)
    return surface - [0.0, 0.0, MOVE_CLEARANCE - FLOOR_GAP]


def _entries(object_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray,
             viewpoint: np.ndarray | None, relayed: bool, short: bool = False) -> list:
    """The ways into a roofed cavity: [(plan, scripts, rolls, extra)] for the cup on the side face
    that looks out at the goal (wpbench.sim.side_entry), their slides let go short with ``short``;
    empty when there is none."""
    out = []
    side = plan_side_entry(object_points, anchor_points, cross_pose, viewpoint)
    if side is not None and not _below_floor(np.stack(side.carry_waypoints())):
        # A relayed object stands where the arm set it down, give or take a centimetre: the cup
        # presses further then.
        press = SUCTION_PRESS + (RELAY_PRESS if relayed else 0.0)
        # The cup near the face's top edge first: the wrist, level with the cup, stays higher above
        # the floor (or the surface) the object stands on.
        for plan in (_raised_cup(side, object_points, anchor_points, cross_pose), side):
            if plan is not None:
                scripts, extra = _side_scripts(plan, object_points, anchor_points, press, slow=True, short=short)
                extra["cup_raised_m"] = round(float(plan.goal[2, 3] - side.goal[2, 3]), 4)
                out.append((plan, scripts, SYMMETRIC_ROLLS, extra))
    return out


def _raised_cup(side, object_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray):
    """The side-entry plan with the cup moved up its face to CUP_EDGE below the object's top (the
    goal upright, no turn before the pick), when the hand and the held object still clear the
    observed anchor along the carry and the slide, and the hand still comes in clear at the pick
    (the side-entry planner's own tests); None otherwise."""
    from dataclasses import replace

    from wpbench.sim.side_entry import (CUP_EDGE, _pick_reachable, hand_box, held_box, path_poses, poses_hit,
                                        surface_clearance)

    if side.regrasp_turn or side.goal[2, 0] < 0.99:
        return None
    goal_points = _moved(object_points, cross_pose)
    rise = float(goal_points[:, 2].max()) - CUP_EDGE - float(side.goal[2, 3])
    if rise < MIN_CUP_RAISE:
        return None
    goal = side.goal.copy()
    goal[2, 3] += rise
    plan = replace(side, pick=np.linalg.inv(cross_pose) @ goal, goal=goal)
    clearance = surface_clearance(anchor_points)
    boxes = [held_box(goal_points, goal), hand_box()]
    if poses_hit(anchor_points, path_poses(plan.carry_waypoints()[1:-1]), boxes, clearance):
        return None
    if not _pick_reachable(anchor_points, plan.pick, float(object_points[:, 2].min()), clearance):
        return None
    return plan


def _roofed_entry(scene: ArmScene, object_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray,
                  viewpoint: np.ndarray | None, goal_change: dict) -> ExecutionResult | None:
    """Into a roofed cavity from where the object stands (see :func:`_roofed_attempt`): first with
    every slide carried to its end; when nothing plans and some arm gave out within SLIDE_SHORT of
    a slide's end, again with slides that may be let go that early, so an episode that plans in
    full is carried out as it would be without them. When neither plans, the first attempt's
    failure. None when no way in is found before planning."""
    outcome = _roofed_attempt(scene, object_points, anchor_points, cross_pose, viewpoint, goal_change, short=False)
    if not isinstance(outcome, tuple):
        return outcome
    if not outcome[1].get("slide_failed_near_end"):
        # The second pass would meet every failure of the first where it met it.
        return _finish(None, *outcome)
    again = _roofed_attempt(scene, object_points, anchor_points, cross_pose, viewpoint, goal_change, short=True)
    if isinstance(again, ExecutionResult):
        again.details["slide_let_go_short"] = True
        return again
    return _finish(None, *outcome)


def _roofed_attempt(scene: ArmScene, object_points: np.ndarray, anchor_points: np.ndarray, cross_pose: np.ndarray,
                    viewpoint: np.ndarray | None, goal_change: dict,
                    short: bool) -> ExecutionResult | tuple[ExecutionResult, dict] | None:
    """Into a roofed cavity from where the object stands; when no base placement reaches both the
    pick and the goal, a relay: the object is first carried from above and set down in front of
    the opening (one base), then put in from there (another base: the robot's base moves only
    while it holds nothing). Slides may end early with ``short``. The result of what was carried
    out; (the failure, what the result records) when nothing planned; None when no way in is
    found before planning."""
    goal_points = _moved(object_points, cross_pose)
    entries = _entries(object_points, anchor_points, cross_pose, viewpoint, relayed=False, short=short)
    if not entries:
        return None
    extra = dict(entries[0][3])
    extra.update(goal_change)
    failed = None
    obstacles = np.concatenate([anchor_points, object_points, goal_points])
    for plan, scripts, rolls, info in entries:
        direct, why = _plan(scene, scripts, anchor_points, obstacles, plan.pick[:3, 3], extra)
        failed = failed or why
        if direct is not None:
            info.update(goal_change)
            info["placements_tried"] = extra["placements_tried"]
            return _carry_out(scene, direct, rolls, info, COLLISION)
    suction = scene.grasp_mode == "suction"
    tries = []
    # Spots on the furniture's own flat surface in front of the opening first (short to slide in
    # from, the side pick higher above the floor), then on the floor.
    spots = (ledge_relay_poses(object_points, anchor_points, cross_pose, entries[0][0])[:MAX_LEDGE_RELAYS]
             + relay_poses(object_points, anchor_points, cross_pose, entries[0][0])[:MAX_RELAYS])
    for M in spots:
        relayed = _moved(object_points, M)
        then = cross_pose @ np.linalg.inv(M)
        # For the hand's path, the surface the object stands on is the side pick's floor (the palm keeps
        # above it), not an obstacle; the arm's links keep clear of it.
        around = _without_support(anchor_points, relayed)
        # The free-space moves keep the palm's height above that surface: its points, filled in
        # and lowered so that the moves' clearance leaves the palm's gap above them.
        floor = _support_floor(anchor_points, around)
        found = False
        for plan, scripts2, rolls2, extra2 in _entries(relayed, around, then, viewpoint, relayed=True, short=short):
            found = True
            for script in scripts2:
                for step in script:
                    if isinstance(step, Move):
                        step.obstacles = np.concatenate([step.obstacles, floor])
            second, why2 = _plan(scene, scripts2, anchor_points, np.concatenate([anchor_points, relayed, goal_points]),
                                 plan.pick[:3, 3], extra)
            if second is None:
                tries.append(f"into the cavity: {why2.reason}: {why2.detail}")
                continue
            scripts1, rolls1, extra1, why1 = _top_scripts(object_points, anchor_points, M, suction)
            if scripts1 is None:
                tries.append(f"setting down: {why1}")
                break
            first, why1 = _plan(scene, scripts1, anchor_points, np.concatenate([anchor_points, object_points, relayed]),
                                extra1["grasp_point"], extra)
            if first is None:
                tries.append(f"setting down: {why1.reason}: {why1.detail}")
                break
            tried = extra["placements_tried"]
            relay = _carry_out(scene, first, rolls1, extra1, COLLISION)
            centre = (relayed.min(0) + relayed.max(0)) / 2
            extra2.update(goal_change)
            extra2.update({"placements_tried": tried, "relay_point": centre.round(4).tolist(),
                           "relay_turn_deg": float(np.degrees(np.arctan2(M[1, 0], M[0, 0]))),
                           "relay_base": extra1.get("arm_base"), "relay_grasp_point": extra1.get("grasp_point")})
            if relay.reason or not relay.ok:
                relay.details.update({k: v for k, v in extra2.items() if k.startswith("relay") or k in goal_change})
                relay.details["placements_tried"] = tried
                relay.detail = f"while setting the object down in front of the opening: {relay.detail}"
                return relay
            result = _carry_out(scene, second, rolls2, extra2, COLLISION)
            result.sim_seconds += relay.sim_seconds
            return result
        if not found:
            tries.append("into the cavity: no side entry from there")
    extra["relay_spots"] = len(spots)
    extra["relay_failures"] = tries
    return failed, extra


def execute_free_panda(scene: ArmScene, object_points: np.ndarray, anchor_points: np.ndarray,
                       cross_pose: np.ndarray, viewpoint: np.ndarray | None = None) -> ExecutionResult:
    """Put the object at the predicted goal along the gripper's path (side entry under a
    roof, else from above), carried by the arm. The goal is the one a hand can reach, as for
    the gripper (wpbench.sim.place_goal): a tumble of a box-symmetric object becomes its
    upright equivalent, a goal sunk a little into the observed surface under it is put down on it."""
    suction = scene.grasp_mode == "suction"
    upright = upright_equivalent(object_points, cross_pose)
    goal_change = {"goal_turned_deg": round(float(np.degrees(_pose_distance(np.asarray(cross_pose), upright)[1])), 2)}
    cross_pose = rest_on_support(object_points, anchor_points, upright)
    goal_change["goal_raised_m"] = round(float(cross_pose[2, 3] - upright[2, 3]), 4)
    if suction and is_roofed(object_points, anchor_points, cross_pose):
        result = _roofed_entry(scene, object_points, anchor_points, cross_pose, viewpoint, goal_change)
        if result is not None:
            return result
    goal_points = _moved(object_points, cross_pose)
    obstacles = np.concatenate([anchor_points, object_points, goal_points])
    scripts, rolls, extra, why = _top_scripts(object_points, anchor_points, cross_pose, suction)
    extra.update(goal_change)
    if scripts is None:
        reason = UNREACHABLE if why.endswith("floor") else PLANNING_FAILED
        return _finish(None, ExecutionResult(ok=False, reason=reason, detail=why), extra)
    return _run(scene, scripts, rolls, anchor_points, obstacles, np.asarray(extra["grasp_point"]), extra, COLLISION)
