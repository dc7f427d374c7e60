"""Triangle meshes of SAPIEN collision shapes, for surface-sampled observations
and for measuring objects (bounds, centroids) exactly as physics sees them."""

from __future__ import annotations

import numpy as np
import trimesh
from sapien import physx

from wpbench.sim.poses import pose_to_matrix


def shape_mesh(shape: physx.PhysxCollisionShape) -> trimesh.Trimesh | None:
    """One collision shape -> mesh in its body's frame (None for planes)."""
    if isinstance(shape, physx.PhysxCollisionShapeBox):
        mesh = trimesh.creation.box(extents=2.0 * np.asarray(shape.half_size))
    elif isinstance(shape, (physx.PhysxCollisionShapeConvexMesh, physx.PhysxCollisionShapeTriangleMesh)):
        mesh = trimesh.Trimesh(
            np.asarray(shape.vertices) * np.asarray(shape.scale), np.asarray(shape.triangles), process=False
        )
    elif isinstance(shape, physx.PhysxCollisionShapeSphere):
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=shape.radius)
    elif isinstance(shape, physx.PhysxCollisionShapeCapsule):
        # SAPIEN capsules lie along x; trimesh builds them along z.
        mesh = trimesh.creation.capsule(height=2 * shape.half_length, radius=shape.radius)
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    elif isinstance(shape, physx.PhysxCollisionShapeCylinder):
        mesh = trimesh.creation.cylinder(radius=shape.radius, height=2 * shape.half_length)
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    else:  # planes are infinite: nothing to sample
        return None
    mesh.apply_transform(pose_to_matrix(shape.local_pose))
    return mesh


def body_mesh(component: physx.PhysxRigidBaseComponent) -> trimesh.Trimesh | None:
    """All collision shapes of a link or actor, merged, in the body frame."""
    parts = [m for m in (shape_mesh(s) for s in component.collision_shapes) if m is not None]
    if not parts:
        return None
    return trimesh.util.concatenate(parts)
