"""How far a door really opens: its joint limit, or where something stops it first.

Real PartNet-Mobility objects declare limits their own geometry cannot reach:
fridge 12036's door is limited at pi, but its handle meets the fridge's side
wall near 2.3 rad. A goal nobody can reach would make even the ground-truth
policy fail, so the loader measures the reachable open value in physics (drive
the door open with gravity compensated, see where it stops) and uses that.
"""

from __future__ import annotations

import numpy as np

PROBE_SECONDS = 3.0
PROBE_TIMESTEP = 1.0 / 200.0
STIFFNESS, DAMPING = 400.0, 40.0   # acceleration-mode gains, as the tasks' executor uses
BACK_OFF = 0.02                    # fraction of the range kept clear of the blocking contact


def reachable_open_qpos(articulation, joint_name: str, rest_by_joint: dict[str, float],
                        closed_q: float, open_q: float, tolerance: float = 0.02) -> float:
    """Joint value the door reaches when driven from closed towards ``open_q``.

    Returns ``open_q`` when the door gets within ``tolerance`` x range of it; otherwise
    the value it stopped at, backed off by BACK_OFF x range (so the goal is clear of the
    contact and a PD drive can settle on it). ``articulation`` is a physics-only SAPIEN
    articulation whose joints are named as in the URDF.
    """
    joints = articulation.get_active_joints()
    names = [j.name for j in joints]
    if joint_name not in names:
        raise ValueError(f"joint {joint_name!r} not in {names}")
    k = names.index(joint_name)
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
    span = open_q - closed_q
    if abs(open_q - reached) <= tolerance * abs(span):
        return float(open_q)
    return float(reached - BACK_OFF * span)
