"""A Panda arm in a SAPIEN scene: ManiSkill3's bundled ``panda_v2`` on a fixed base,
controlled like ManiSkill's ``pd_joint_pos`` controller.

The env has no ManiSkill agent (its action is a cross-pose), so the arm is an articulation
loaded from the bundled URDF with its root fixed. Every arm joint has a PD position drive
(ARM_STIFFNESS, ARM_DAMPING, force capped at the joint's URDF effort: 87 N m for joints
1-4, 12 N m for 5-7) that follows a joint target and a velocity feed-forward; gravity is
off on the arm's links (gravity compensation, as ManiSkill's Panda balances passive
forces). A load the drives cannot hold stops the arm: it is never pushed through.

Grasps are the floating hand's (wpbench.sim.gripper): ``friction`` closes the fingers
(FINGER_FORCE each, pad friction PAD_FRICTION); ``suction`` holds the touched surface at
the TCP with a spring capped at SUCTION_FORCE / SUCTION_TORQUE. The TCP is the URDF's
``panda_hand_tcp`` link: z is the approach, y the direction the fingers open along.

Between stages the arm waits at PARK_POSITION, far from everything (out of the camera's view).
"""

from __future__ import annotations

import numpy as np
import sapien
from sapien import physx

from wpbench.sim.arm_planner import panda_files
from wpbench.sim.gripper import (FINGER_DAMPING, FINGER_FORCE, FINGER_OPEN, FINGER_STIFFNESS, PAD_FRICTION,
                                 SUCTION_FORCE, SUCTION_STIFFNESS, SUCTION_TORQUE, TOUCH_GAP)
from wpbench.sim.poses import matrix_to_pose, pose_to_matrix

ARM_STIFFNESS = 1000.0      # N m/rad (ManiSkill's Panda pd_joint_pos)
ARM_DAMPING = 100.0         # N m s/rad
# Where a stage starts: the arm folded over its base, the TCP 29 cm in front of it and 28 cm up,
# pointing down (ManiSkill's rest pose reaches 62 cm forward, into furniture the base stands close to).
HOME_QPOS = np.array([0.0, -0.8, 0.0, -2.9, 0.0, 2.1, np.pi / 4])
PARK_POSITION = (-50.0, 50.0, 0.0)


class PandaArm:
    """The arm, its drives, fingers and suction in one ManiSkill scene (single CPU sub-scene)."""

    def __init__(self, scene, name: str = "panda"):
        urdf, _ = panda_files()
        loader = scene.create_urdf_loader()
        loader.fix_root_link = True
        loader.name = name
        builder = loader.parse(str(urdf))["articulation_builders"][0]
        builder.initial_pose = sapien.Pose(p=list(PARK_POSITION))
        self._ms = builder.build(name=name)
        self.articulation: physx.PhysxArticulation = self._ms._objs[0]
        self.links = self.articulation.get_links()
        self.hand = next(l for l in self.links if l.name.endswith("panda_hand"))
        self.tcp_link = next(l for l in self.links if l.name.endswith("panda_hand_tcp"))
        self.fingers = [l for l in self.links if l.name.endswith("finger")]
        joints = self.articulation.get_active_joints()
        self.arm_joints = [j for j in joints if "finger" not in j.name]
        self.finger_joints = [j for j in joints if "finger" in j.name]
        self.n_arm = len(self.arm_joints)
        pad = physx.PhysxMaterial(static_friction=PAD_FRICTION, dynamic_friction=PAD_FRICTION * 0.8, restitution=0.0)
        for link in self.links:
            link.disable_gravity = True
            if link in self.fingers:
                for shape in link.collision_shapes:
                    shape.set_physical_material(pad)
        efforts = [87.0] * 4 + [12.0] * 3
        for joint, effort in zip(self.arm_joints, efforts):
            joint.set_drive_properties(ARM_STIFFNESS, ARM_DAMPING, effort, "force")
        for joint in self.finger_joints:
            joint.set_drive_properties(FINGER_STIFFNESS, FINGER_DAMPING, FINGER_FORCE, "force")
        self.suction = None
        self.suction_body = None
        self.base = np.eye(4)
        self.park()

    # ------------------------------------------------------------------ state
    def tcp_pose(self) -> np.ndarray:
        """(4, 4) world pose of the TCP."""
        return pose_to_matrix(self.tcp_link.entity_pose)

    def qpos(self) -> np.ndarray:
        """(7,) arm joint values."""
        return np.asarray(self.articulation.get_qpos(), dtype=np.float64)[: self.n_arm]

    @property
    def opening(self) -> float:
        """Distance between the finger pads (m)."""
        return float(np.sum(np.asarray(self.articulation.get_qpos())[self.n_arm:]))

    def velocities(self) -> list[np.ndarray]:
        return [np.asarray(self.articulation.get_qvel())]

    # ------------------------------------------------------------------ commands
    def place(self, base: np.ndarray, q: np.ndarray = HOME_QPOS, opening: float = 2 * FINGER_OPEN) -> None:
        """Stand the robot at ``base`` (4, 4), arm at rest at ``q`` (7,), fingers at ``opening``."""
        self.base = np.asarray(base, dtype=np.float64).copy()
        self.articulation.set_root_pose(matrix_to_pose(self.base))
        full = np.concatenate([np.asarray(q, dtype=np.float64), np.full(len(self.finger_joints), opening / 2)])
        self.articulation.set_qpos(full.astype(np.float32))
        self.articulation.set_qvel(np.zeros_like(full, dtype=np.float32))
        self.set_joint_targets(q)
        self.set_fingers(opening)

    def park(self) -> None:
        self.detach()
        park = np.eye(4)
        park[:3, 3] = PARK_POSITION
        self.place(park)

    def set_joint_targets(self, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        """pd_joint_pos: position targets (7,) with an optional velocity feed-forward (7,)."""
        qd = np.zeros(self.n_arm) if qd is None else qd
        for joint, target, speed in zip(self.arm_joints, q, qd):
            joint.set_drive_target(float(target))
            joint.set_drive_velocity_target(float(speed))

    def set_fingers(self, opening: float) -> None:
        """Finger targets: pad distance ``opening`` (m); closing on an object squeezes with FINGER_FORCE."""
        half = float(np.clip(opening / 2, -0.01, FINGER_OPEN))
        for joint in self.finger_joints:
            joint.set_drive_target(half)

    # ------------------------------------------------------------------ grasping
    def touched_body(self, contacts, near: float | None = None):
        """The body (rigid component) the hand or fingers touch (the closest one), or None;
        contacts of the arm's other links do not count. With ``near`` (m), only contact points
        that close to the TCP (the cup) count."""
        arm = {l.entity.per_scene_id for l in self.links}
        mine = {l.entity.per_scene_id for l in self.links if l is self.hand or l is self.tcp_link or "finger" in l.name}
        tcp = self.tcp_pose()[:3, 3] if near is not None else None
        best, best_gap = None, TOUCH_GAP
        for c in contacts:
            ids = (c.bodies[0].entity.per_scene_id, c.bodies[1].entity.per_scene_id)
            if (ids[0] in mine) == (ids[1] in mine) or ids[0] in arm and ids[1] in arm or not c.points:
                continue
            points = [p for p in c.points if tcp is None or np.linalg.norm(np.asarray(p.position) - tcp) < near]
            if not points:
                continue
            gap = min(float(p.separation) for p in points)
            if gap < best_gap:
                best, best_gap = c.bodies[1] if ids[0] in mine else c.bodies[0], gap
        return best

    def attach(self, scene, body) -> None:
        """Suction: hold ``body`` at its current pose relative to the TCP with a capped spring."""
        tcp_in_body = np.linalg.inv(pose_to_matrix(body.entity_pose)) @ self.tcp_pose()
        tcp_in_hand = np.linalg.inv(pose_to_matrix(self.hand.entity_pose)) @ self.tcp_pose()
        self.suction = scene.sub_scenes[0].create_drive(body, matrix_to_pose(tcp_in_body), self.hand,
                                                        matrix_to_pose(tcp_in_hand))
        for axis in ("x", "y", "z"):
            getattr(self.suction, f"set_drive_property_{axis}")(SUCTION_STIFFNESS, 2 * np.sqrt(SUCTION_STIFFNESS),
                                                                   SUCTION_FORCE, "force")
        self.suction.set_drive_property_slerp(SUCTION_STIFFNESS / 20, 2.0, SUCTION_TORQUE, "force")
        self.suction.set_drive_target(sapien.Pose())
        self.suction_body = body

    def suction_stretch(self) -> float:
        """How far (m) the TCP is from where the cup holds the body; 0 when nothing is attached."""
        if self.suction is None:
            return 0.0
        hold = pose_to_matrix(self.suction_body.entity_pose) @ pose_to_matrix(self.suction.pose_in_parent)
        return float(np.linalg.norm(hold[:3, 3] - self.tcp_pose()[:3, 3]))

    def contacts_with_others(self, contacts) -> list[str]:
        """Names of the arm's links pressed against something that is not the arm (impulse > 0)."""
        mine = {l.entity.per_scene_id: l.name for l in self.links}
        out = set()
        for c in contacts:
            a, b = c.bodies[0].entity.per_scene_id, c.bodies[1].entity.per_scene_id
            if (a in mine) == (b in mine) or not any(np.linalg.norm(p.impulse) > 1e-6 for p in c.points):
                continue
            link, other = (mine[a], c.bodies[1]) if a in mine else (mine[b], c.bodies[0])
            out.add(f"{link.split('/')[-1]}-{other.entity.name}")
        return sorted(out)

    def detach(self) -> None:
        if self.suction is not None:
            self.hand.entity.remove_component(self.suction)
            self.suction = None
            self.suction_body = None
