"""The scripted executor: one for every policy, so that only the predicted
cross-pose differs between policies.

- Articulated: pick the joint value whose target-link pose best matches the
  predicted cross-pose (least squares on the link's points, within the joint
  limits), move the joint's PD target there at a bounded speed (as a hand would
  swing it), simulate until still.
- Free-floating: move the object to the predicted pose, release it, simulate
  until it rests. Physics decides: a pose inside a wall is pushed out, and that
  counts. A free body's rest is judged from the pose it shows over its physics
  steps (:class:`ObservedMotion`), not from the velocity PhysX reports: a block
  wedged between two held drawers keeps a reported 0.1 m/s and 2 rad/s while its
  pose does not move (storage 45332).

A simulation that blows up (NaN, runaway velocities) ends as a failure with a
reason; it never raises.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import sapien
from sapien import physx
from scipy.optimize import minimize_scalar

from wpbench.sim.failure import BLOW_UP, NOT_AT_REST
from wpbench.sim.furniture import SceneFurniture
from wpbench.sim.poses import matrix_to_pose, pose_to_matrix, transform_points

MAX_SETTLE_SECONDS = 4.0
STILL_STEPS = 20          # consecutive still steps that count as "at rest"
JOINT_STILL_VEL = 1e-2    # rad/s or m/s
BODY_STILL_LIN = 1e-2     # m/s
BODY_STILL_ANG = 1e-1     # rad/s
RUNAWAY_SPEED = 20.0      # m/s (or rad/s): nothing in these scenes moves that fast
MAX_DEPENETRATION_SPEED = 0.5  # m/s: a pose inside a wall is pushed out gently, not launched
# How fast the ideal executor moves a joint's target. A step of the target would swing a
# door through its whole range at once: a 180-degree fridge door peaked above RUNAWAY_SPEED,
# and the jolt set light parts (knobs) spinning.
IDEAL_JOINT_SPEED = {"revolute": 1.5, "prismatic": 0.5}   # rad/s, m/s


@dataclass
class ExecutionResult:
    ok: bool                      # False when the simulation blew up, the pose was unusable or the robot failed
    reason: str = ""              # a code of wpbench.sim.failure ("" when nothing went wrong)
    detail: str = ""              # free text about the reason
    sim_seconds: float = 0.0
    at_rest: bool = False
    details: dict = field(default_factory=dict)


def best_joint_value(furniture: SceneFurniture, cross_pose: np.ndarray, link_points: np.ndarray) -> float:
    """argmin_q sum_i |T_pred p_i - L(q) L(q_now)^-1 p_i|^2 over the joint limits.

    A coarse grid finds the basin (the cost is not convex in q for a revolute joint),
    then a bounded scalar search refines it.
    """
    lo, hi = furniture.limits
    now_inv = np.linalg.inv(furniture.target_link_pose())
    local = transform_points(now_inv, link_points)
    wanted = transform_points(cross_pose, link_points)

    def cost_of(poses: np.ndarray) -> np.ndarray:
        moved = np.einsum("kij,nj->kni", poses[:, :3, :3], local) + poses[:, None, :3, 3]
        return ((moved - wanted) ** 2).sum(-1).mean(-1)

    grid = np.linspace(lo, hi, 61)
    costs = cost_of(furniture.target_link_pose_at(grid))
    k = int(np.argmin(costs))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    if b - a <= 0:
        return float(grid[k])
    res = minimize_scalar(
        lambda q: float(cost_of(furniture.target_link_pose_at(np.array([q])))[0]),
        bounds=(a, b), method="bounded", options={"xatol": 1e-5},
    )
    return float(res.x) if res.fun <= costs[k] else float(grid[k])


def blown_up(values: list[np.ndarray]) -> str:
    """A description of what blew up in ``values`` (non-finite or runaway), "" when all is well."""
    for v in values:
        if not np.all(np.isfinite(v)):
            return "simulation blow-up: non-finite state"
        if np.abs(v).max() > RUNAWAY_SPEED:
            return f"simulation blow-up: runaway velocity {np.abs(v).max():.1f}"
    return ""


def simulate_until_still(
    step: Callable[[], None],
    timestep: float,
    velocities: Callable[[], list[np.ndarray]],
    is_still: Callable[[], bool],
    max_seconds: float = MAX_SETTLE_SECONDS,
) -> ExecutionResult:
    """Step physics until ``is_still`` holds for STILL_STEPS steps, or time runs out."""
    still = 0
    n_max = int(round(max_seconds / timestep))
    for n in range(1, n_max + 1):
        step()
        detail = blown_up(velocities())
        if detail:
            return ExecutionResult(ok=False, reason=BLOW_UP, detail=detail, sim_seconds=n * timestep)
        still = still + 1 if is_still() else 0
        if still >= STILL_STEPS:
            return ExecutionResult(ok=True, sim_seconds=n * timestep, at_rest=True)
    return ExecutionResult(ok=True, reason=NOT_AT_REST, detail="did not come to rest", sim_seconds=n_max * timestep, at_rest=False)


def step_speeds(before: sapien.Pose, after: sapien.Pose, timestep: float) -> tuple[float, float]:
    """(m/s, rad/s): how fast a body moved over one physics step of ``timestep`` s, from
    the world poses of its mass centre before and after the step."""
    turn = (after * before.inv()).q                 # (w, x, y, z)
    angle = 2.0 * np.arctan2(np.linalg.norm(turn[1:]), abs(turn[0]))
    return float(np.linalg.norm(after.p - before.p)) / timestep, float(angle) / timestep


class ObservedMotion:
    """The speeds a rigid body's pose showed over its last ``window`` physics steps.

    Rest is judged from these, not from ``linear_velocity`` / ``angular_velocity``: PhysX
    can report a velocity a body does not move with (a block pinched between two driven
    drawers reported 0.1 m/s and 2 rad/s every step while its pose changed by 1e-7 m in
    4 s), and a body that moves shows it in its pose whatever velocity is reported.
    ``steps(step)`` wraps a physics step so that each call records the step's motion; a
    pose set between steps (a teleport) is not motion.
    """

    def __init__(self, body: physx.PhysxRigidDynamicComponent, timestep: float, window: int = STILL_STEPS):
        self.body = body
        self.timestep = timestep
        self.speeds: deque[tuple[float, float]] = deque(maxlen=window)

    def _mass_centre(self) -> sapien.Pose:
        return self.body.entity_pose * self.body.cmass_local_pose

    def observe(self, step: Callable[[], None]) -> None:
        """Run one physics ``step`` and record how fast the body moved over it."""
        before = self._mass_centre()
        step()
        self.speeds.append(step_speeds(before, self._mass_centre(), self.timestep))

    def steps(self, step: Callable[[], None]) -> Callable[[], None]:
        """``step`` that also records each step's motion."""
        return lambda: self.observe(step)

    def still(self, linear: float, angular: float, steps: int = 1) -> bool | None:
        """The last ``steps`` recorded steps (fewer if fewer were recorded) all moved slower than
        ``linear`` m/s and turned slower than ``angular`` rad/s; None when none was recorded."""
        if not self.speeds:
            return None
        recent = list(self.speeds)[-steps:]
        return all(v < linear and w < angular for v, w in recent)


def execute_articulated(
    furniture: SceneFurniture,
    cross_pose: np.ndarray,
    link_points: np.ndarray,
    step: Callable[[], None],
    timestep: float,
) -> ExecutionResult:
    """Move the target joint to the value that best realises ``cross_pose``: its PD target
    runs there at IDEAL_JOINT_SPEED, then physics settles."""
    q_cmd = best_joint_value(furniture, cross_pose, link_points)
    q_now = furniture.qpos
    speed = IDEAL_JOINT_SPEED[furniture.asset.joint_type]
    n_ramp = int(np.ceil(abs(q_cmd - q_now) / (speed * timestep)))
    velocities = lambda: [furniture.articulation.get_qvel()]  # noqa: E731
    for n in range(1, n_ramp + 1):
        furniture.drive_to(q_now + (q_cmd - q_now) * n / n_ramp)
        step()
        detail = blown_up(velocities())
        if detail:
            result = ExecutionResult(ok=False, reason=BLOW_UP, detail=detail, sim_seconds=n * timestep)
            result.details.update(q_command=q_cmd, q_final=furniture.qpos)
            return result
    result = simulate_until_still(
        step,
        timestep,
        velocities=velocities,
        is_still=lambda: abs(furniture.qvel) < JOINT_STILL_VEL,
    )
    result.sim_seconds += n_ramp * timestep
    result.details.update(q_command=q_cmd, q_final=furniture.qpos)
    return result


def execute_free(
    body: physx.PhysxRigidDynamicComponent,
    cross_pose: np.ndarray,
    step: Callable[[], None],
    timestep: float,
) -> ExecutionResult:
    """Teleport the free object by ``cross_pose``, release it and let it settle: at rest once
    its pose has moved slower than BODY_STILL_LIN / BODY_STILL_ANG for STILL_STEPS steps."""
    goal = cross_pose @ pose_to_matrix(body.entity_pose)
    body.set_max_depenetration_velocity(MAX_DEPENETRATION_SPEED)
    body.entity.set_pose(matrix_to_pose(goal))
    body.set_linear_velocity(np.zeros(3))
    body.set_angular_velocity(np.zeros(3))
    body.wake_up()
    motion = ObservedMotion(body, timestep)
    result = simulate_until_still(
        motion.steps(step),
        timestep,
        velocities=lambda: [np.asarray(body.linear_velocity), np.asarray(body.angular_velocity), np.asarray(body.entity_pose.p)],
        is_still=lambda: bool(motion.still(BODY_STILL_LIN, BODY_STILL_ANG)),
    )
    result.details.update(placed_pose=goal.tolist())
    return result
