"""Procedural furniture in SAPIEN physics (no renderer): cavities hold a block, closed doors stay shut.

For every category, one generated object is loaded with SAPIEN's URDF loader; an 8 cm,
0.1 kg block dropped into the open cavity must come to rest inside the in-region,
and a closed door or drawer left without any drive must not be pushed open by
contacts with the body.
"""

from __future__ import annotations


import numpy as np
import pytest

sapien = pytest.importorskip("sapien")

from wpbench.assets.procedural import CATEGORIES, generate_object  # noqa: E402
from wpbench.assets.spec import FurnitureAsset  # noqa: E402

TIMESTEP = 1 / 240
BLOCK_HALF = 0.04


@pytest.fixture(scope="module")
def assets(tmp_path_factory) -> dict[str, FurnitureAsset]:
    out = tmp_path_factory.mktemp("physics_lib")
    return {c: generate_object(c, 0, out, seed=0) for c in CATEGORIES}


def physics_scene():
    scene = sapien.Scene([sapien.physx.PhysxCpuSystem()])
    scene.set_timestep(TIMESTEP)
    ground = scene.create_actor_builder()
    # A plane's normal is its local +x; turn it to +z.
    ground.add_plane_collision(sapien.Pose(q=[0.7071068, 0, -0.7071068, 0]))
    ground.build_static(name="ground")
    return scene


def load_furniture(scene, asset: FurnitureAsset):
    """Load with SAPIEN's URDF loader, dropping visual shapes (there is no renderer)."""
    loader = scene.create_urdf_loader()
    loader.fix_root_link = True
    loader.scale = asset.scale
    articulation_builders, actor_builders, _ = loader.parse(str(asset.urdf))
    assert len(articulation_builders) == 1 and not actor_builders
    builder = articulation_builders[0]
    for link_builder in builder.link_builders:
        link_builder.visual_records = []
    art = builder.build()
    art.set_root_pose(sapien.Pose([0.0, 0.0, -asset.bounds_low[2] * asset.scale]))
    return art


def add_body_copy(scene, asset: FurnitureAsset):
    """A static actor with the body's (link_0) collision shapes, in the same place.

    PhysX never makes contacts between a link and its parent, so a door that cut into
    the body would go unnoticed; against this copy every overlap shows up as a contact.
    """
    loader = scene.create_urdf_loader()
    loader.fix_root_link = True
    loader.scale = asset.scale
    articulation_builders, _, _ = loader.parse(str(asset.urdf))
    (body,) = [b for b in articulation_builders[0].link_builders if b.name == "link_0"]
    builder = scene.create_actor_builder()
    builder.collision_records = list(body.collision_records)
    builder.set_initial_pose(sapien.Pose([0.0, 0.0, -asset.bounds_low[2] * asset.scale]))
    return builder.build_static(name="body_copy")


def joint_index(art, asset: FurnitureAsset) -> int:
    names = [j.name for j in art.get_active_joints()]
    return names.index(asset.target_joint)


def region_to_world(asset: FurnitureAsset, art) -> tuple[np.ndarray, np.ndarray]:
    """World pose (R (3,3), t (3,)) of the body frame."""
    pose = art.get_root_pose().to_transformation_matrix()
    return pose[:3, :3], pose[:3, 3]


@pytest.mark.parametrize("category", CATEGORIES)
def test_block_dropped_into_open_cavity_rests_inside(assets, category):
    asset = assets[category]
    scene = physics_scene()
    art = load_furniture(scene, asset)
    k = joint_index(art, asset)
    qpos = np.zeros(art.dof)
    qpos[k] = asset.open_qpos
    art.set_qpos(qpos)
    for i, joint in enumerate(art.get_active_joints()):
        joint.set_drive_property(stiffness=2000.0, damping=200.0)
        joint.set_drive_target(float(qpos[i]))

    R, t = region_to_world(asset, art)
    box = asset.in_region
    centre_world = R @ np.asarray(box.center) * asset.scale + t
    top_world = centre_world[2] + box.half_extents[2] * asset.scale
    builder = scene.create_actor_builder()
    builder.add_box_collision(half_size=[BLOCK_HALF] * 3, density=0.1 / (2 * BLOCK_HALF) ** 3)
    block = builder.build(name="block")
    start = centre_world.copy()
    start[2] = top_world - BLOCK_HALF - 0.01
    block.set_pose(sapien.Pose(start))

    for _ in range(int(2.0 / TIMESTEP)):
        scene.step()

    rigid = block.find_component_by_type(sapien.physx.PhysxRigidDynamicComponent)
    assert abs(rigid.mass - 0.1) < 1e-3
    p_world = block.get_pose().p
    p_body = R.T @ (p_world - t) / asset.scale
    assert box.contains(p_body), f"{asset.object_id}: block at {p_body.round(3)} outside in-region {box}"
    assert np.linalg.norm(rigid.linear_velocity) < 0.02, rigid.linear_velocity
    # The block rests on a floor or shelf, it did not fall through to the ground.
    assert p_world[2] > BLOCK_HALF + 0.02
    assert abs(art.get_qpos()[k] - asset.open_qpos) < 0.05


@pytest.mark.parametrize("category", CATEGORIES)
def test_closed_door_without_drive_stays_closed(assets, category):
    asset = assets[category]
    scene = physics_scene()
    art = load_furniture(scene, asset)
    k = joint_index(art, asset)
    art.set_qpos(np.zeros(art.dof))
    art.set_qvel(np.zeros(art.dof))
    for joint in art.get_active_joints():
        joint.set_drive_property(stiffness=0.0, damping=0.0)
    add_body_copy(scene, asset)
    moving = {link.name for link in art.get_links()} - {"base", "link_0"}
    deepest = 0.0
    for step in range(int(1.0 / TIMESTEP)):
        scene.step()
        if step % 24 == 0:
            for contact in scene.get_contacts():
                names = {c.entity.name for c in contact.bodies}
                # moving part vs the body copy, or two moving parts (doors, drawers)
                if ("body_copy" in names and names & moving) or len(names & moving) == 2:
                    for point in contact.points:
                        deepest = min(deepest, point.separation)
    q = art.get_qpos()
    assert np.all(np.abs(q) < 1e-3), f"{asset.object_id}: closed joints drifted to {q}"
    assert abs(q[k] - asset.closed_qpos) < 1e-3
    # Any contact between links of the closed object is a touch, not an overlap.
    assert deepest > -1e-3, f"{asset.object_id}: parts interpenetrate by {-deepest:.4f} m when closed"
