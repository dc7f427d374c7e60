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

Part-door cabinet (extra training instances only, :func:`build_training_variety`): a taller
carcass split by a divider into a section behind the target door(s) and a neighbour section
above or below it (an open shelf, drawers or another door). In-region: a compartment behind
the target door, so a goal's height cannot be told from the floor alone.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

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
    part_door_height: tuple[float, float] = (0.75, 1.40)  # room for a door section and another above or below it
    part_door_fraction: tuple[float, float] = (0.35, 0.65)  # of the inside height behind the target door
    part_door_share: float = 1 / 3  # of the training-variety instances


def build(rng: np.random.Generator, object_id: str, ranges: StorageRanges = StorageRanges()) -> Blueprint:
    """A door cabinet with probability ``ranges.door_cabinet_share``, else a chest of drawers.

    The choice comes from a stream spawned off ``rng``'s seed, which leaves ``rng`` untouched:
    an instance that is a chest is the same chest it was before door cabinets existed.
    """
    style_rng = np.random.default_rng(rng.bit_generator.seed_seq.spawn(1)[0])
    if style_rng.random() < ranges.door_cabinet_share:
        return build_door_cabinet(rng, object_id, ranges)
    return build_drawer_chest(rng, object_id, ranges)


def build_training_variety(rng: np.random.Generator, object_id: str, ranges: StorageRanges = StorageRanges()) -> Blueprint:
    """What :func:`build` makes, or with probability ``ranges.part_door_share`` a cabinet whose target door closes
    only part of its height (:func:`build_part_door_cabinet`); the choice comes from the same spawned stream.

    Only extra training instances are built this way (see ``generate.TRAINING_VARIETY``): val and test keep the
    benchmark's furniture, and training also sees cabinets where the goal's height is not given by the floor.
    """
    style_rng = np.random.default_rng(rng.bit_generator.seed_seq.spawn(1)[0])
    door_cabinet = style_rng.random() < ranges.door_cabinet_share
    if style_rng.random() < ranges.part_door_share:
        return build_part_door_cabinet(rng, object_id, ranges)
    return build_door_cabinet(rng, object_id, ranges) if door_cabinet else build_drawer_chest(rng, object_id, ranges)


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


def _add_drawer(rng: np.random.Generator, carcass: _Carcass, opening: tuple[float, float, float, float],
                front: tuple[float, float, float, float], box_depth: float, open_q: float, handle_kind: P.HandleKind,
                ranges: StorageRanges) -> tuple[str, str, P.Handle, tuple[float, ...], float]:
    """Add one drawer, sliding out along +x by ``open_q``, to the carcass.

    ``opening`` = (y0, y1, z0, z1) of the hole in the carcass it runs in, ``front`` = (y0, y1, z0, z1) of its overlay
    front. Returns (link, joint, handle, box bounds (x0, x1, y0, y1, z0, z1), x of the front's face).
    """
    (oy0, oy1, oz0, oz1), (fy0, fy1, fz0, fz1) = opening, front
    dwall, wood = carcass.drawer_wall, carcass.wood
    x_in = carcass.xf + FRONT_GAP  # back face of the front panel
    panel = P.box_from_bounds((x_in, fy0, fz0), (x_in + carcass.front_t, fy1, fz1), carcass.front_colour)
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
    face_x = x_in + carcass.front_t
    hz = (fz0 + fz1) / 2 if rng.random() < 0.5 else fz1 - min(0.06, (fz1 - fz0) / 4)
    handle = P.make_handle(handle_kind, face_x, (fy0 + fy1) / 2, hz, "y", min(0.3, (fy1 - fy0) * 0.5),
                           carcass.metal, standoff=0.03, radius=0.007)
    origin = (face_x, (fy0 + fy1) / 2, (fz0 + fz1) / 2)
    link, joint = carcass.b.add_moving([panel, *box, *handle.parts], "prismatic", origin, (1.0, 0.0, 0.0), open_q,
                                       uniform(rng, *ranges.drawer_mass), "slider drawer")
    return link, joint, handle, (bx0, bx1, by0, by1, bz0, bz1), face_x


def _shelved_goal_compartment(rng: np.random.Generator, object_id: str, carcass: _Carcass, z0: float, z1: float,
                              max_shelves: int, ranges: StorageRanges) -> tuple[list[float], tuple[float, float]]:
    """Add 0 .. ``max_shelves`` shelves between heights ``z0`` and ``z1`` of the carcass; return their bottoms and
    the (floor, ceiling) of the compartment whose middle is nearest ``ranges.reach_height``."""
    inside, xf, shelf_t = carcass.inside, carcass.xf, carcass.wall
    shelf_bottoms = P.shelf_bottoms(rng, z0, z1, ranges.min_compartment, min_count=0, max_count=max_shelves)
    for z in shelf_bottoms:
        carcass.b.add_body(P.box_from_bounds((inside[0, 0], inside[0, 1], z), (xf - 0.01, inside[1, 1], z + shelf_t),
                                             carcass.wood))
    floors = [z0] + [z + shelf_t for z in shelf_bottoms]
    ceilings = shelf_bottoms + [z1]
    compartments = [(lo, hi) for lo, hi in zip(floors, ceilings) if hi - lo >= MIN_CAVITY_EXTENT]
    if not compartments:
        raise ValueError(f"{object_id}: {z1 - z0:.3f} m inside is too low for a compartment")
    return shelf_bottoms, min(compartments, key=lambda c: abs((c[0] + c[1]) / 2 - ranges.reach_height))


def _target_door_specs(rng: np.random.Generator, W: float, door_t: float, z_range: tuple[float, float],
                       ranges: StorageRanges) -> list[P.DoorSpec]:
    """One door over the carcass's width between heights ``z_range``, hinged left or right, or (when the
    carcass is wide enough, half of the time) two doors meeting in the middle, either one the target."""
    if W >= ranges.two_doors_min_width and rng.random() < 0.5:
        # The centre gap leaves room for the inner back corner's sideways sweep (see fridge).
        mid_gap = door_t**2 / (W / 2) + 0.004
        target_left = bool(rng.random() < 0.5)
        return [("left", (-W / 2, -mid_gap / 2), z_range, target_left),
                ("right", (mid_gap / 2, W / 2), z_range, not target_left)]
    return [("left" if rng.random() < 0.5 else "right", (-W / 2, W / 2), z_range, True)]


def _region_behind_door(inside: np.ndarray, xf: float, two_doors: bool, target_hinge: str, lo: float,
                        hi: float) -> np.ndarray:
    """(2, 3) bounds of the space the target door closes between heights ``lo`` and ``hi``: the whole width
    behind one door, the half behind the target of two."""
    y_lo, y_hi = inside[0, 1], inside[1, 1]
    if two_doors:
        y_lo, y_hi = (y_lo, -0.01) if target_hinge == "left" else (0.01, y_hi)
    return np.array([[inside[0, 0], y_lo, lo], [xf, y_hi, hi]])


def build_door_cabinet(rng: np.random.Generator, object_id: str, ranges: StorageRanges = StorageRanges()) -> Blueprint:
    carcass = _storage_carcass(rng, object_id, ranges, drawer_wall=False)
    inside = carcass.inside
    shelf_bottoms, goal_z = _shelved_goal_compartment(rng, object_id, carcass, inside[0, 2], inside[1, 2], 3, ranges)
    door_specs = _target_door_specs(rng, carcass.W, carcass.front_t, (carcass.base_h, carcass.base_h + carcass.H),
                                    ranges)
    two_doors = len(door_specs) == 2
    open_angle = round(float(np.deg2rad(rng.uniform(*ranges.door_open_deg))), 4)
    handle_kind = choose(rng, P.HANDLE_KINDS)
    return _hang_doors(rng, carcass, door_specs, two_doors, open_angle, handle_kind, goal_z, ranges,
                       {"style": "door_cabinet", "shelves": len(shelf_bottoms)})


def _hang_doors(rng: np.random.Generator, carcass: _Carcass, door_specs: list[P.DoorSpec], two_doors: bool,
                open_angle: float, handle_kind: P.HandleKind, goal_z: tuple[float, float], ranges: StorageRanges,
                extra: dict) -> Blueprint:
    """Hang ``door_specs`` on the carcass (``two_doors``: the target is one of two side by side) and return the
    cabinet's blueprint, its goal the space behind the target door between heights ``goal_z``; ``extra`` adds
    to the description every door cabinet has."""
    handle_at = 0.8 if rng.random() < 0.5 else 0.5  # fraction of the door's height, the same on every door
    masses = [uniform(rng, *ranges.door_mass) for _ in door_specs]  # drawn in door order
    link, joint, target_hinge, handle = P.add_side_hinged_doors_with_handles(
        carcass.b, door_specs, masses, carcass.xf, carcass.front_t, FRONT_GAP, carcass.front_colour, open_angle,
        handle_kind, carcass.metal, handle_height=(handle_at, handle_at), handle_length=(0.4, 0.25), standoff=0.03,
        radius=0.007)
    in_region = _region_behind_door(carcass.inside, carcass.xf, two_doors, target_hinge, *goal_z)
    description = {
        "hinge": target_hinge,
        "doors": len(door_specs),
        "handle_type": handle.kind,
        "handle_grasp_point": list(handle.grasp_point),
        "on_legs": carcass.on_legs,
        "wall_thickness": carcass.wall,
        "door_thickness": carcass.front_t,
        **extra,
    }
    return Blueprint(carcass.b.model(), link, joint, "revolute", open_angle, in_region, description)


PART_DOOR_NEIGHBOURS = ("open", "drawers", "door")


def build_part_door_cabinet(rng: np.random.Generator, object_id: str, ranges: StorageRanges = StorageRanges()) -> Blueprint:
    """A cabinet split by a fixed divider into a section behind the target door(s) and, above or below it, a
    neighbour section: an open shelf, one or two drawers, or another door. The goal is a compartment behind the
    target door, so its height follows the door, not the floor."""
    carcass = _storage_carcass(rng, object_id, replace(ranges, height=ranges.part_door_height), drawer_wall=True)
    b, W, wall, xf, base_h, inside = carcass.b, carcass.W, carcass.wall, carcass.xf, carcass.base_h, carcass.inside
    z_bottom, z_top = inside[0, 2], inside[1, 2]
    section_min = max(ranges.min_compartment, ranges.min_opening)
    room = z_top - z_bottom - wall  # both sections, without the divider
    if room < 2 * section_min:
        raise ValueError(f"{object_id}: {z_top - z_bottom:.3f} m inside is too low for two sections")
    door_h = float(np.clip(uniform(rng, *ranges.part_door_fraction) * room, section_min, room - section_min))
    door_below = bool(rng.random() < 0.5)
    divider_z = z_bottom + door_h if door_below else z_top - door_h - wall
    b.add_body(P.box_from_bounds((inside[0, 0], inside[0, 1], divider_z), (xf, inside[1, 1], divider_z + wall),
                                 carcass.wood))
    # Each section's inside, and the fronts' extents: a front covers the carcass edge and half the divider.
    below, above = (z_bottom, divider_z), (divider_z + wall, z_top)
    split_z = divider_z + wall / 2
    fronts_below, fronts_above = (base_h, split_z - 0.002), (split_z + 0.002, base_h + carcass.H)
    door_section, other_section = (below, above) if door_below else (above, below)
    door_z, other_z = (fronts_below, fronts_above) if door_below else (fronts_above, fronts_below)

    shelf_bottoms, goal_z = _shelved_goal_compartment(rng, object_id, carcass, *door_section, 1, ranges)
    door_specs = _target_door_specs(rng, W, carcass.front_t, door_z, ranges)
    two_doors = len(door_specs) == 2
    neighbour = PART_DOOR_NEIGHBOURS[int(rng.integers(len(PART_DOOR_NEIGHBOURS)))]
    handle_kind = choose(rng, P.HANDLE_KINDS)
    if neighbour == "open":
        _shelved_goal_compartment(rng, object_id, carcass, *other_section, 1, ranges)
    elif neighbour == "door":
        door_specs.append(("left" if rng.random() < 0.5 else "right", (-W / 2, W / 2), other_z, False))
    else:
        _add_drawer_rows(rng, carcass, other_section, other_z, handle_kind, ranges)

    open_angle = round(float(np.deg2rad(rng.uniform(*ranges.door_open_deg))), 4)
    return _hang_doors(rng, carcass, door_specs, two_doors, open_angle, handle_kind, goal_z, ranges,
                       {"style": "part_door_cabinet", "shelves": len(shelf_bottoms), "neighbour": neighbour,
                        "door_section": "below" if door_below else "above"})


def _add_drawer_rows(rng: np.random.Generator, carcass: _Carcass, section: tuple[float, float],
                     fronts: tuple[float, float], handle_kind: P.HandleKind, ranges: StorageRanges) -> None:
    """Fill the carcass between heights ``section`` with one or two full-width drawers (two when both fit),
    their fronts spanning ``fronts``, separated by a divider."""
    inside, wall, xf = carcass.inside, carcass.wall, carcass.xf
    (z0, z1), (f0, f1) = section, fronts
    rows = 2 if z1 - z0 >= 2 * ranges.min_opening + wall and rng.random() < 0.5 else 1
    row_h = (z1 - z0 - (rows - 1) * wall) / rows
    box_depth = round(inside[1, 0] - inside[0, 0] - 0.02, 4)
    open_q = round(uniform(rng, *ranges.open_fraction) * box_depth, 4)
    for r in range(rows):
        oz0 = z0 + r * (row_h + wall)
        if r > 0:
            carcass.b.add_body(P.box_from_bounds((inside[0, 0], inside[0, 1], oz0 - wall), (xf, inside[1, 1], oz0),
                                                 carcass.wood))
        fz0 = f0 if r == 0 else oz0 - wall / 2 + 0.002
        fz1 = f1 if r == rows - 1 else oz0 + row_h + wall / 2 - 0.002
        _add_drawer(rng, carcass, (inside[0, 1], inside[1, 1], oz0, oz0 + row_h),
                    (-carcass.W / 2, carcass.W / 2, fz0, fz1), box_depth, open_q, handle_kind, ranges)


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
            drawers.append(_add_drawer(rng, carcass, (oy0, oy1, oz0, oz1), (fy0, fy1, fz0, fz1), box_depth, open_q,
                                       handle_kind, ranges))

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
