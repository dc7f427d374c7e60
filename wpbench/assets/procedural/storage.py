"""Storage furniture, half of it chests of drawers and half door cabinets, on a plinth or legs.

Chest of drawers (one or two columns). Each drawer is a prismatic link: an overlay front panel plus an open box (bottom,
two sides, back) that slides along +x. The open limit is a fixed fraction (0.8) of
the drawer box's depth, so an open drawer stays on its runners.

What "in" means for a drawer: the drawer box moves, so the in-region is defined in
the *open* state (target joint at ``open_qpos``) as the part of the drawer's inside
that has come out of the carcass, i.e. in front of the neighbouring drawer fronts,
where an object can be dropped in from above. It runs from the drawer's floor to
the top of its side walls.

Door cabinet: an open-front carcass with shelves behind one or two overlay doors hinged
at the outer edges (both hinge sides occur). A cabinet door's stop is hidden in its hinge,
so no point cloud shows it; the stop is drawn from ``door_open_deg``, a range narrow
enough (upper / lower <= 1.1) that the range's middle lies inside the 10% success
tolerance of every stop in it, with margin (a door driven past its stop is held there).
A policy that cannot see the stop regresses to that middle, so the middle is what
must pass. Common real stops (90-105 deg) are below the range and are reached by
clamping. In-region: the compartment behind the
target door (the half behind it for two doors) whose middle is nearest reach height.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wpbench.assets.procedural import parts as P
from wpbench.assets.procedural.blueprint import MIN_CAVITY_EXTENT, Blueprint, ModelBuilder, choose, uniform
from wpbench.assets.procedural.writer import RGBA


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
    door_cabinet_share: float = 0.5
    door_open_deg: tuple[float, float] = (119.0, 130.0)
    door_mass: tuple[float, float] = (1.5, 4.0)
    two_doors_min_width: float = 0.6
    min_compartment: float = 0.24  # height between shelves, so a 16 cm block fits with margin
    reach_height: float = 0.8


def build(rng: np.random.Generator, object_id: str, ranges: StorageRanges = StorageRanges()) -> Blueprint:
    """A door cabinet with probability ``ranges.door_cabinet_share``, else a chest of drawers.

    The choice comes from a stream spawned off ``rng``'s seed, which leaves ``rng`` untouched:
    an instance that is a chest is the same chest it was before door cabinets existed.
    """
    style_rng = np.random.default_rng(rng.bit_generator.seed_seq.spawn(1)[0])
    if style_rng.random() < ranges.door_cabinet_share:
        return build_door_cabinet(rng, object_id, ranges)
    return build_drawer_chest(rng, object_id, ranges)


# Clearance between the carcass front and the door or drawer fronts laid over it.
FRONT_GAP = 0.003


def _base(rng: np.random.Generator, b: ModelBuilder, D: float, W: float, wood, ranges: StorageRanges) -> tuple[bool, float]:
    """Legs or a plinth under the carcass; returns (on_legs, base height)."""
    on_legs = bool(rng.random() < 0.4)
    if on_legs:
        base_h = uniform(rng, *ranges.leg_height)
        b.add_body(P.feet((-D / 2, D / 2), (-W / 2, W / 2), base_h, 0.04, bool(rng.random() < 0.5), wood, inset=0.01))
    else:
        base_h = uniform(rng, *ranges.plinth_height)
        b.add_body(P.box_from_bounds((-D / 2 + 0.02, -W / 2 + 0.02, 0.0), (D / 2 - 0.03, W / 2 - 0.02, base_h), wood))
    return on_legs, base_h


@dataclass
class _Carcass:
    """The open-front wooden box both storage styles start from, and the finishes of its fronts."""

    b: ModelBuilder  # holds the base and the shell walls so far
    W: float
    H: float  # shell height, above the base
    wall: float
    front_t: float  # thickness of the door or drawer fronts
    drawer_wall: float | None  # drawer box wall thickness, drawn for chests only
    wood: RGBA
    front_colour: RGBA
    metal: RGBA  # handle colour
    xf: float  # x of the shell's open front
    on_legs: bool
    base_h: float
    inside: np.ndarray  # (2, 3) bounds of the hollow inside


def _storage_carcass(rng: np.random.Generator, object_id: str, ranges: StorageRanges, drawer_wall: bool) -> _Carcass:
    """Draw the sizes and finishes of a storage carcass and build its base and open-front shell.

    The draws come in this order: width, depth, height, wall, front thickness, the drawer box wall
    (only if ``drawer_wall``), wood, front colour, handle metal, then the base.
    """
    W, D, H = uniform(rng, *ranges.width), uniform(rng, *ranges.depth), uniform(rng, *ranges.height)
    wall = uniform(rng, *ranges.wall)
    front_t = uniform(rng, *ranges.front_thickness)
    dwall = uniform(rng, *ranges.drawer_wall) if drawer_wall else None
    wood = choose(rng, P.WOODS + (P.WHITE, P.DARK_GREY))
    front_colour = wood if rng.random() < 0.6 else choose(rng, P.WOODS + (P.WHITE,))
    metal = choose(rng, (P.CHROME, P.BLACK, (0.70, 0.55, 0.25, 1.0)))
    xf = D / 2
    b = ModelBuilder(object_id, "furniture_body")
    on_legs, base_h = _base(rng, b, D, W, wood, ranges)
    walls, inside = P.open_front_shell((-D / 2, -W / 2, base_h), (xf, W / 2, base_h + H), wall, wall * 0.6, wood)
    b.add_body(walls)
    return _Carcass(b, W, H, wall, front_t, dwall, wood, front_colour, metal, xf, on_legs, base_h, inside)


def build_door_cabinet(rng: np.random.Generator, object_id: str, ranges: StorageRanges = StorageRanges()) -> Blueprint:
    carcass = _storage_carcass(rng, object_id, ranges, drawer_wall=False)
    b, W, wall, door_t, wood, xf, base_h, inside = (carcass.b, carcass.W, carcass.wall, carcass.front_t, carcass.wood,
                                                     carcass.xf, carcass.base_h, carcass.inside)
    shelf_t = wall
    shelf_bottoms = P.shelf_bottoms(rng, inside[0, 2], inside[1, 2], ranges.min_compartment, min_count=0, max_count=3)
    for z in shelf_bottoms:
        b.add_body(P.box_from_bounds((inside[0, 0], inside[0, 1], z), (xf - 0.01, inside[1, 1], z + shelf_t), wood))
    floors = [inside[0, 2]] + [z + shelf_t for z in shelf_bottoms]
    ceilings = shelf_bottoms + [inside[1, 2]]
    compartments = [(lo, hi) for lo, hi in zip(floors, ceilings) if hi - lo >= MIN_CAVITY_EXTENT]
    if not compartments:
        raise ValueError(f"{object_id}: {inside[1, 2] - inside[0, 2]:.3f} m inside is too low for a compartment")
    lo, hi = min(compartments, key=lambda c: abs((c[0] + c[1]) / 2 - ranges.reach_height))

    two_doors = W >= ranges.two_doors_min_width and rng.random() < 0.5
    z_range = (base_h, base_h + carcass.H)
    if two_doors:
        # The centre gap leaves room for the inner back corner's sideways sweep (see fridge).
        mid_gap = door_t**2 / (W / 2) + 0.004
        target_left = bool(rng.random() < 0.5)
        door_specs: list[P.DoorSpec] = [("left", (-W / 2, -mid_gap / 2), z_range, target_left),
                                        ("right", (mid_gap / 2, W / 2), z_range, not target_left)]
    else:
        door_specs = [("left" if rng.random() < 0.5 else "right", (-W / 2, W / 2), z_range, True)]

    open_angle = round(float(np.deg2rad(rng.uniform(*ranges.door_open_deg))), 4)
    handle_kind = choose(rng, P.HANDLE_KINDS)
    handle_at = 0.8 if rng.random() < 0.5 else 0.5  # fraction of the door's height, the same on every door
    masses = [uniform(rng, *ranges.door_mass) for _ in door_specs]  # drawn in door order
    link, joint, target_hinge, handle = P.add_side_hinged_doors_with_handles(
        b, door_specs, masses, xf, door_t, FRONT_GAP, carcass.front_colour, open_angle, handle_kind, carcass.metal,
        handle_height=(handle_at, handle_at), handle_length=(0.4, 0.25), standoff=0.03, radius=0.007)

    y_lo, y_hi = inside[0, 1], inside[1, 1]
    if two_doors:  # only the half behind the opened door is reachable
        y_lo, y_hi = (y_lo, -0.01) if target_hinge == "left" else (0.01, y_hi)
    in_region = np.array([[inside[0, 0], y_lo, lo], [xf, y_hi, hi]])
    extra = {
        "style": "door_cabinet",
        "hinge": target_hinge,
        "doors": len(door_specs),
        "shelves": len(shelf_bottoms),
        "handle_type": handle.kind,
        "handle_grasp_point": list(handle.grasp_point),
        "on_legs": carcass.on_legs,
        "wall_thickness": wall,
        "door_thickness": door_t,
    }
    return Blueprint(b.model(), link, joint, "revolute", open_angle, in_region, extra)


def build_drawer_chest(rng: np.random.Generator, object_id: str, ranges: StorageRanges = StorageRanges()) -> Blueprint:
    carcass = _storage_carcass(rng, object_id, ranges, drawer_wall=True)
    b, W, wall, front_t, dwall, wood, xf, inside = (carcass.b, carcass.W, carcass.wall, carcass.front_t,
                                                    carcass.drawer_wall, carcass.wood, carcass.xf, carcass.inside)

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
            x_in = xf + FRONT_GAP  # back face of the front panel
            front = P.box_from_bounds((x_in, fy0, fz0), (x_in + front_t, fy1, fz1), carcass.front_colour)
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
            handle = P.make_handle(handle_kind, face_x, (fy0 + fy1) / 2, hz, "y", min(0.3, (fy1 - fy0) * 0.5),
                                   carcass.metal, standoff=0.03, radius=0.007)
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
        "on_legs": carcass.on_legs,
        "open_fraction": open_fraction,
        "style": "drawer_chest",
        "in_region_state": "open",
        "wall_thickness": wall,
        "door_thickness": front_t,
    }
    return Blueprint(b.model(), link, joint, "prismatic", open_q, in_region, extra)
