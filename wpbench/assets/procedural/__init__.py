"""Procedural articulated furniture written in PartNet-Mobility's on-disk format.

Nothing can be downloaded at run time, so wpbench makes its own ovens, microwaves,
dishwashers, fridges, safes and chests of drawers. ``writer`` turns a model made of
boxes and cylinders into ``mobility.urdf`` + meshes + ``semantics.txt``; ``parts``
holds the shared building blocks; one module per category draws an instance from a
numpy Generator; ``generate`` writes objects, ``wpbench.json`` and the train/val/test split.
"""

from wpbench.assets.procedural.generate import (
    CATEGORIES,
    GENERATOR_VERSION,
    TEST_FIRST_INDEX,
    TEST_PER_CATEGORY,
    build_blueprint,
    generate_library,
    generate_object,
)

__all__ = ["CATEGORIES", "GENERATOR_VERSION", "TEST_FIRST_INDEX", "TEST_PER_CATEGORY", "build_blueprint", "generate_library", "generate_object"]
