"""Ovens: a free-standing range with a bottom-hinged door that opens 90 degrees.

Layout from the floor up: optional feet, a solid plinth (drawn with a storage-drawer
front), the oven shell (five walls, open at the front, maybe one wire rack), the
cooktop with burners, maybe a backguard with knobs. The door covers the shell front.
In-region: the cavity above the rack (or above the oven floor when there is no rack).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wpbench.assets.procedural import parts as P
from wpbench.assets.procedural.blueprint import Blueprint, ModelBuilder, choose, uniform


@dataclass(frozen=True)
class OvenRanges:
    """Per-instance ranges (metres unless said otherwise)."""

    width: tuple[float, float] = (0.56, 0.78)
    depth: tuple[float, float] = (0.55, 0.68)
    plinth_height: tuple[float, float] = (0.10, 0.24)
    shell_height: tuple[float, float] = (0.44, 0.58)
    wall: tuple[float, float] = (0.02, 0.04)
    door_thickness: tuple[float, float] = (0.03, 0.06)
    cooktop_thickness: tuple[float, float] = (0.03, 0.05)
    backguard_height: tuple[float, float] = (0.06, 0.18)
    door_mass: tuple[float, float] = (4.0, 8.0)
    open_angle: float = round(np.pi / 2, 4)


def build(rng: np.random.Generator, object_id: str, ranges: OvenRanges = OvenRanges()) -> Blueprint:
    W, D = uniform(rng, *ranges.width), uniform(rng, *ranges.depth)
    wall, door_t = uniform(rng, *ranges.wall), uniform(rng, *ranges.door_thickness)
    finish = choose(rng, (P.STAINLESS, P.WHITE, P.BLACK))
    trim = P.BLACK if finish != P.BLACK else P.DARK_GREY
    gap = 0.003
    xf = D / 2  # front plane of the body
    b = ModelBuilder(object_id, "oven_body")

    foot_h = uniform(rng, 0.02, 0.05) if rng.random() < 0.5 else 0.0
    if foot_h > 0:
        b.add_body(P.feet((-D / 2, D / 2), (-W / 2, W / 2), foot_h, 0.04, bool(rng.random() < 0.5), P.BLACK))
    plinth_top = foot_h + uniform(rng, *ranges.plinth_height)
    b.add_body(P.box_from_bounds((-D / 2, -W / 2, foot_h), (xf, W / 2, plinth_top), finish))
    # The storage drawer front under the oven (part of the body: drawn, not movable).
    b.add_body(P.box_from_bounds((xf, -W / 2 + 0.01, foot_h + 0.01), (xf + 0.002, W / 2 - 0.01, plinth_top - 0.01), trim, collide=False))

    shell_top = plinth_top + uniform(rng, *ranges.shell_height)
    walls, inside = P.open_front_shell((-D / 2, -W / 2, plinth_top), (xf, W / 2, shell_top), wall, wall, finish)
    b.add_body(walls, P.interior_lining(inside, P.DARK_GREY))
    cook_top = shell_top + uniform(rng, *ranges.cooktop_thickness)
    b.add_body(P.box_from_bounds((-D / 2, -W / 2, shell_top), (xf, W / 2, cook_top), finish))
    burner_r = min(W, D) * uniform(rng, 0.12, 0.16)
    for bx in (-D / 4, D / 4 - 0.02):
        for by in (-W / 4, W / 4):
            b.add_body(P.Cylinder((bx, by, cook_top + 0.004), burner_r, 0.008, "z", P.BLACK, collide=False))
    has_backguard = bool(rng.random() < 0.6)
    if has_backguard:
        guard_top = cook_top + uniform(rng, *ranges.backguard_height)
        guard_x = -D / 2 + 0.05
        b.add_body(P.box_from_bounds((-D / 2, -W / 2, cook_top), (guard_x, W / 2, guard_top), finish))
        for ky in np.linspace(-W / 2 + 0.08, W / 2 - 0.08, 4):
            b.add_body(P.Cylinder((guard_x + 0.012, float(ky), (cook_top + guard_top) / 2), 0.018, 0.024, "x", trim))

    # Rack: only when the space above it still fits a 16 cm block with margin.
    inner_h = inside[1, 2] - inside[0, 2]
    floor_z = inside[0, 2]
    has_rack = inner_h - 0.26 > 0.08 and rng.random() < 0.7
    if has_rack:
        rack_z = floor_z + uniform(rng, 0.08, inner_h - 0.26)
        lo = (inside[0, 0] + 0.01, inside[0, 1] + 0.005, rack_z)
        hi = (inside[1, 0] - 0.02, inside[1, 1] - 0.005, rack_z + 0.008)
        b.add_body(P.wire_rack(lo, hi, 0.006, 0.04, P.CHROME))
        floor_z = rack_z + 0.008

    door = P.hinged_door("bottom", xf, (-W / 2, W / 2), (plinth_top, shell_top), door_t, gap, finish)
    door_h = shell_top - plinth_top
    door_parts: list = [door.slab]
    door_parts.append(P.window(door.outer_x, (-W / 2 + 0.1, W / 2 - 0.1), (plinth_top + 0.1 * door_h, shell_top - 0.25 * door_h)))
    handle_kind = choose(rng, ("bar", "bar", "bar", "recessed", "knob"))
    handle_z = shell_top - uniform(rng, 0.04, 0.08)
    if handle_kind == "knob":
        handle_z = shell_top - 0.06
    handle = P.make_handle(handle_kind, door.outer_x, 0.0, handle_z, "y", W * uniform(rng, 0.6, 0.85), trim if finish != P.STAINLESS else P.CHROME,
                           standoff=uniform(rng, 0.035, 0.05), radius=uniform(rng, 0.008, 0.013))
    door_parts += handle.parts
    link, joint = b.add_moving(door_parts, "revolute", door.origin, door.axis, ranges.open_angle, uniform(rng, *ranges.door_mass), "hinge door")

    in_region = np.array([[inside[0, 0], inside[0, 1], floor_z], inside[1]])
    extra = {
        "style": "range",
        "hinge": "bottom",
        "handle_type": handle.kind,
        "handle_grasp_point": list(handle.grasp_point),
        "has_rack": has_rack,
        "has_feet": foot_h > 0,
        "has_backguard": has_backguard,
        "wall_thickness": wall,
        "door_thickness": door_t,
    }
    return Blueprint(b.model(), link, joint, "revolute", ranges.open_angle, in_region, extra)
