"""Microwaves: a countertop box with a side-hinged door (90 degrees) and a control panel.

The shell is split by a divider into the cooking cavity and the control-panel column
(on the side away from the hinge). The door covers only the cavity column. A
turntable sits on the cavity floor. In-region: the cavity above the turntable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wpbench.assets.procedural import parts as P
from wpbench.assets.procedural.blueprint import Blueprint, ModelBuilder, choose, uniform


@dataclass(frozen=True)
class MicrowaveRanges:
    width: tuple[float, float] = (0.45, 0.60)
    depth: tuple[float, float] = (0.34, 0.45)
    height: tuple[float, float] = (0.29, 0.36)
    wall: tuple[float, float] = (0.012, 0.022)
    panel_width: tuple[float, float] = (0.09, 0.14)
    door_thickness: tuple[float, float] = (0.025, 0.045)
    foot_height: tuple[float, float] = (0.008, 0.015)
    door_mass: tuple[float, float] = (1.0, 2.0)
    open_angle: float = round(np.pi / 2, 4)


def build(rng: np.random.Generator, object_id: str, ranges: MicrowaveRanges = MicrowaveRanges()) -> Blueprint:
    W, D, H = (uniform(rng, *ranges.width), uniform(rng, *ranges.depth), uniform(rng, *ranges.height))
    wall, door_t = uniform(rng, *ranges.wall), uniform(rng, *ranges.door_thickness)
    panel_w = uniform(rng, *ranges.panel_width)
    hinge = "left" if rng.random() < 0.75 else "right"
    finish = choose(rng, (P.STAINLESS, P.WHITE, P.BLACK, P.DARK_GREY))
    trim = P.BLACK if finish != P.BLACK else P.MID_GREY
    gap, xf = 0.003, D / 2
    b = ModelBuilder(object_id, "microwave_body")

    foot_h = uniform(rng, *ranges.foot_height)
    b.add_body(P.feet((-D / 2, D / 2), (-W / 2, W / 2), foot_h, 0.03, True, P.BLACK, inset=0.02))
    walls, inside = P.open_front_shell((-D / 2, -W / 2, foot_h), (xf, W / 2, foot_h + H), wall, wall, finish)
    b.add_body(walls)
    # The control panel column sits on the side opposite the hinge.
    sign = 1.0 if hinge == "left" else -1.0  # +1: panel at +y
    panel_outer = sign * (W / 2 - wall)
    panel_inner = sign * (W / 2 - wall - panel_w)
    py0, py1 = sorted((panel_outer, panel_inner))
    b.add_body(P.box_from_bounds((inside[0, 0], py0, inside[0, 2]), (xf, py1, inside[1, 2]), finish))
    b.add_body(P.box_from_bounds((xf, py0 + 0.01, inside[1, 2] - 0.09), (xf + 0.002, py1 - 0.01, inside[1, 2] - 0.04), P.GLASS, collide=False))
    for k in range(3):
        bz = inside[1, 2] - 0.12 - 0.035 * k
        b.add_body(P.Cylinder((xf + 0.004, (py0 + py1) / 2, bz), 0.012, 0.008, "x", trim, collide=False))
    # Divider between cavity and panel column (its own convex piece).
    div = 0.01
    dy0, dy1 = (py0 - div, py0) if sign > 0 else (py1, py1 + div)
    b.add_body(P.box_from_bounds((inside[0, 0], dy0, inside[0, 2]), (xf, dy1, inside[1, 2]), P.LIGHT_GREY))
    cav_y = (inside[0, 1], dy0) if sign > 0 else (dy1, inside[1, 1])
    cavity = np.array([[inside[0, 0], cav_y[0], inside[0, 2]], [xf, cav_y[1], inside[1, 2]]])
    b.add_body(P.interior_lining(cavity, P.LIGHT_GREY))

    table_r = min(cavity[1, 0] - cavity[0, 0], cavity[1, 1] - cavity[0, 1]) / 2 - 0.02
    table_t = 0.008
    cx, cy = (cavity[0, 0] + cavity[1, 0]) / 2, (cavity[0, 1] + cavity[1, 1]) / 2
    b.add_body(P.Cylinder((cx, cy, cavity[0, 2] + table_t / 2), table_r, table_t, "z", (0.85, 0.88, 0.9, 1.0)))

    # Door spans the cavity column, from the hinge-side outer edge to the panel.
    door_y = (-W / 2, dy1) if sign > 0 else (dy0, W / 2)
    door = P.hinged_door(hinge, xf, door_y, (foot_h, foot_h + H), door_t, gap, finish if rng.random() < 0.5 else P.BLACK)
    dy_lo, dy_hi = door_y
    door_parts: list = [door.slab, P.window(door.outer_x, (dy_lo + 0.06, dy_hi - 0.07), (foot_h + 0.05, foot_h + H - 0.05))]
    handle_kind = choose(rng, ("bar", "recessed", "recessed", "knob"))
    free_y = dy_hi - 0.035 if hinge == "left" else dy_lo + 0.035
    handle = P.make_handle(handle_kind, door.outer_x, free_y, foot_h + H / 2, "z", H * uniform(rng, 0.5, 0.75), trim,
                           standoff=uniform(rng, 0.025, 0.04), radius=uniform(rng, 0.007, 0.011))
    door_parts += handle.parts
    link, joint = b.add_moving(door_parts, "revolute", door.origin, door.axis, ranges.open_angle, uniform(rng, *ranges.door_mass), "hinge door")

    in_region = cavity.copy()
    in_region[0, 2] += table_t
    extra = {
        "hinge": hinge,
        "handle_type": handle.kind,
        "handle_grasp_point": list(handle.grasp_point),
        "panel_side": "+y" if sign > 0 else "-y",
        "wall_thickness": wall,
        "door_thickness": door_t,
    }
    return Blueprint(b.model(), link, joint, "revolute", ranges.open_angle, in_region, extra)
