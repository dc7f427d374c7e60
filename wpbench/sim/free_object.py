"""Build a Ravens object (block, ell, disk, ...) as a dynamic SAPIEN actor.

Meshes are written once per object to a cache folder and loaded by file, because
SAPIEN's builders take convex collision pieces from files; the per-episode scale
is passed to the builder, so one set of files serves every scale.
"""

from __future__ import annotations

import os
from pathlib import Path

import sapien

from wpbench.assets.library import cache_root


def _mesh_files(obj) -> tuple[Path, list[Path]]:
    """Unit-scale visual and convex collision meshes of a RavensObject, as .obj files."""
    folder = cache_root() / "ravens" / obj.name
    visual = folder / "visual.obj"
    parts = obj.collision_parts(1.0)
    part_files = [folder / f"collision_{k}.obj" for k in range(len(parts))]
    if not (visual.exists() and all(p.exists() for p in part_files)):
        tmp = folder.with_name(f".{obj.name}.tmp-{os.getpid()}")
        tmp.mkdir(parents=True, exist_ok=True)
        obj.visual_mesh(1.0).export(tmp / "visual.obj")
        for k, part in enumerate(parts):
            part.export(tmp / f"collision_{k}.obj")
        folder.parent.mkdir(parents=True, exist_ok=True)
        if folder.exists():  # another process won the race; its files are the same
            for f in tmp.iterdir():
                f.unlink()
            tmp.rmdir()
        else:
            tmp.rename(folder)
    return visual, part_files


def build_free_object(scene, obj, scale: float, name: str = "free_object"):
    """Add ``obj`` (a RavensObject) at ``scale`` to a ManiSkill scene; returns the ManiSkill Actor.

    Its mass is the Ravens mass whatever the scale (TAX-Pose scales only the shape).
    """
    visual, parts = _mesh_files(obj)
    volume = float(obj.visual_mesh(1.0).volume) * scale**3
    density = obj.mass / max(volume, 1e-9)
    builder = scene.create_actor_builder()
    material = sapien.pysapien.physx.PhysxMaterial(static_friction=0.8, dynamic_friction=0.6, restitution=0.0)
    for part in parts:
        builder.add_convex_collision_from_file(str(part), scale=[scale] * 3, material=material, density=density)
    render_material = sapien.render.RenderMaterial(base_color=list(obj.rgba))
    builder.add_visual_from_file(str(visual), scale=[scale] * 3, material=render_material)
    builder.initial_pose = sapien.Pose(p=[0.0, 0.0, 5.0])
    return builder.build(name=name)


def raw_body(actor):
    """The physx rigid body behind a ManiSkill Actor (single CPU scene)."""
    entity = actor._objs[0]
    from sapien import physx

    return entity.find_component_by_type(physx.PhysxRigidDynamicComponent)
