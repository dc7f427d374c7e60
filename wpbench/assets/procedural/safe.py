"""Safes: thick-walled boxes with a heavy, thick side-hinged door (90 to 110 degrees).

The door carries a combination dial (drawn) and a handle; the inside may have one
shelf. In-region: the taller of the compartments (the whole inside without a shelf).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wpbench.assets.procedural import parts as P
from wpbench.assets.procedural.blueprint import Blueprint, ModelBuilder, choose, uniform


@dataclass(frozen=True)
class SafeRanges:
    width: tuple[float, float] = (0.38, 0.60)
    depth: tuple[float, float] = (0.38, 0.55)
    height: tuple[float, float] = (0.40, 0.80)
    wall: tuple[float, float] = (0.03, 0.06)
    door_thickness: tuple[float, float] = (0.05, 0.10)
    foot_height: tuple[float, float] = (0.02, 0.05)
    open_angle_deg: tuple[float, float] = (100.0, 100.0)  # a fixed door stop: see FridgeRanges.open_angle_deg
    door_mass: tuple[float, float] = (8.0, 15.0)
    min_compartment: float = 0.23


def build(rng: np.random.Generator, object_id: str, ranges: SafeRanges = SafeRanges()) -> Blueprint:
    W, D, H = uniform(rng, *ranges.width), uniform(rng, *ranges.depth), uniform(rng, *ranges.height)
    wall, door_t = uniform(rng, *ranges.wall), uniform(rng, *ranges.door_thickness)
    hinge = "left" if rng.random() < 0.5 else "right"
    finish = choose(rng, (P.DARK_GREY, P.BLACK, (0.20, 0.27, 0.22, 1.0), (0.55, 0.55, 0.50, 1.0)))
    metal = P.CHROME
    gap, xf = 0.003, D / 2
    b = ModelBuilder(object_id, "safe_body")

    foot_h = uniform(rng, *ranges.foot_height) if rng.random() < 0.5 else 0.0
    if foot_h > 0:
        b.add_body(P.feet((-D / 2, D / 2), (-W / 2, W / 2), foot_h, 0.05, False, P.BLACK, inset=0.01))
    walls, inside = P.open_front_shell((-D / 2, -W / 2, foot_h), (xf, W / 2, foot_h + H), wall, wall, finish)
    b.add_body(walls)
    # A lighter lining makes the cavity readable in renders (visual only, on the walls).
    lining = (0.62, 0.52, 0.40, 1.0)
    b.add_body(P.interior_lining(inside, lining))

    lo, hi = inside[0, 2], inside[1, 2]
    has_shelf = (hi - lo) >= 2 * ranges.min_compartment + 0.02 and rng.random() < 0.6
    if has_shelf:
        shelf_t = 0.012
        z = round(lo + float(rng.uniform(ranges.min_compartment, hi - lo - ranges.min_compartment - shelf_t)), 4)
        b.add_body(P.box_from_bounds((inside[0, 0], inside[0, 1], z), (xf - 0.02, inside[1, 1], z + shelf_t), finish))
        lo, hi = (lo, z) if z - lo >= hi - (z + shelf_t) else (z + shelf_t, hi)

    door = P.hinged_door(hinge, xf, (-W / 2, W / 2), (foot_h, foot_h + H), door_t, gap, finish)
    door_parts: list = [door.slab]
    fx = door.outer_x
    # Free side of the door: handle near it, dial towards the middle.
    free_sign = 1.0 if hinge == "left" else -1.0
    mid_z = foot_h + H * uniform(rng, 0.5, 0.6)
    dial_y = free_sign * W * 0.05
    door_parts.append(P.Cylinder((fx + 0.01, dial_y, mid_z + 0.05), 0.035, 0.02, "x", metal, collide=False))
    door_parts.append(P.box_from_bounds((fx, dial_y - 0.04, mid_z - 0.11), (fx + 0.004, dial_y + 0.04, mid_z - 0.03), P.BLACK, collide=False))
    handle_kind = choose(rng, ("bar", "knob", "knob", "recessed"))
    handle_y = free_sign * (W / 2 - uniform(rng, 0.06, 0.1))
    handle = P.make_handle(handle_kind, fx, handle_y, mid_z, "z", min(0.2, H * 0.35), metal,
                           standoff=uniform(rng, 0.04, 0.06), radius=uniform(rng, 0.01, 0.015))
    door_parts += handle.parts
    open_angle = round(float(np.deg2rad(rng.uniform(*ranges.open_angle_deg))), 4)
    link, joint = b.add_moving(door_parts, "revolute", door.origin, door.axis, open_angle, uniform(rng, *ranges.door_mass), "hinge door")

    in_region = np.array([[inside[0, 0], inside[0, 1], lo], [xf, inside[1, 1], hi]])
    extra = {
        "hinge": hinge,
        "handle_type": handle.kind,
        "handle_grasp_point": list(handle.grasp_point),
        "has_shelf": bool(has_shelf),
        "has_feet": foot_h > 0,
        "wall_thickness": wall,
        "door_thickness": door_t,
    }
    return Blueprint(b.model(), link, joint, "revolute", open_angle, in_region, extra)
