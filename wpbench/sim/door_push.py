"""Finishing a door by pushing it, for a door whose face an arm cannot follow to the end.

A suction cup on a door's outer face turns with the door. For a door hinged at its
bottom (an oven, a dishwasher) the face ends up looking down near the floor: the hand
would point up from under the door, and the arm's wrist (WRIST_OFFSET behind the TCP
along the approach) would have to be under the floor. So the arm pulls the door by its
face until the face's approach points HANDOVER_ELEVATION_DEG up, lets go, comes round to
the door's inner side, and pushes the rest of the predicted screw with the hand turned
to face the door: the same point of the door, PUSH_INSET behind its observed outer face
(the door's thickness is not observed; a thicker door is pushed that much further, to
its stop at the most).

Everything comes from the grasp on the observed door cloud and the predicted cross-pose. Pure numpy.
"""

from __future__ import annotations

import numpy as np

from wpbench.sim.screw_path import interpolate, screw_of

WRIST_OFFSET = 0.21              # m, TCP to the Panda's joint-6 axis along the approach (hand + link7)
WRIST_MIN_HEIGHT = 0.12          # m, a wrist lower than this (link6 and its clearance) would meet the floor
HANDOVER_ELEVATION_DEG = 45.0    # the face grasp hands over once its approach points this far up
MIN_HANDOVER = 0.15              # fraction of the screw: no handover earlier than this ...
MAX_HANDOVER = 0.85              # ... or later
PUSH_INSET = 0.03                # m, the pushing TCP runs this far behind the observed outer face
MIN_TURN = np.radians(10.0)      # a screw turning less than this (a drawer) is never pushed
SAMPLES = 101


def handover_fraction(cross_pose: np.ndarray, face_tcp: np.ndarray) -> float | None:
    """The fraction s of the predicted screw at which the arm lets go of the face grasp
    ``face_tcp`` (4, 4; z the approach) and pushes instead, or None when the wrist stays
    above WRIST_MIN_HEIGHT all along the face path (no push needed)."""
    if screw_of(cross_pose).angle < MIN_TURN:
        return None
    s = np.linspace(0.0, 1.0, SAMPLES)
    poses = interpolate(cross_pose, s) @ face_tcp
    wrist_z = poses[:, 2, 3] - WRIST_OFFSET * poses[:, 2, 2]
    if wrist_z.min() >= WRIST_MIN_HEIGHT:
        return None
    steep = np.flatnonzero(poses[:, 2, 2] >= np.sin(np.radians(HANDOVER_ELEVATION_DEG)))
    u = s[steep[0]] if len(steep) else MAX_HANDOVER
    return float(np.clip(u, MIN_HANDOVER, MAX_HANDOVER))


def push_grip(face_tcp: np.ndarray) -> np.ndarray:
    """(4, 4) the pushing TCP in the door's frame: the face grasp's point moved PUSH_INSET
    through the door, the hand turned half a turn about its y axis to face the inner side."""
    T = face_tcp.copy()
    T[:3, 3] += PUSH_INSET * face_tcp[:3, 2]
    T[:3, 0] *= -1.0
    T[:3, 2] *= -1.0
    return T
