"""The ``gripper`` executor: a floating Panda hand carries out the predicted cross-pose.

It sees what a policy sees (the stage's observed clouds) and the predicted cross-pose,
nothing else. Physics decides the outcome:

- Articulated: grasp the moving part where the predicted motion is largest
  (wpbench.sim.grasp_choice), close the fingers (friction) or seal the cup after a
  guarded approach that stops where the hand touches (suction), move the hand along the
  screw path from the identity to T (an arc about the predicted hinge, a line for a
  slide) with bounded force and speed, hand the joint to its spring, release, retreat,
  and let the scene settle. The joint is free while the hand moves it; a wrong axis
  pulls against the hinge and the hand stalls or the part slips out of the fingers.
- Free-floating: the goal is the predicted one, turned upright when it tumbles a
  box-symmetric object and put down on the observed surface when it sinks a little into
  it (wpbench.sim.place_goal). Under a roof, suction from the side through the opening
  (wpbench.sim.side_entry); otherwise grasp the object from above, lift it, carry it at
  the lowest height above the goal that clears the observed anchor cloud to above the
  goal, lower it to the goal, release, retreat and settle. The furniture collides with
  hand and object all the way.

When the hand misses, stalls, slips or collides it stops, lets go, and the scene is
scored as it is (``ok`` stays True, ``reason`` says what went wrong and becomes the
stage's failure_reason if the stage fails). Only a blow-up is not executed. Nothing raises.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from wpbench.sim.executor import ExecutionResult, blown_up, simulate_until_still
from wpbench.sim.failure import (BLOW_UP, COLLISION, GRASP_MISSED, PLANNING_FAILED, SLIPPED, STALLED_AGAINST_HINGE,
                                 UNREACHABLE)
from wpbench.sim.grasp_choice import (Grasp, articulated_grasp, carry_height, clear_suction_point, suction_point, top_grasp,
                                      top_suction_point)
from wpbench.sim.gripper import FINGER_OPEN, FloatingGripper
from wpbench.sim.place_goal import rest_on_support, upright_equivalent
from wpbench.sim.screw_path import interpolate, path_length
from wpbench.sim.side_entry import SidePlan, is_roofed, plan_side_entry

MAX_SPEED = 0.3              # m/s, TCP
MAX_ANGULAR_SPEED = 1.2      # rad/s, TCP
MIN_SEGMENT_SECONDS = 0.15
PREGRASP_DISTANCE = 0.10     # m, the hand starts this far back along the approach
CLOSE_SECONDS = 0.3          # fingers closing
RELEASE_SECONDS = 0.2        # fingers opening
HOLD_SECONDS = 0.1           # pause at the end of a path before releasing
RETREAT_DISTANCE = 0.06      # m, back off along the approach after releasing
HELD_OPENING = 0.003         # m: closed fingers further apart than this hold something ...
BLOCKED_OPENING = 2 * FINGER_OPEN - 0.005  # m: ... unless they could not close at all (pads on a flat face)
STALL_DISTANCE = 0.05        # m: the TCP this far behind its target has been stopped
STALL_ANGLE = 0.35           # rad: ... or turned this far from it
SUCTION_PRESS = 0.006       # m: the cup is pushed this far past the surface to seal
SUCTION_SLIP = 0.02          # m: the cup stretched this far has let go
GUARD_START = 0.02           # m: a guarded approach slows down this far short of the observed surface ...
GUARD_DEPTH = 0.05           # m: ... and creeps on at most this far past it
GUARD_SPEED = 0.05           # m/s
CUP_REACH = 0.04             # m: a guarded approach stops on a touch this close to the TCP (the cup), not on the palm's
GRASPS = ("friction", "suction")
LIFT_HEIGHT = 0.05           # m, lift above the start before carrying
CARRY_CLEARANCE = 0.03       # m, carry this far above the predicted goal, then lower
FLOOR_Z = 0.0                # the floor the robot and the furniture stand on: the hand cannot go below it
REGRASP_LIFT = 0.03          # m, an object turned in place is lifted this far off the floor


@dataclass
class Scene:
    """What the executor drives: the hand, one physics step, and the settle test of the action object."""

    gripper: FloatingGripper
    ms_scene: object                  # the ManiSkill scene (suction attaches with a drive in it)
    grasp_mode: str                   # one of GRASPS
    step: Callable[[], None]
    timestep: float
    velocities: Callable[[], list[np.ndarray]]   # of the action object (blow-up check, settling)
    is_still: Callable[[], bool]
    held_touches_furniture: Callable[[], bool] | None = None   # free objects: the held object is pressed against the furniture


class _Abort(Exception):
    def __init__(self, reason: str, detail: str = ""):
        super().__init__(detail)
        self.reason, self.detail = reason, detail


def _pose_distance(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    d = float(np.linalg.norm(a[:3, 3] - b[:3, 3]))
    ang = float(np.linalg.norm(Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).as_rotvec()))
    return d, ang


def _segment_seconds(a: np.ndarray, b: np.ndarray, length: float | None = None) -> float:
    d, ang = _pose_distance(a, b)
    return max(MIN_SEGMENT_SECONDS, (length if length is not None else d) / MAX_SPEED, ang / MAX_ANGULAR_SPEED)


def _smooth(u: float) -> float:
    """Minimum-jerk time scaling, 0 -> 1 with zero speed at both ends."""
    return u**3 * (10 - 15 * u + 6 * u**2)


class _Runner:
    def __init__(self, scene: Scene, stall_reason: str, slip_check: bool):
        self.s = scene
        self.seconds = 0.0
        self.stall_reason = stall_reason
        self.holding = False
        self.slip_check = slip_check
        self.executed: list[np.ndarray] = []     # TCP positions, one per physics step

    def tick(self) -> None:
        self.s.step()
        self.seconds += self.s.timestep
        self.executed.append(self.s.gripper.tcp_pose()[:3, 3])
        detail = blown_up(self.s.velocities() + self.s.gripper.velocities())
        if detail:
            raise _Abort(BLOW_UP, detail)

    def wait(self, seconds: float) -> None:
        for _ in range(int(round(seconds / self.s.timestep))):
            self.tick()

    def follow(self, poses: Callable[[float], np.ndarray], seconds: float, check_stall: bool = True) -> None:
        """Drive the TCP target along ``poses(u)``, u in [0, 1], over ``seconds``."""
        n = max(1, int(round(seconds / self.s.timestep)))
        for k in range(1, n + 1):
            target = poses(_smooth(k / n))
            self.s.gripper.set_target(target)
            self.tick()
            if self.holding and self.slip_check and self._slipped():
                touching = self.s.held_touches_furniture
                if touching is not None and touching():
                    raise _Abort(COLLISION, "the furniture stopped the held object and pulled it off the gripper")
                raise _Abort(SLIPPED, "the object left the gripper while moving")
            if check_stall:
                d, ang = _pose_distance(self.s.gripper.tcp_pose(), target)
                if d > STALL_DISTANCE or ang > STALL_ANGLE:
                    raise _Abort(self.stall_reason, f"hand {d * 100:.1f} cm / {np.degrees(ang):.0f} deg behind its target")

    def line(self, a: np.ndarray, b: np.ndarray, check_stall: bool = True) -> None:
        """Straight line and slerp from pose a to pose b."""
        rots = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([a[:3, :3], b[:3, :3]])))

        def pose(u: float) -> np.ndarray:
            T = np.eye(4)
            T[:3, :3] = rots(u).as_matrix()
            T[:3, 3] = (1 - u) * a[:3, 3] + u * b[:3, 3]
            return T

        self.follow(pose, _segment_seconds(a, b), check_stall)

    def _slipped(self) -> bool:
        g = self.s.gripper
        if self.s.grasp_mode == "suction":
            if g.suction_stretch() > SUCTION_SLIP:
                g.detach()
                return True
            return False
        return g.opening < HELD_OPENING

    def grasp(self, grasp: Grasp, guarded: bool = False) -> np.ndarray:
        """Take hold at ``grasp``; returns the TCP pose the hand holds at (``grasp.tcp``
        unless a guarded suction approach touched the surface elsewhere along the approach)."""
        if self.s.grasp_mode == "suction":
            return self._suction_grasp(grasp, guarded)
        g = self.s.gripper
        pre = grasp.tcp.copy()
        pre[:3, 3] -= PREGRASP_DISTANCE * grasp.approach
        g.teleport(pre)
        self.line(pre, grasp.tcp, check_stall=False)
        g.set_fingers(-0.02)
        self.wait(CLOSE_SECONDS)
        if g.opening < HELD_OPENING:
            raise _Abort(GRASP_MISSED, "the fingers closed on nothing")
        if g.opening > BLOCKED_OPENING:
            raise _Abort(GRASP_MISSED, "the fingers could not close (nothing to pinch)")
        self.holding = True
        return grasp.tcp

    def _suction_grasp(self, grasp: Grasp, guarded: bool = False) -> np.ndarray:
        """Seal the cup on the surface at ``grasp``; returns the TCP pose it holds at. With
        ``guarded``, the hand comes in at MAX_SPEED to GUARD_START short of the observed
        surface, then creeps on at GUARD_SPEED until the cup touches something (a contact
        within CUP_REACH of the TCP; at most GUARD_DEPTH past the surface) and presses
        SUCTION_PRESS from there (at the observed surface when the cup touched nothing): a
        camera's cloud may not show the face the cup meets where it is, and a door is not
        pushed shut by a hand that expected it further in. The cup seals on the body it
        touches (any body the hand touches when the cup touched nothing)."""
        g = self.s.gripper
        a = grasp.approach
        pre = grasp.tcp.copy()
        pre[:3, 3] -= PREGRASP_DISTANCE * a
        g.teleport(pre, opening=0.0)
        held, touched = grasp.tcp, None
        if guarded:
            near = grasp.tcp.copy()
            near[:3, 3] -= GUARD_START * a
            touched = self._creep(pre, PREGRASP_DISTANCE - GUARD_START, a, MAX_SPEED)
            if touched is None:
                touched = self._creep(near, GUARD_START + GUARD_DEPTH, a, GUARD_SPEED)
            # The cup met nothing on the way (the palm, stopped by something else, kept it
            # off): press at the observed surface, as an unguarded approach does.
            held = grasp.tcp if touched is None else touched
        press = held.copy()
        press[:3, 3] += SUCTION_PRESS * a
        self.line(g.tcp_pose() if guarded else pre, press, check_stall=False)
        self.wait(HOLD_SECONDS)
        contacts = self.s.ms_scene.px.get_contacts()
        body = g.touched_body(contacts, near=CUP_REACH) if touched is not None else None
        if body is None:
            body = g.touched_body(contacts)
        if body is None:
            raise _Abort(GRASP_MISSED, "the suction cup touched nothing")
        g.attach(self.s.ms_scene, body)
        self.holding = True
        return held

    def _creep(self, start: np.ndarray, depth: float, approach: np.ndarray, speed: float) -> np.ndarray | None:
        """Move the TCP target from ``start`` along ``approach`` at ``speed``, at most ``depth``;
        the TCP pose (``start``'s orientation, the reached position) at the first touch, or None."""
        g = self.s.gripper
        per_step = speed * self.s.timestep
        for k in range(1, int(np.ceil(depth / per_step)) + 1):
            target = start.copy()
            target[:3, 3] += min(k * per_step, depth) * approach
            g.set_target(target)
            self.tick()
            if g.touched_body(self.s.ms_scene.px.get_contacts(), near=CUP_REACH) is not None:
                reached = start.copy()
                reached[:3, 3] += float((g.tcp_pose()[:3, 3] - start[:3, 3]) @ approach) * approach
                return reached
        return None

    def release(self, approach: np.ndarray, retreat_to: np.ndarray | None = None) -> None:
        """Let go, back off RETREAT_DISTANCE against ``approach`` (or to the TCP pose
        ``retreat_to``) and park the hand."""
        g = self.s.gripper
        self.holding = False
        g.detach()
        self.wait(HOLD_SECONDS)
        g.set_fingers(2 * FINGER_OPEN)
        self.wait(RELEASE_SECONDS)
        now = g.tcp_pose()
        back = now.copy()
        if retreat_to is None:
            back[:3, 3] -= RETREAT_DISTANCE * approach
        else:
            back[:3, 3] = retreat_to[:3, 3]
        self.line(now, back, check_stall=False)
        g.park()


def _below_floor(poses: np.ndarray) -> bool:
    """True when a TCP pose (K, 4, 4) of a path lies under the floor."""
    return bool(np.any(np.asarray(poses).reshape(-1, 4, 4)[:, 2, 3] < FLOOR_Z))


def _unreachable(run: "_Runner", extra: dict) -> ExecutionResult:
    return _finish(run, ExecutionResult(ok=False, reason=UNREACHABLE, detail="the path goes under the floor"), extra)


def _finish(run: _Runner, result: ExecutionResult, extra: dict) -> ExecutionResult:
    result.sim_seconds += run.seconds
    result.details.update(extra)
    result.details["executed_path"] = np.asarray(run.executed[::10]).round(4).tolist()
    return result


def _settle(scene: Scene) -> ExecutionResult:
    return simulate_until_still(scene.step, scene.timestep, scene.velocities, scene.is_still)


def execute_articulated_gripper(scene: Scene, action_points: np.ndarray, cross_pose: np.ndarray,
                                free_joint: Callable[[], None], hold_joint: Callable[[], None]) -> ExecutionResult:
    """Grasp the door or drawer, move it along the predicted screw, release, settle."""
    run = _Runner(scene, STALLED_AGAINST_HINGE, slip_check=True)
    clear = False
    if scene.grasp_mode == "suction":
        # The cup clear of a handle (the closed fingers would strike it); when that moves
        # the grasp to where the path goes under the floor, the plain face choice.
        grasp, clear = clear_suction_point(action_points, cross_pose)
        if clear and _below_floor(interpolate(cross_pose, np.linspace(0, 1, 11)) @ grasp.tcp):
            grasp, clear = suction_point(action_points, cross_pose), False
    else:
        grasp = articulated_grasp(action_points, cross_pose)
    if grasp is None:   # the prediction moves nothing: the hand has nothing to do
        return _finish(run, _settle(scene), {"grasp_point": None})
    extra = {"grasp_point": grasp.tcp[:3, 3].round(4).tolist(), "grasp_approach": grasp.approach.round(4).tolist(),
             "grasp_width": grasp.width, "grasp_clear_of_handle": clear}
    path = interpolate(cross_pose, np.linspace(0, 1, 11)) @ grasp.tcp
    extra["planned_path"] = path[:, :3, 3].round(4).tolist()
    if _below_floor(path):
        return _unreachable(run, extra)
    try:
        held = run.grasp(grasp, guarded=True)
        extra["held_point"] = held[:3, 3].round(4).tolist()
        free_joint()   # held by the hand from now on (until then the joint keeps its place)
        seconds = _segment_seconds(np.eye(4), cross_pose, path_length(cross_pose, held[:3, 3]))
        run.follow(lambda u: interpolate(cross_pose, u) @ held, seconds)
        hold_joint()   # the joint keeps where the hand has brought it, before the hand lets go
        run.release((cross_pose @ held)[:3, 2])   # back off along the approach as the door now stands
    except _Abort as abort:
        scene.gripper.detach()
        scene.gripper.set_fingers(2 * FINGER_OPEN)
        run.wait(RELEASE_SECONDS) if abort.reason != BLOW_UP else None
        scene.gripper.park()
        hold_joint()
        settled = _settle(scene) if abort.reason != BLOW_UP else ExecutionResult(ok=False)
        # A robot that stalled or slipped stops, lets go, and the scene is scored as it is.
        result = ExecutionResult(ok=abort.reason != BLOW_UP, reason=abort.reason, detail=str(abort.detail),
                                 sim_seconds=settled.sim_seconds, at_rest=settled.at_rest)
        return _finish(run, result, extra)
    return _finish(run, _settle(scene), extra)


def _abort_free(scene: Scene, run: _Runner, abort: _Abort, extra: dict) -> ExecutionResult:
    """The hand stops and lets go where it is; the scene is scored as it is."""
    scene.gripper.detach()
    scene.gripper.set_fingers(2 * FINGER_OPEN)
    scene.gripper.park()
    settled = _settle(scene) if abort.reason != BLOW_UP else ExecutionResult(ok=False)
    return _finish(run, ExecutionResult(ok=abort.reason != BLOW_UP, reason=abort.reason, detail=str(abort.detail),
                                        sim_seconds=settled.sim_seconds, at_rest=settled.at_rest), extra)


def _turn_in_place(run: _Runner, object_points: np.ndarray, turn: float) -> None:
    """Regrasp: pick the object by the middle of its top, turn it by ``turn`` (rad) about
    the vertical, put it down where it was and let go."""
    top = top_suction_point(object_points)
    run.grasp(top)
    lifted = top.tcp.copy()
    lifted[2, 3] += REGRASP_LIFT
    turned = lifted.copy()
    turned[:3, :3] = Rotation.from_rotvec([0.0, 0.0, turn]).as_matrix() @ lifted[:3, :3]
    down = turned.copy()
    down[2, 3] = top.tcp[2, 3]
    for a, b in ((top.tcp, lifted), (lifted, turned), (turned, down)):
        run.line(a, b)
    run.release(top.approach)


def execute_side_entry(scene: Scene, run: _Runner, object_points: np.ndarray, plan: SidePlan) -> ExecutionResult:
    """Carry out a side-entry plan (wpbench.sim.side_entry): turn the object first when the
    plan says so, hold it by the face that looks out of the cavity, carry it to the staging
    pose, slide it in, lower it, let go, back out the way it came, settle."""
    waypoints = plan.carry_waypoints()
    extra = {"grasp_point": plan.pick[:3, 3].round(4).tolist(), "grasp_approach": plan.pick[:3, 2].round(4).tolist(),
             "grasp_width": 0.0, "entry": "side",
             "regrasp_turn_deg": float(np.degrees(plan.regrasp_turn)),
             "planned_path": [w[:3, 3].round(4).tolist() for w in waypoints]}
    if _below_floor(np.stack(waypoints)):
        return _unreachable(run, extra)
    try:
        if plan.regrasp_turn:
            _turn_in_place(run, object_points, plan.regrasp_turn)
        run.grasp(Grasp(plan.pick, plan.pick[:3, 2].copy(), 0.0))
        for a, b in zip(waypoints[:-1], waypoints[1:]):
            run.line(a, b)
        run.release(plan.goal[:3, 2], retreat_to=plan.retreat())
    except _Abort as abort:
        return _abort_free(scene, run, abort, extra)
    return _finish(run, _settle(scene), extra)


def _with(result: ExecutionResult, details: dict) -> ExecutionResult:
    result.details.update(details)
    return result


def execute_free_gripper(scene: Scene, object_points: np.ndarray, anchor_points: np.ndarray,
                         cross_pose: np.ndarray, viewpoint: np.ndarray | None = None) -> ExecutionResult:
    """Put the object at the predicted goal. Suction, when the observed anchor roofs the
    goal: from the side through the cavity's opening (wpbench.sim.side_entry), if the
    observed anchor leaves a way in; otherwise from above. From above: pick the object by
    its top, carry it over the predicted goal, lower it there, release, settle. A path
    under the floor is ``unreachable``."""
    run = _Runner(scene, COLLISION, slip_check=True)
    # The goal the hand can reach: a tumble of a box-symmetric object becomes the upright
    # equivalent, a goal sunk into the observed surface under it is put down on it.
    upright = upright_equivalent(object_points, cross_pose)
    goal_change = {"goal_turned_deg": round(float(np.degrees(_pose_distance(np.asarray(cross_pose), upright)[1])), 2)}
    cross_pose = rest_on_support(object_points, anchor_points, upright)
    goal_change["goal_raised_m"] = round(float(cross_pose[2, 3] - upright[2, 3]), 4)
    if scene.grasp_mode == "suction" and is_roofed(object_points, anchor_points, cross_pose):
        plan = plan_side_entry(object_points, anchor_points, cross_pose, viewpoint)
        if plan is not None:
            return _with(execute_side_entry(scene, run, object_points, plan), goal_change)
    grasp = top_suction_point(object_points) if scene.grasp_mode == "suction" else top_grasp(object_points)
    if grasp is None:
        return _finish(run, ExecutionResult(ok=False, reason=PLANNING_FAILED,
                                            detail="the object is wider than the fingers open"), {"grasp_point": None, **goal_change})
    start = grasp.tcp
    goal = cross_pose @ start
    rise = carry_height(object_points, anchor_points, start[:3, 3], goal[:3, 3])
    if rise is None:
        return _finish(run, ExecutionResult(ok=False, reason=PLANNING_FAILED,
                                            detail="no carry height clears the observed furniture"), {"grasp_point": None, **goal_change})
    lifted = start.copy()
    above_goal = goal.copy()
    travel_z = max(start[2, 3] + LIFT_HEIGHT, goal[2, 3] + max(CARRY_CLEARANCE, rise))
    lifted[2, 3] = travel_z
    above_goal[2, 3] = travel_z
    waypoints = [start, lifted, above_goal, goal]
    extra = {"grasp_point": start[:3, 3].round(4).tolist(), "grasp_approach": grasp.approach.round(4).tolist(),
             "grasp_width": grasp.width, "entry": "top",
             "planned_path": [w[:3, 3].round(4).tolist() for w in waypoints], **goal_change}
    if _below_floor(np.stack(waypoints)):
        return _unreachable(run, extra)
    try:
        run.grasp(grasp)
        for a, b in zip(waypoints[:-1], waypoints[1:]):
            run.line(a, b)
        run.release(grasp.approach)
    except _Abort as abort:
        return _abort_free(scene, run, abort, extra)
    return _finish(run, _settle(scene), extra)
