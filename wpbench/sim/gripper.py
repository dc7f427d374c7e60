"""A floating Panda hand in a SAPIEN scene, moved by a bounded 6-DoF drive.

The hand is ManiSkill3's bundled Panda hand (``panda_v2_gripper.urdf`` without its
six virtual base joints): a free articulation of the palm and two prismatic fingers.
A PhysX D6 drive pulls the tool centre point (TCP, between the fingertips) toward a
target pose with springs whose force and torque are capped, as an arm's would be:
an obstacle or a hinge that resists more than the cap stops the hand, it is not
pushed through. Gravity is off on the hand (the arm it stands for carries it).

Grasps: ``friction`` closes the fingers (pads with friction PAD_FRICTION, FINGER_FORCE
each); ``suction`` (an explicit option) attaches the closed fingertips to the surface
they touch with a spring capped at SUCTION_FORCE, as a suction cup holds: pulled
harder than that, the cup stretches and the executor lets it go (a slip).

Frames: the TCP frame is the hand frame moved ``TCP_OFFSET`` along its z axis; z is
the approach direction (out of the palm), y the direction the fingers open along.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import sapien
from sapien import physx

from wpbench.sim.poses import matrix_to_pose, pose_to_matrix

TCP_OFFSET = 0.1034          # m, hand frame -> TCP along z (the bundled URDF's hand_tcp joint)
FINGER_OPEN = 0.04           # m, each finger's travel (8 cm between the pads)
LINEAR_STIFFNESS = 3000.0    # N/m, TCP position spring
LINEAR_DAMPING = 150.0       # N s/m
MAX_FORCE = 120.0            # N, the most the drive pulls with (a Panda's payload-class force)
ANGULAR_STIFFNESS = 300.0    # N m/rad
ANGULAR_DAMPING = 15.0       # N m s/rad
MAX_TORQUE = 20.0            # N m
FINGER_STIFFNESS = 2000.0    # N/m, finger position drive
FINGER_DAMPING = 100.0
FINGER_FORCE = 70.0          # N per finger (the Franka hand's continuous grip force)
PAD_FRICTION = 1.5           # static friction of the finger pads
SUCTION_STIFFNESS = 4000.0  # N/m, the suction cup's hold on a surface (grasp="suction")
SUCTION_FORCE = 60.0         # N, the most the cup holds before it lets go
SUCTION_TORQUE = 3.0         # N m
TOUCH_GAP = 0.002            # m: closer than this counts as touching
PARK_POSITION = (50.0, 50.0, 5.0)  # where an idle hand waits, far from every scene object


def _hand_urdf() -> Path:
    """The bundled hand URDF without its virtual base joints, written to the asset cache once."""
    import mani_skill
    from wpbench.assets.library import cache_root

    source = Path(mani_skill.__file__).parent / "assets" / "robots" / "panda" / "panda_v2_gripper.urdf"
    out = cache_root() / "robots" / "panda_hand.urdf"
    if out.exists():
        return out
    tree = ET.parse(source)
    robot = tree.getroot()
    for element in list(robot):
        name = element.get("name", "")
        if (element.tag == "link" and name.startswith("root")) or (element.tag == "joint" and name.startswith("root_")):
            robot.remove(element)
    for mesh in robot.iter("mesh"):
        mesh.set("filename", str(source.parent / mesh.get("filename")))
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(f".tmp{id(tree)}")
    tree.write(tmp)
    tmp.replace(out)
    return out


def tcp_to_hand(tcp: np.ndarray) -> np.ndarray:
    """(4, 4) TCP pose -> (4, 4) hand (palm) pose."""
    offset = np.eye(4)
    offset[2, 3] = -TCP_OFFSET
    return tcp @ offset


class FloatingGripper:
    """The hand, its drive and its fingers in one ManiSkill scene (single CPU sub-scene)."""

    def __init__(self, scene, name: str = "gripper"):
        loader = scene.create_urdf_loader()
        loader.fix_root_link = False
        loader.name = name
        builder = loader.parse(str(_hand_urdf()))["articulation_builders"][0]
        builder.initial_pose = sapien.Pose(p=list(PARK_POSITION))
        self._ms = builder.build(name=name)
        self.articulation: physx.PhysxArticulation = self._ms._objs[0]
        self.links = self.articulation.get_links()
        self.hand = next(l for l in self.links if l.name.endswith("panda_hand"))
        self.fingers = [l for l in self.links if "finger" in l.name]
        pad = physx.PhysxMaterial(static_friction=PAD_FRICTION, dynamic_friction=PAD_FRICTION * 0.8, restitution=0.0)
        for link in self.links:
            link.disable_gravity = True
            if link in self.fingers:
                for shape in link.collision_shapes:
                    shape.set_physical_material(pad)
        self.finger_joints = self.articulation.get_active_joints()
        for joint in self.finger_joints:
            joint.set_drive_properties(FINGER_STIFFNESS, FINGER_DAMPING, FINGER_FORCE, "force")
        offset = sapien.Pose(p=[0.0, 0.0, TCP_OFFSET])
        self.drive: physx.PhysxDriveComponent = scene.sub_scenes[0].create_drive(None, sapien.Pose(), self.hand, offset)
        for axis in ("x", "y", "z"):
            getattr(self.drive, f"set_drive_property_{axis}")(LINEAR_STIFFNESS, LINEAR_DAMPING, MAX_FORCE, "force")
        self.drive.set_drive_property_slerp(ANGULAR_STIFFNESS, ANGULAR_DAMPING, MAX_TORQUE, "force")
        self.park()

    # ------------------------------------------------------------------ state
    def tcp_pose(self) -> np.ndarray:
        """(4, 4) world pose of the TCP."""
        offset = np.eye(4)
        offset[2, 3] = TCP_OFFSET
        return pose_to_matrix(self.hand.entity_pose) @ offset

    @property
    def opening(self) -> float:
        """Distance between the finger pads (m)."""
        return float(np.sum(self.articulation.get_qpos()))

    def velocities(self) -> list[np.ndarray]:
        return [np.asarray(self.hand.linear_velocity), np.asarray(self.hand.angular_velocity)]

    # ------------------------------------------------------------------ commands
    def teleport(self, tcp: np.ndarray, opening: float = 2 * FINGER_OPEN) -> None:
        """Put the TCP at ``tcp`` (4, 4) at rest, fingers at ``opening``, and hold it there."""
        self.articulation.set_root_pose(matrix_to_pose(tcp_to_hand(tcp)))
        self.articulation.set_root_linear_velocity(np.zeros(3))
        self.articulation.set_root_angular_velocity(np.zeros(3))
        q = np.full(len(self.finger_joints), opening / 2, dtype=np.float32)
        self.articulation.set_qpos(q)
        self.articulation.set_qvel(np.zeros_like(q))
        self.set_fingers(opening)
        self.set_target(tcp)

    def park(self) -> None:
        self.detach()
        park = np.eye(4)
        park[:3, 3] = PARK_POSITION
        self.teleport(park)

    def set_target(self, tcp: np.ndarray, velocity: np.ndarray | None = None) -> None:
        """Drive target for the TCP (4, 4), with an optional (6,) linear+angular velocity feed-forward."""
        self.drive.set_drive_target(matrix_to_pose(tcp))
        v = np.zeros(6) if velocity is None else np.asarray(velocity, dtype=np.float64)
        self.drive.set_drive_velocity_target(v[:3], v[3:])

    def set_fingers(self, opening: float) -> None:
        """Finger position target: pad distance ``opening`` (m); closing on an object squeezes with FINGER_FORCE."""
        half = float(np.clip(opening / 2, -0.01, FINGER_OPEN))
        for joint in self.finger_joints:
            joint.set_drive_target(half)

    def touched_body(self, contacts, near: float | None = None):
        """The body (rigid component) in contact with the hand or fingers (the closest one), or
        None; with ``near`` (m), only contact points that close to the TCP (the cup) count."""
        mine = {l.entity.per_scene_id for l in self.links}
        best, best_gap = None, TOUCH_GAP
        tcp = self.tcp_pose()[:3, 3] if near is not None else None
        for c in contacts:
            ids = (c.bodies[0].entity.per_scene_id, c.bodies[1].entity.per_scene_id)
            if (ids[0] in mine) == (ids[1] in mine) or not c.points:
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
        self.suction = scene.sub_scenes[0].create_drive(body, matrix_to_pose(tcp_in_body), self.hand,
                                                        sapien.Pose(p=[0.0, 0.0, TCP_OFFSET]))
        for axis in ("x", "y", "z"):
            getattr(self.suction, f"set_drive_property_{axis}")(SUCTION_STIFFNESS, 2 * np.sqrt(SUCTION_STIFFNESS),
                                                                   SUCTION_FORCE, "force")
        self.suction.set_drive_property_slerp(SUCTION_STIFFNESS / 20, 2.0, SUCTION_TORQUE, "force")
        self.suction.set_drive_target(sapien.Pose())
        self.suction_body = body

    def suction_stretch(self) -> float:
        """How far (m) the TCP is from where the cup holds the body; 0 when nothing is attached."""
        if getattr(self, "suction", None) is None:
            return 0.0
        hold = pose_to_matrix(self.suction_body.entity_pose) @ pose_to_matrix(self.suction.pose_in_parent)
        return float(np.linalg.norm(hold[:3, 3] - self.tcp_pose()[:3, 3]))

    def detach(self) -> None:
        if getattr(self, "suction", None) is not None:
            self.hand.entity.remove_component(self.suction)
            self.suction = None
            self.suction_body = None

    def touching(self, contacts, body_ids: set[int]) -> int:
        """How many fingers touch a body whose entity per-scene id is in ``body_ids``."""
        finger_set = {f.entity.per_scene_id for f in self.fingers}
        touching: set[int] = set()
        for c in contacts:
            a, b = c.bodies[0].entity.per_scene_id, c.bodies[1].entity.per_scene_id
            for mine, other in ((a, b), (b, a)):
                if mine in finger_set and other in body_ids and any(np.linalg.norm(p.impulse) > 1e-6 for p in c.points):
                    touching.add(mine)
        return len(touching)
