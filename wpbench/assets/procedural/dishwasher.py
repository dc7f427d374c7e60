"""Dishwashers: a tall tub with two wire racks and a bottom-hinged door (90 degrees).

A recessed toe kick runs under the door. The lower and upper racks have rims; the
door carries a control strip along its top. In-region: inside the lower rack's rims,
from the rack's floor up to the underside of the upper rack.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wpbench.assets.procedural import parts as P
from wpbench.assets.procedural.blueprint import Blueprint, ModelBuilder, choose, uniform


@dataclass(frozen=True)
class DishwasherRanges:
    width: tuple[float, float] = (0.55, 0.62)
    depth: tuple[float, float] = (0.55, 0.65)
    height: tuple[float, float] = (0.80, 0.88)
    toe_kick: tuple[float, float] = (0.08, 0.12)
    wall: tuple[float, float] = (0.02, 0.03)
    door_thickness: tuple[float, float] = (0.05, 0.07)
    lower_rack_height: tuple[float, float] = (0.05, 0.10)  # above the tub floor
    rack_gap: tuple[float, float] = (0.27, 0.32)  # lower rack floor to upper rack floor
    rim: tuple[float, float] = (0.06, 0.10)
    door_mass: tuple[float, float] = (5.0, 9.0)
    open_angle: float = round(np.pi / 2, 4)


def build(rng: np.random.Generator, object_id: str, ranges: DishwasherRanges = DishwasherRanges()) -> Blueprint:
    W, D, H = uniform(rng, *ranges.width), uniform(rng, *ranges.depth), uniform(rng, *ranges.height)
    wall, door_t = uniform(rng, *ranges.wall), uniform(rng, *ranges.door_thickness)
    kick = uniform(rng, *ranges.toe_kick)
    finish = choose(rng, (P.STAINLESS, P.WHITE, P.BLACK))
    trim = P.BLACK if finish != P.BLACK else P.MID_GREY
    gap, xf = 0.003, D / 2
    b = ModelBuilder(object_id, "dishwasher_body")

    recess = 0.05
    b.add_body(P.box_from_bounds((-D / 2, -W / 2, 0.0), (xf - recess, W / 2, kick), P.BLACK))
    walls, inside = P.open_front_shell((-D / 2, -W / 2, kick), (xf, W / 2, H), wall, wall, finish)
    b.add_body(walls, P.interior_lining(inside, P.LIGHT_GREY))

    bar, rack_t = 0.006, 0.008
    rx0, rx1 = inside[0, 0] + 0.015, inside[1, 0] - 0.02
    ry0, ry1 = inside[0, 1] + 0.01, inside[1, 1] - 0.01
    lower_z = inside[0, 2] + uniform(rng, *ranges.lower_rack_height)
    upper_z = lower_z + uniform(rng, *ranges.rack_gap)
    rim = uniform(rng, *ranges.rim)
    b.add_body(P.wire_rack((rx0, ry0, lower_z), (rx1, ry1, lower_z + rack_t), bar, 0.03, P.MID_GREY, rim_height=rim))
    b.add_body(P.wire_rack((rx0, ry0, upper_z), (rx1, ry1, upper_z + rack_t), bar, 0.03, P.MID_GREY, rim_height=min(rim, 0.06)))
    # Spray arm under the lower rack (visual: it does not hold anything).
    b.add_body(P.box_from_bounds((-0.02, ry0 + 0.08, inside[0, 2] + 0.01), (0.02, ry1 - 0.08, inside[0, 2] + 0.025), P.MID_GREY, collide=False))

    door = P.hinged_door("bottom", xf, (-W / 2, W / 2), (kick, H), door_t, gap, finish)
    strip_h = 0.07
    door_parts: list = [door.slab, P.box_from_bounds((door.outer_x, -W / 2 + 0.01, H - strip_h), (door.outer_x + 0.002, W / 2 - 0.01, H - 0.01), trim, collide=False)]
    handle_kind = choose(rng, ("bar", "bar", "recessed", "knob"))
    handle_z = H - strip_h - uniform(rng, 0.03, 0.06)
    handle = P.make_handle(handle_kind, door.outer_x, 0.0, handle_z, "y", W * uniform(rng, 0.4, 0.8), P.CHROME if finish != P.BLACK else P.MID_GREY,
                           standoff=uniform(rng, 0.03, 0.045), radius=uniform(rng, 0.008, 0.012))
    door_parts += handle.parts
    link, joint = b.add_moving(door_parts, "revolute", door.origin, door.axis, ranges.open_angle, uniform(rng, *ranges.door_mass), "hinge door")

    in_region = np.array([[rx0 + bar, ry0 + bar, lower_z + rack_t], [rx1 - bar, ry1 - bar, upper_z]])
    extra = {
        "hinge": "bottom",
        "handle_type": handle.kind,
        "handle_grasp_point": list(handle.grasp_point),
        "racks": 2,
        "wall_thickness": wall,
        "door_thickness": door_t,
    }
    return Blueprint(b.model(), link, joint, "revolute", ranges.open_angle, in_region, extra)
