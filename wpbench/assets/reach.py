"""How far a door really opens: its joint limit, or where something stops it first.

Real PartNet-Mobility objects declare limits their own geometry cannot reach:
fridge 12036's door is limited at pi, but its handle meets the fridge's side
wall near 2.3 rad. A goal nobody can reach would make even the ground-truth
policy fail, so the loader measures the reachable open value in physics (drive
the door open with gravity compensated, see where it stops) and uses that.

:func:`probe_opening` also says what stopped the door: the collision pieces of other
links pressed against the moving part at the stop (``wpbench.assets.clear_path``
uses them to find pieces that are decomposition defects).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

PROBE_SECONDS = 3.0
PROBE_TIMESTEP = 1.0 / 200.0
STIFFNESS, DAMPING = 400.0, 40.0   # acceleration-mode gains, as the tasks' executor uses
BACK_OFF = 0.02                    # fraction of the range kept clear of the blocking contact
REACH_TOLERANCE = 0.02             # a door within this fraction of its range from the limit reaches it
MIN_BLOCKING_IMPULSE = 1e-3        # contact impulses (N s) below this do not hold anything back


@dataclass(frozen=True)
class Blocker:
    """A collision piece pressed against the moving part where it stopped.

    link / piece: the piece (index into the link's collision shapes); impulse: summed
    contact impulse over the last step (N s); position: a contact point (body frame).
    """

    link: str
    piece: int
    impulse: float
    position: tuple[float, float, float]


@dataclass(frozen=True)
class OpeningProbe:
    """Where a door driven open stopped: ``reached`` (joint value), ``full`` (within
    tolerance of the limit), and what held it (``blockers``, strongest first)."""

    reached: float
    full: bool
    blockers: list[Blocker] = field(default_factory=list)


def reachable_open_qpos(articulation, joint_name: str, rest_by_joint: dict[str, float],
                        closed_q: float, open_q: float, tolerance: float = REACH_TOLERANCE) -> float:
    """Joint value the door reaches when driven from closed towards ``open_q``.

    Returns ``open_q`` when the door gets within ``tolerance`` x range of it; otherwise
    the value it stopped at, backed off by BACK_OFF x range (so the goal is clear of the
    contact and a PD drive can settle on it). ``articulation`` is a physics-only SAPIEN
    articulation whose joints are named as in the URDF.
    """
    probe = probe_opening(articulation, joint_name, rest_by_joint, closed_q, open_q, tolerance=tolerance)
    if probe.full:
        return float(open_q)
    return float(probe.reached - BACK_OFF * (open_q - closed_q))


def probe_opening(articulation, joint_name: str, rest_by_joint: dict[str, float], closed_q: float,
                  open_q: float, moving_links: set[str] | None = None,
                  tolerance: float = REACH_TOLERANCE) -> OpeningProbe:
    """Drive joint ``joint_name`` from ``closed_q`` towards ``open_q`` (other joints held at
    ``rest_by_joint``) and report where it stopped and which pieces of links outside
    ``moving_links`` (default: the joint's child link) press on links inside it.
    """
    joints = articulation.get_active_joints()
    names = [j.name for j in joints]
    if joint_name not in names:
        raise ValueError(f"joint {joint_name!r} not in {names}")
    k = names.index(joint_name)
    moving = set(moving_links) if moving_links is not None else {joints[k].child_link.name}
    qpos = np.array([rest_by_joint.get(n, 0.0) for n in names], dtype=np.float32)
    qpos[k] = closed_q
    articulation.set_qpos(qpos)
    articulation.set_qvel(np.zeros_like(qpos))
    for i, j in enumerate(joints):
        j.set_drive_properties(STIFFNESS, DAMPING, 1e6, "acceleration")
        j.set_drive_target(float(open_q if i == k else qpos[i]))
    scene = articulation.get_links()[0].entity.scene
    scene.set_timestep(PROBE_TIMESTEP)
    for _ in range(int(PROBE_SECONDS / PROBE_TIMESTEP)):
        articulation.set_qf(articulation.compute_passive_force(gravity=True, coriolis_and_centrifugal=True))
        scene.step()
    reached = float(articulation.get_qpos()[k])
    full = abs(open_q - reached) <= tolerance * abs(open_q - closed_q)
    return OpeningProbe(reached, bool(full), [] if full else _blockers(scene, moving))


def _blockers(scene, moving: set[str]) -> list[Blocker]:
    """Pieces of links outside ``moving`` in contact with links inside it, strongest first."""
    found: dict[tuple[str, int], Blocker] = {}
    for contact in scene.get_contacts():
        impulse = float(sum(np.linalg.norm(p.impulse) for p in contact.points))
        if impulse < MIN_BLOCKING_IMPULSE or not contact.points:
            continue
        sides = list(zip(contact.bodies, contact.shapes))
        names = [body.entity.name for body, _shape in sides]
        if (names[0] in moving) == (names[1] in moving):
            continue
        body, shape = sides[0] if names[0] not in moving else sides[1]
        shapes = body.get_collision_shapes()
        piece = next((i for i, s in enumerate(shapes) if s is shape or s == shape), -1)
        key = (body.entity.name, piece)
        position = tuple(float(v) for v in contact.points[0].position)
        if key not in found or found[key].impulse < impulse:
            found[key] = Blocker(body.entity.name, piece, impulse, position)
    return sorted(found.values(), key=lambda b: -b.impulse)


REST_SECONDS = 0.2
RESTLESS_SPEED = 1.0   # rad/s or m/s: a part held at rest that moves this fast is being pushed


def restless_links(articulation, rest_by_joint: dict[str, float], still_links: set[str]) -> dict[str, float]:
    """{link: peak joint speed} of the links, outside ``still_links``, that move faster than
    RESTLESS_SPEED while every joint is held at ``rest_by_joint`` for REST_SECONDS.

    A part held still by its drive moves only when something pushes it: collision pieces of
    a neighbour that it overlaps (a knob sunk into the body's panel spins up).
    """
    joints = articulation.get_active_joints()
    qpos = np.array([rest_by_joint.get(j.name, 0.0) for j in joints], dtype=np.float32)
    articulation.set_qpos(qpos)
    articulation.set_qvel(np.zeros_like(qpos))
    for j, q in zip(joints, qpos):
        j.set_drive_properties(STIFFNESS, DAMPING, 1e6, "acceleration")
        j.set_drive_target(float(q))
    scene = articulation.get_links()[0].entity.scene
    scene.set_timestep(PROBE_TIMESTEP)
    peak = np.zeros(len(joints))
    for _ in range(int(REST_SECONDS / PROBE_TIMESTEP)):
        articulation.set_qf(articulation.compute_passive_force(gravity=True, coriolis_and_centrifugal=True))
        scene.step()
        peak = np.maximum(peak, np.abs(articulation.get_qvel()))
    return {j.child_link.name: float(v) for j, v in zip(joints, peak)
            if v > RESTLESS_SPEED and j.child_link.name not in still_links}

