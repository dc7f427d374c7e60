"""Render a furniture asset closed and open, side by side, with a SAPIEN camera.

Needs SAPIEN's Vulkan renderer (Mesa lavapipe on CPU machines). The camera looks at
the object's front (``asset.front``: +x for the built-in furniture, whatever way the
door faces for a PartNet-Mobility object) from the front-right and a little above, so
the door, its handle and the cavity behind it are visible; the in-region is drawn as
a translucent green box in the open view.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wpbench.assets.spec import FurnitureAsset, rest_joint_values


@dataclass(frozen=True)
class RenderConfig:
    width: int = 480
    height: int = 480
    fovy_deg: float = 40.0
    azimuth_deg: float = 35.0  # camera direction from the asset's front, turned towards its left
    elevation_deg: float = 25.0
    distance_factor: float = 3.4  # camera distance / object bounding-sphere radius
    show_in_region: bool = True


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """4x4 camera pose in SAPIEN's camera convention (x forward, y left, z up)."""
    forward = target - eye
    forward = forward / np.linalg.norm(forward)
    left = np.cross(np.asarray(up, float), forward)
    left = left / np.linalg.norm(left)
    true_up = np.cross(forward, left)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([forward, left, true_up], axis=1)
    pose[:3, 3] = eye
    return pose


def camera_direction(front, config: RenderConfig = RenderConfig()) -> np.ndarray:
    """Unit vector from the object's centre to the camera: ``config.azimuth_deg`` away from
    the asset's ``front`` (body frame, horizontal part used), ``config.elevation_deg`` above."""
    front = np.asarray(front, float)
    if not np.all(np.isfinite(front)) or np.hypot(front[0], front[1]) < 1e-9:
        raise ValueError(f"asset front must have a horizontal direction, got {front.tolist()}")
    az = np.arctan2(front[1], front[0]) + np.deg2rad(config.azimuth_deg)
    el = np.deg2rad(config.elevation_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def render_states(asset: FurnitureAsset, qpos_values: list[float], config: RenderConfig = RenderConfig()) -> list[np.ndarray]:
    """One (H, W, 3) uint8 image per value of the target joint (other joints closed)."""
    import sapien

    scene = sapien.Scene()  # default systems: physics + the Vulkan renderer
    scene.set_ambient_light([0.45, 0.45, 0.45])
    scene.add_directional_light([-0.4, -0.6, -1.0], [0.9, 0.9, 0.9], shadow=False)
    scene.add_point_light([2.0, 1.5, 2.5], [2.0, 2.0, 2.0])
    ground = sapien.render.RenderMaterial(base_color=[0.42, 0.43, 0.45, 1.0])
    scene.add_ground(0.0, render_material=ground)

    loader = scene.create_urdf_loader()
    loader.fix_root_link = True
    loader.scale = float(asset.scale)
    art = loader.load(str(asset.urdf))
    if art is None:
        raise RuntimeError(f"SAPIEN could not load {asset.urdf}")
    lift = -float(asset.bounds_low[2])
    art.set_root_pose(sapien.Pose([0.0, 0.0, lift]))
    names = [j.name for j in art.get_active_joints()]
    if asset.target_joint not in names:
        raise ValueError(f"{asset.object_id}: target joint {asset.target_joint} not among active joints {names}")
    index = names.index(asset.target_joint)

    low, high = np.asarray(asset.bounds_low, float), np.asarray(asset.bounds_high, float)
    centre = (low + high) / 2 + np.array([0.0, 0.0, lift])
    radius = float(np.linalg.norm(high - low)) / 2
    eye = centre + camera_direction(asset.front, config) * radius * config.distance_factor
    camera = scene.add_camera("viewer", config.width, config.height, np.deg2rad(config.fovy_deg), 0.02, 50.0)
    camera.entity.set_pose(sapien.Pose(look_at(eye, centre)))

    # Other joints rest closed, as in the simulator.
    limits = np.array([j.get_limits()[0] for j in art.get_active_joints()], dtype=float)
    rest = rest_joint_values(asset, names, limits)
    region_entity = None
    images = []
    for q in qpos_values:
        qpos = rest.copy()
        qpos[index] = q
        art.set_qpos(qpos)
        show_region = config.show_in_region and np.isclose(q, asset.open_qpos)
        if show_region and region_entity is None:
            region_entity = _add_region_box(scene, asset, lift)
        if region_entity is not None:
            region_entity.find_component_by_type(sapien.render.RenderBodyComponent).visibility = 1.0 if show_region else 0.0
        scene.update_render()
        camera.take_picture()
        rgba = camera.get_picture("Color")  # (H, W, 4) float in [0, 1]
        images.append((np.clip(rgba[..., :3], 0, 1) * 255).astype(np.uint8))
    return images


def _add_region_box(scene, asset: FurnitureAsset, lift: float):
    """A translucent green box showing the in-region (visual only, no collision)."""
    import sapien

    box = asset.in_region
    rotation = np.asarray(box.rotation, float)
    pose = np.eye(4)
    pose[:3, :3] = rotation
    # The in-region is stored in the scaled body frame (as the simulator uses it): no asset.scale here.
    pose[:3, 3] = np.asarray(box.center, float) + np.array([0.0, 0.0, lift])
    builder = scene.create_actor_builder()
    material = sapien.render.RenderMaterial(base_color=[0.1, 0.9, 0.2, 0.35])
    builder.add_box_visual(half_size=list(np.asarray(box.half_extents, float)), material=material)
    entity = builder.build_kinematic(name="in_region")
    entity.set_pose(sapien.Pose(pose))
    return entity


def render_closed_open(asset: FurnitureAsset, out: Path, config: RenderConfig = RenderConfig()) -> Path:
    """Write a PNG: the asset closed (left) and fully open (right), with a caption."""
    from PIL import Image, ImageDraw

    closed, opened = render_states(asset, [asset.closed_qpos, asset.open_qpos], config)
    canvas = Image.new("RGB", (closed.shape[1] * 2, closed.shape[0] + 24), (255, 255, 255))
    canvas.paste(Image.fromarray(closed), (0, 24))
    canvas.paste(Image.fromarray(opened), (closed.shape[1], 24))
    draw = ImageDraw.Draw(canvas)
    draw.text((6, 5), f"{asset.object_id} ({asset.category}) closed", fill=(0, 0, 0))
    draw.text((closed.shape[1] + 6, 5), f"open {asset.target_joint}={asset.open_qpos:.3f}, green = in-region", fill=(0, 0, 0))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(out)
    return out
