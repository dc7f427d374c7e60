"""Pure-torch geometry: SE(3) helpers, weighted Procrustes / WeightedPose SVD, pose metrics, symmetry groups.

Conventions (docs/design.md): 4x4 homogeneous transforms on column vectors,
``p' = R p + t``; quaternions (w, x, y, z); point clouds (B, N, 3) in the
world frame. Nothing here imports the simulator.
"""

from wpbench.geometry.metrics import (
    point_error,
    raw_translation_error,
    rotation_angle,
    rotation_error_deg,
    translation_error,
)
from wpbench.geometry.procrustes import dual_flow_svd, weighted_pose_svd, weighted_procrustes
from wpbench.geometry.se3 import (
    apply,
    compose,
    invert,
    make_transform,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
    random_rotation,
)
from wpbench.geometry.symmetry import Symmetry

__all__ = [
    "Symmetry",
    "apply",
    "compose",
    "dual_flow_svd",
    "invert",
    "make_transform",
    "matrix_to_quat_wxyz",
    "point_error",
    "quat_wxyz_to_matrix",
    "random_rotation",
    "raw_translation_error",
    "rotation_angle",
    "rotation_error_deg",
    "translation_error",
    "weighted_pose_svd",
    "weighted_procrustes",
]
