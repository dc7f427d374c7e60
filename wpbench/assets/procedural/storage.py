"""Storage furniture: a chest of drawers (one or two columns) on a plinth or legs.

Each drawer is a prismatic link: an overlay front panel plus an open box (bottom,
two sides, back) that slides along +x. The open limit is a fixed fraction (0.8) of
the drawer box's depth, so an open drawer stays on its runners.

What "in" means for a drawer: the drawer box moves, so the in-region is defined in
the *open* state (target joint at ``open_qpos``) as the part of the drawer's inside
that has come out of the carcass, i.e. in front of the neighbouring drawer fronts,
where an object can be dropped in from above. It runs from the drawer's floor to
the top of its side walls.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wpbench.assets.procedural import parts as P
from wpbench.assets.procedural.blueprint import Blueprint, ModelBuilder, choose, uniform


@dataclass(frozen=True)
class StorageRanges:
    width: tuple[float, float] = (0.50, 1.00)
    depth: tuple[float, float] = (0.42, 0.60)
    height: tuple[float, float] = (0.50, 1.20)
    wall: tuple[float, float] = (0.015, 0.025)
    front_thickness: tuple[float, float] = (0.015, 0.025)
    drawer_wall: tuple[float, float] = (0.008, 0.014)
    plinth_height: tuple[float, float] = (0.04, 0.10)
    leg_height: tuple[float, float] = (0.08, 0.16)
    open_fraction: tuple[float, float] = (0.80, 0.80)  # a fixed stop, unseen by the camera: see FridgeRanges.open_angle_deg
    drawer_mass: tuple[float, float] = (1.5, 4.0)
    min_opening: float = 0.25  # drawer opening height: a 16 cm block + drawer floor + margin


def build(rng: np.random.Generator, object_id: str, ranges: StorageRanges = StorageRanges()) -> Blueprint:
    W, D, H = uniform(rng, *ranges.width), uniform(rng, *ranges.depth), uniform(rng, *ranges.height)
    wall = uniform(rng, *ranges.wall)
    front_t = uniform(rng, *ranges.front_thickness)
    dwall = uniform(rng, *ranges.drawer_wall)
    wood = choose(rng, P.WOODS + (P.WHITE, P.DARK_GREY))
    front_colour = wood if rng.random() < 0.6 else choose(rng, P.WOODS + (P.WHITE,))
    metal = choose(rng, (P.CHROME, P.BLACK, (0.70, 0.55, 0.25, 1.0)))
    gap, xf = 0.003, D / 2
    b = ModelBuilder(object_id, "furniture_body")

    on_legs = bool(rng.random() < 0.4)
    if on_legs:
        base_h = uniform(rng, *ranges.leg_height)
        b.add_body(P.feet((-D / 2, D / 2), (-W / 2, W / 2), base_h, 0.04, bool(rng.random() < 0.5), wood, inset=0.01))
    else:
        base_h = uniform(rng, *ranges.plinth_height)
        b.add_body(P.box_from_bounds((-D / 2 + 0.02, -W / 2 + 0.02, 0.0), (xf - 0.03, W / 2 - 0.02, base_h), wood))
    walls, inside = P.open_front_shell((-D / 2, -W / 2, base_h), (xf, W / 2, base_h + H), wall, wall * 0.6, wood)
    b.add_body(walls)

    inner_h = inside[1, 2] - inside[0, 2]
    rows_max = int((inner_h + wall) // (ranges.min_opening + wall))
    if rows_max < 1:
        raise ValueError(f"{object_id}: {inner_h:.3f} m inside is too low for one drawer")
    rows = int(rng.integers(max(1, min(2, rows_max)), rows_max + 1))
    columns = 2 if (W >= 0.8 and rng.random() < 0.5) else 1

    # Openings: rows x columns, separated by dividers as thick as the walls.
    row_h = (inner_h - (rows - 1) * wall) / rows
    col_w = (inside[1, 1] - inside[0, 1] - (columns - 1) * wall) / columns
    for r in range(1, rows):
        z = inside[0, 2] + r * row_h + (r - 1) * wall
        b.add_body(P.box_from_bounds((inside[0, 0], inside[0, 1], z), (xf, inside[1, 1], z + wall), wood))
    for c in range(1, columns):
        y = inside[0, 1] + c * col_w + (c - 1) * wall
        for r in range(rows):
            z = inside[0, 2] + r * (row_h + wall)
            b.add_body(P.box_from_bounds((inside[0, 0], y, z), (xf, y + wall, z + row_h), wood))

    handle_kind = choose(rng, P.HANDLE_KINDS)
    open_fraction = uniform(rng, *ranges.open_fraction)
    box_depth = round(inside[1, 0] - inside[0, 0] - 0.02, 4)
    open_q = round(open_fraction * box_depth, 4)
    target_index = int(rng.integers(rows * columns))
    drawers = []
    half = wall / 2 - 0.002  # overlay fronts cover half a divider, leaving 4 mm between fronts
    for r in range(rows):
        for c in range(columns):
            oz0 = inside[0, 2] + r * (row_h + wall)
            oy0 = inside[0, 1] + c * (col_w + wall)
            oz1, oy1 = oz0 + row_h, oy0 + col_w
            fz0 = oz0 - (wall - 0.002 if r == 0 else half)
            fz1 = oz1 + (wall - 0.002 if r == rows - 1 else half)
            fy0 = oy0 - (wall - 0.002 if c == 0 else half)
            fy1 = oy1 + (wall - 0.002 if c == columns - 1 else half)
            x_in = xf + gap  # back face of the front panel
            front = P.box_from_bounds((x_in, fy0, fz0), (x_in + front_t, fy1, fz1), front_colour)
            # The box sits inside the opening with running clearance on every side.
            bx0, bx1 = x_in - box_depth, x_in
            by0, by1 = oy0 + 0.006, oy1 - 0.006
            bz0, bz1 = oz0 + 0.004, oz1 - 0.015
            box = [
                P.box_from_bounds((bx0, by0, bz0), (bx1, by1, bz0 + dwall), wood),  # floor
                P.box_from_bounds((bx0, by0, bz0 + dwall), (bx1, by0 + dwall, bz1), wood),
                P.box_from_bounds((bx0, by1 - dwall, bz0 + dwall), (bx1, by1, bz1), wood),
                P.box_from_bounds((bx0, by0 + dwall, bz0 + dwall), (bx0 + dwall, by1 - dwall, bz1), wood),  # back
            ]
            face_x = x_in + front_t
            hz = (fz0 + fz1) / 2 if rng.random() < 0.5 else fz1 - min(0.06, (fz1 - fz0) / 4)
            handle = P.make_handle(handle_kind, face_x, (fy0 + fy1) / 2, hz, "y", min(0.3, (fy1 - fy0) * 0.5), metal,
                                   standoff=0.03, radius=0.007)
            origin = (face_x, (fy0 + fy1) / 2, (fz0 + fz1) / 2)
            link, joint = b.add_moving([front, *box, *handle.parts], "prismatic", origin, (1.0, 0.0, 0.0), open_q,
                                       uniform(rng, *ranges.drawer_mass), "slider drawer")
            drawers.append((link, joint, handle, (bx0, bx1, by0, by1, bz0, bz1), face_x))

    link, joint, handle, (bx0, bx1, by0, by1, bz0, bz1), face_x = drawers[target_index]
    # Open-state inside of the drawer, in front of the closed neighbours' fronts.
    in_region = np.array([
        [face_x, by0 + dwall, bz0 + dwall],
        [bx1 + open_q, by1 - dwall, bz1],
    ])
    extra = {
        "rows": rows,
        "columns": columns,
        "target_drawer": target_index,
        "handle_type": handle.kind,
        "handle_grasp_point": list(handle.grasp_point),
        "on_legs": on_legs,
        "open_fraction": open_fraction,
        "in_region_state": "open",
        "wall_thickness": wall,
        "door_thickness": front_t,
    }
    return Blueprint(b.model(), link, joint, "prismatic", open_q, in_region, extra)
