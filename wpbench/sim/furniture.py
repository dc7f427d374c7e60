"""A piece of furniture in a SAPIEN scene: its target joint, drives that hold
every joint where it is put, and the target link's pose as a function of the
joint value (read from the articulation's own kinematics, so revolute and
prismatic joints, any axis and any URDF frame, are handled the same way).

Works on the raw ``sapien.physx.PhysxArticulation`` (single CPU scene).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from sapien import physx

from wpbench.assets.spec import FurnitureAsset, rest_joint_values
from wpbench.sim.collision_mesh import body_mesh
from wpbench.sim.poses import pose_to_matrix, transform_points

# Acceleration-mode PD gains: independent of link mass, so a 2 kg microwave door and
# a 15 kg fridge door move alike. Gravity is compensated separately (see hold()).
DRIVE_STIFFNESS = 400.0
DRIVE_DAMPING = 40.0
DRIVE_FORCE_LIMIT = 1e6
# A free target joint (while a robot moves it) keeps a little damping, as real hinges and
# slides have; the rest of the furniture stays held.
FREE_JOINT_DAMPING = 0.5


def _urdf_name(scene_name: str) -> str:
    return scene_name.split("furniture_", 1)[-1] if scene_name.startswith("scene-") else scene_name


@dataclass
class SceneFurniture:
    asset: FurnitureAsset
    articulation: physx.PhysxArticulation

    def __post_init__(self) -> None:
        joints = self.articulation.get_active_joints()
        # ManiSkill prefixes every name with "scene-<k>-<articulation name>_".
        names = [_urdf_name(j.name) for j in joints]
        if self.asset.target_joint not in names:
            raise ValueError(
                f"{self.asset.object_id}: target joint {self.asset.target_joint!r} is not an active joint "
                f"of {self.asset.urdf} (active joints: {', '.join(names)}); regenerate or fix its wpbench.json"
            )
        self.joints = joints
        self.target_index = names.index(self.asset.target_joint)
        self.target_joint = joints[self.target_index]
        self.target_link = self.target_joint.child_link
        self.links = self.articulation.get_links()
        self._mesh_cache: dict[str, trimesh.Trimesh | None] = {}
        limits = np.array([j.get_limits()[0] for j in joints], dtype=np.float64)
        self.rest_qpos = rest_joint_values(self.asset, names, limits)
        for j in joints:
            j.set_drive_properties(DRIVE_STIFFNESS, DRIVE_DAMPING, DRIVE_FORCE_LIMIT, "acceleration")
            j.set_friction(0.0)

    # --- joint state --------------------------------------------------------
    @property
    def qpos(self) -> float:
        return float(self.articulation.get_qpos()[self.target_index])

    @property
    def qvel(self) -> float:
        return float(self.articulation.get_qvel()[self.target_index])

    def set_target_qpos(self, q: float) -> None:
        """Teleport the target joint to q (others to rest) and hold everything there."""
        qpos = self.rest_qpos.copy()
        qpos[self.target_index] = q
        self.articulation.set_qpos(qpos.astype(np.float32))
        self.articulation.set_qvel(np.zeros_like(qpos, dtype=np.float32))
        self.drive_to(q)

    def drive_to(self, q: float) -> None:
        """PD targets: the target joint to q, every other joint to its rest value."""
        for i, j in enumerate(self.joints):
            j.set_drive_target(float(q if i == self.target_index else self.rest_qpos[i]))

    def free_target_joint(self) -> None:
        """Let the target joint move freely (no spring, light damping): a robot moves it now."""
        self.target_joint.set_drive_properties(0.0, FREE_JOINT_DAMPING, DRIVE_FORCE_LIMIT, "acceleration")

    def hold_target_joint_here(self) -> None:
        """The target joint's spring back on, holding the joint where it is now."""
        self.target_joint.set_drive_properties(DRIVE_STIFFNESS, DRIVE_DAMPING, DRIVE_FORCE_LIMIT, "acceleration")
        self.drive_to(self.qpos)

    def hold(self) -> None:
        """Gravity compensation for this physics step (what an arm holding the door provides).

        Without it a bottom-hinged oven door sags under a PD drive by g / stiffness.
        """
        qf = self.articulation.compute_passive_force(gravity=True, coriolis_and_centrifugal=True)
        self.articulation.set_qf(qf)

    # --- kinematics ---------------------------------------------------------
    def target_link_pose(self) -> np.ndarray:
        return pose_to_matrix(self.target_link.entity_pose)

    def target_link_pose_at(self, qs: np.ndarray) -> np.ndarray:
        """(K,) joint values -> (K, 4, 4) world poses of the target link (state restored after)."""
        saved_q, saved_v = self.articulation.get_qpos(), self.articulation.get_qvel()
        qpos = saved_q.copy()
        out = np.empty((len(qs), 4, 4))
        for k, q in enumerate(qs):
            qpos[self.target_index] = q
            self.articulation.set_qpos(qpos)
            out[k] = pose_to_matrix(self.target_link.entity_pose)
        self.articulation.set_qpos(saved_q)
        self.articulation.set_qvel(saved_v)
        return out

    @property
    def limits(self) -> tuple[float, float]:
        lo, hi = self.target_joint.get_limits()[0]
        return float(lo), float(hi)

    # --- geometry -----------------------------------------------------------
    def link_mesh(self, link: physx.PhysxArticulationLinkComponent) -> trimesh.Trimesh | None:
        """Collision mesh of a link in its own frame (cached: shapes never change)."""
        if link.name not in self._mesh_cache:
            self._mesh_cache[link.name] = body_mesh(link)
        return self._mesh_cache[link.name]

    def world_mesh(self, links) -> trimesh.Trimesh | None:
        parts = []
        for link in links:
            mesh = self.link_mesh(link)
            if mesh is not None:
                parts.append(mesh.copy().apply_transform(pose_to_matrix(link.entity_pose)))
        return trimesh.util.concatenate(parts) if parts else None

    def anchor_links(self) -> list:
        return [l for l in self.links if l is not self.target_link]

    def world_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        mesh = self.world_mesh(self.links)
        return mesh.bounds[0].copy(), mesh.bounds[1].copy()

    def in_region_world(self, root_pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The asset's "in" box in the world: (center (3,), rotation (3, 3), half extents (3,))."""
        box = self.asset.in_region
        center = transform_points(root_pose, np.asarray(box.center)[None])[0]
        rotation = root_pose[:3, :3] @ np.asarray(box.rotation)
        return center, rotation, np.asarray(box.half_extents)
