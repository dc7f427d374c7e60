"""SAPIEN's own PhysX defaults, pinned while an asset's physics probe builds its scene.

ManiSkill3 sets PhysX's process-wide defaults (scene, shape and body config, default
material) whenever it builds an env's scene. A probe scene built afterwards in the same
process (the load-time checks of ``wpbench.assets.partnet``) would inherit the env's
solver iterations, contact offsets and friction, so the same object could come out with a
slightly different open limit depending on whether an env had been made first.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

# SAPIEN 3's default material (static friction, dynamic friction, restitution).
DEFAULT_MATERIAL = (0.3, 0.3, 0.1)


@contextmanager
def sapien_physx_defaults() -> Iterator[None]:
    """Within the block, scenes, shapes and bodies are made with SAPIEN's own defaults;
    afterwards the process's previous defaults are back."""
    import sapien.physx as px

    saved_material = px.get_default_material()
    saved = (px.get_scene_config(), px.get_shape_config(), px.get_body_config(),
             (saved_material.static_friction, saved_material.dynamic_friction, saved_material.restitution))
    px.set_scene_config(px.PhysxSceneConfig())
    px.set_shape_config(px.PhysxShapeConfig())
    px.set_body_config(px.PhysxBodyConfig())
    px.set_default_material(*DEFAULT_MATERIAL)
    try:
        yield
    finally:
        scene, shape, body, material = saved
        px.set_scene_config(scene)
        px.set_shape_config(shape)
        px.set_body_config(body)
        px.set_default_material(*material)
