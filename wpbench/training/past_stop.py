"""Door goals turned past the stop: a training target for doors whose stop no cloud shows.

A side-hinged door's stop sits in its hinge, so a model can only guess it from the kind of
furniture and regresses to the middle of the stops it was trained on. A door whose stop
lies beyond that guess is left short of open, while a door driven past its stop is held
there by every executor (the ``ideal`` one clamps to the joint limits; a hand stalls
against the stop and lets go). With ``degrees`` > 0, :func:`turn_doors_past_stop` turns
the goal of every side-hinged door sample that much further about its own hinge, so the
model learns to aim past the stop and the door ends at it. ``max_turn_deg`` caps the
turned goal's whole turn, so a door whose stop is already wide (a fridge at 150 deg) is not
aimed where an arm following its handle cannot reach; a goal already beyond the cap is
left as it is.

Left as they are: drawers (no rotation), and doors hinged at the bottom (ovens,
dishwashers; hinge more than ``MAX_HINGE_TILT_DEG`` from vertical). Those open down to
the horizontal, where real ones stop as well, and turned further their far edge heads for
the floor, where a hand following it is refused (the gripper's path under the floor).

The screw of each goal (hinge axis, point, angle, slide) comes from
``wpbench.sim.screw_path``; the goal at fraction ``(angle + extra) / angle`` of that screw
is the door turned ``extra`` further about the same hinge.
"""

from __future__ import annotations

import numpy as np
import torch

from wpbench.names import ARTICULATED, KIND_CODE
from wpbench.sim.screw_path import screw_at, screw_of

# A goal that turns less than this is a drawer's slide (or a door already at its stop),
# whose hinge cannot be read from the goal: it is left as it is.
MIN_DOOR_TURN_DEG = 1.0
# A hinge within this angle of vertical is a side hinge; the rest are top or bottom hinges.
MAX_HINGE_TILT_DEG = 30.0


def turn_doors_past_stop(gt_transform: torch.Tensor, gt_equivalents: torch.Tensor, kind: torch.Tensor,
                         degrees: float, max_turn_deg: float | None = None) -> tuple[torch.Tensor, torch.Tensor, int]:
    """Every articulated goal that turns by at least ``MIN_DOOR_TURN_DEG`` about a side hinge
    (within ``MAX_HINGE_TILT_DEG`` of the world's z axis), turned ``degrees`` further, but to a
    whole turn of at most ``max_turn_deg`` (None: no cap; a goal already at or beyond the cap
    is not turned).

    gt_transform (N, 4, 4), gt_equivalents (N, K, 4, 4) (an articulated sample's rows all
    repeat its goal), kind (N,) codes of ``wpbench.data.config.KIND_CODE`` ->
    (new gt_transform, new gt_equivalents, number of goals turned), in the input dtypes.
    ``degrees`` must be in [0, 90) and ``max_turn_deg`` in (0, 180].
    """
    if not 0.0 <= degrees < 90.0:
        raise ValueError(f"degrees past the stop must be in [0, 90), got {degrees}")
    if max_turn_deg is not None and not 0.0 < max_turn_deg <= 180.0:
        raise ValueError(f"max_turn_deg must be in (0, 180], got {max_turn_deg}")
    if gt_transform.dim() != 3 or gt_transform.shape[1:] != (4, 4):
        raise ValueError(f"gt_transform must have shape (N, 4, 4), got {tuple(gt_transform.shape)}")
    N = gt_transform.shape[0]
    if gt_equivalents.dim() != 4 or gt_equivalents.shape[0] != N or gt_equivalents.shape[2:] != (4, 4):
        raise ValueError(f"gt_equivalents must have shape (N, K, 4, 4) with N = {N}, got {tuple(gt_equivalents.shape)}")
    if kind.shape != (N,):
        raise ValueError(f"kind must have shape (N,) with N = {N}, got {tuple(kind.shape)}")
    goals, table = gt_transform.clone(), gt_equivalents.clone()
    if degrees == 0.0:
        return goals, table, 0
    extra = np.deg2rad(degrees)
    cap = np.inf if max_turn_deg is None else np.deg2rad(max_turn_deg)
    turned = 0
    for i in torch.nonzero(kind == KIND_CODE[ARTICULATED]).flatten().tolist():
        screw = screw_of(gt_transform[i].double().numpy())
        if np.rad2deg(screw.angle) < MIN_DOOR_TURN_DEG:
            continue
        if abs(screw.axis[2]) < np.cos(np.deg2rad(MAX_HINGE_TILT_DEG)):
            continue
        target = min(screw.angle + extra, cap)
        if target <= screw.angle + 1e-9:        # at the cap already, up to rounding
            continue
        further = torch.from_numpy(screw_at(screw, target / screw.angle)).to(goals.dtype)
        goals[i] = further
        table[i] = further
        turned += 1
    return goals, table, turned
