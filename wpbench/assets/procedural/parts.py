"""Building blocks shared by the furniture categories: shells, doors, handles, feet.

All coordinates are in the body frame at q = 0 (z up, the front faces +x, metres).
Every function returns plain :class:`~wpbench.assets.procedural.writer.Box` /
:class:`~wpbench.assets.procedural.writer.Cylinder` parts so that each wall, shelf or
door stays its own convex collision piece.

Hinges, seen by a person standing in front of the object (looking along -x): their
right hand is +y. A door hinged on the "right" turns about +z at y_max, one hinged on
the "left" about -z at y_min, a "bottom" one about +y at its lower edge; in all three
cases q = 0 is closed and a positive q swings the free edge towards +x (open).
The hinge line sits on the door's *outer* face, so the door never sweeps into the body.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from wpbench.assets.procedural.writer import RGBA, Box, Cylinder, Part, Vec3

if TYPE_CHECKING:  # blueprint imports this module, so the builder's type is named for annotations only
    from wpbench.assets.procedural.blueprint import ModelBuilder

HingeSide = Literal["left", "right", "bottom"]
HandleKind = Literal["bar", "knob", "recessed"]
HANDLE_KINDS: tuple[HandleKind, ...] = ("bar", "knob", "recessed")

# A small palette; categories pick from it so renders look like real appliances.
STAINLESS: RGBA = (0.72, 0.73, 0.75, 1.0)
WHITE: RGBA = (0.92, 0.92, 0.90, 1.0)
BLACK: RGBA = (0.10, 0.10, 0.11, 1.0)
DARK_GREY: RGBA = (0.28, 0.29, 0.31, 1.0)
MID_GREY: RGBA = (0.50, 0.51, 0.53, 1.0)
LIGHT_GREY: RGBA = (0.80, 0.80, 0.80, 1.0)
GLASS: RGBA = (0.08, 0.10, 0.13, 1.0)
CHROME: RGBA = (0.85, 0.86, 0.88, 1.0)
WOODS: tuple[RGBA, ...] = ((0.55, 0.38, 0.22, 1.0), (0.76, 0.60, 0.42, 1.0), (0.36, 0.24, 0.15, 1.0))


def box_from_bounds(low, high, rgba: RGBA, collide: bool = True, visible: bool = True) -> Box:
    """A box spanning ``low``..``high`` (each (3,))."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    if np.any(high - low <= 0):
        raise ValueError(f"empty box: low={low}, high={high}")
    return Box(tuple((low + high) / 2), tuple(high - low), rgba, collide=collide, visible=visible)


def open_front_shell(low, high, wall: float, back: float, rgba: RGBA) -> tuple[list[Box], np.ndarray]:
    """Five walls of a box whose outer bounds are ``low``..``high``, open towards +x.

    Returns the walls and the (2, 3) bounds of the hollow inside. The walls do not
    overlap each other (bottom and top span everything, sides fit between them, the
    back fits between the sides).
    """
    (x0, y0, z0), (x1, y1, z1) = np.asarray(low, float), np.asarray(high, float)
    walls = [
        box_from_bounds((x0, y0, z0), (x1, y1, z0 + wall), rgba),  # bottom
        box_from_bounds((x0, y0, z1 - wall), (x1, y1, z1), rgba),  # top
        box_from_bounds((x0, y0, z0 + wall), (x1, y0 + wall, z1 - wall), rgba),  # side at -y
        box_from_bounds((x0, y1 - wall, z0 + wall), (x1, y1, z1 - wall), rgba),  # side at +y
        box_from_bounds((x0, y0 + wall, z0 + wall), (x0 + back, y1 - wall, z1 - wall), rgba),  # back
    ]
    inside = np.array([[x0 + back, y0 + wall, z0 + wall], [x1, y1 - wall, z1 - wall]])
    return walls, inside


@dataclass(frozen=True)
class Door:
    """A door slab and how it hangs: the joint origin (body frame) and axis."""

    slab: Box
    origin: Vec3
    axis: Vec3
    hinge: HingeSide
    outer_x: float  # x of the door's outer face when closed

    @property
    def low(self) -> np.ndarray:
        return self.slab.bounds()[0]

    @property
    def high(self) -> np.ndarray:
        return self.slab.bounds()[1]


def hinged_door(
    hinge: HingeSide, front_x: float, y_range, z_range, thickness: float, gap: float, rgba: RGBA
) -> Door:
    """A flat door in front of the plane ``x = front_x`` (with ``gap`` clearance).

    ``y_range``/``z_range`` are the door's extents. See the module docstring for the
    hinge convention.
    """
    (y0, y1), (z0, z1) = y_range, z_range
    x_in, x_out = front_x + gap, front_x + gap + thickness
    slab = box_from_bounds((x_in, y0, z0), (x_out, y1, z1), rgba)
    if hinge == "right":
        origin, axis = (x_out, y1, z0), (0.0, 0.0, 1.0)
    elif hinge == "left":
        origin, axis = (x_out, y0, z0), (0.0, 0.0, -1.0)
    elif hinge == "bottom":
        origin, axis = (x_out, (y0 + y1) / 2, z0), (0.0, 1.0, 0.0)
    else:
        raise ValueError(f"hinge must be 'left', 'right' or 'bottom', got {hinge!r}")
    return Door(slab, origin, axis, hinge, x_out)


@dataclass(frozen=True)
class Handle:
    parts: list[Part]
    kind: HandleKind
    grasp_point: Vec3  # body frame, closed state: where a gripper should close
    direction: Literal["y", "z"]  # long axis of a bar / recess ("x" never: they lie on the face)


def make_handle(
    kind: HandleKind,
    face_x: float,
    y: float,
    z: float,
    direction: Literal["y", "z"],
    length: float,
    rgba: RGBA,
    standoff: float = 0.04,
    radius: float = 0.01,
) -> Handle:
    """A handle centred at (y, z) on the face ``x = face_x``.

    bar: a cylinder ``length`` long at ``standoff`` from the face, held by two posts.
    knob: a short stem and a wider head, pointing +x.
    recessed: a dark finger pocket drawn on the face (visual only: nothing sticks out).
    """
    parts: list[Part] = []
    if kind == "bar":
        bar_x = face_x + standoff
        parts.append(Cylinder((bar_x, y, z), radius, length, direction, rgba))
        post = min(0.02, length / 4)
        for sign in (-1, 1):
            offset = sign * (length / 2 - post / 2)
            py, pz = (y + offset, z) if direction == "y" else (y, z + offset)
            parts.append(
                box_from_bounds(
                    (face_x, py - post / 2 + 0.003, pz - post / 2 + 0.003),
                    (bar_x - radius * 0.5, py + post / 2 - 0.003, pz + post / 2 - 0.003),
                    rgba,
                )
            )
        grasp = (bar_x, y, z)
    elif kind == "knob":
        head_r = max(radius * 1.8, 0.015)
        stem_len = standoff * 0.55
        head_len = standoff - stem_len
        parts.append(Cylinder((face_x + stem_len / 2, y, z), head_r * 0.45, stem_len, "x", rgba))
        parts.append(Cylinder((face_x + stem_len + head_len / 2, y, z), head_r, head_len, "x", rgba))
        grasp = (face_x + stem_len + head_len / 2, y, z)
    elif kind == "recessed":
        width = 0.03
        size = (0.002, length, width) if direction == "y" else (0.002, width, length)
        parts.append(Box((face_x + 0.001, y, z), size, BLACK, collide=False))
        grasp = (face_x, y, z)
    else:
        raise ValueError(f"handle kind must be one of {HANDLE_KINDS}, got {kind!r}")
    return Handle(parts, kind, grasp, direction)


# One side-hinged door: hinge side, y extent, z extent, and whether it is the task's target door.
DoorSpec = tuple[HingeSide, tuple[float, float], tuple[float, float], bool]


def add_side_hinged_doors_with_handles(
    b: ModelBuilder,
    doors: Sequence[DoorSpec],
    masses: Sequence[float],
    front_x: float,
    thickness: float,
    gap: float,
    rgba: RGBA,
    open_angle: float,
    handle_kind: HandleKind,
    handle_rgba: RGBA,
    handle_height: tuple[float, float],
    handle_length: tuple[float, float],
    standoff: float,
    radius: float,
) -> tuple[str, str, HingeSide, Handle]:
    """Add each door of ``doors`` to ``b`` as a revolute link opening to ``open_angle``, with an
    upright handle 5 cm in from its free edge; return the target door's (link, joint, hinge, handle).

    ``masses`` holds one link mass per door, in the order of ``doors``. ``handle_height`` places
    the handle's centre at that fraction of the door's height above its bottom edge, the first
    value on the target door and the second on the others; ``handle_length`` is (fraction of
    the door's height, longest handle). The doors hang as :func:`hinged_door` says.
    """
    if len(masses) != len(doors):
        raise ValueError(f"{len(doors)} doors but {len(masses)} masses")
    target = None
    for (hinge, y_range, z_range, is_target), mass in zip(doors, masses):
        door = hinged_door(hinge, front_x, y_range, z_range, thickness, gap, rgba)
        y0, y1 = y_range
        free_y = y1 - 0.05 if hinge == "left" else y0 + 0.05
        z0, z1 = z_range
        door_h = z1 - z0
        hz = z0 + (handle_height[0] if is_target else handle_height[1]) * door_h
        length = min(handle_length[1], door_h * handle_length[0])
        handle = make_handle(handle_kind, door.outer_x, free_y, hz, "z", length, handle_rgba,
                             standoff=standoff, radius=radius)
        link, joint = b.add_moving([door.slab, *handle.parts], "revolute", door.origin, door.axis, open_angle,
                                   mass, "hinge door")
        if is_target:
            target = (link, joint, hinge, handle)
    if target is None:
        raise ValueError("no door is marked as the target")
    return target


def shelf_bottoms(rng: np.random.Generator, z0: float, z1: float, min_gap: float, min_count: int = 1,
                  max_count: int = 4, thickness: float = 0.02) -> list[float]:
    """z of ``min_count .. max_count`` shelf bottoms (as many as fit) splitting [z0, z1] into
    compartments at least ``min_gap`` high; ``thickness`` is the allowance per shelf."""
    room = int((z1 - z0) // (min_gap + thickness)) - 1
    n = int(rng.integers(min_count, max(min_count, min(room, max_count)) + 1)) if room >= 1 else 0
    if n == 0:
        return []
    spacing = (z1 - z0) / (n + 1)
    jitter = max(0.0, (spacing - min_gap - thickness) / 2)
    return [round(z0 + spacing * (k + 1) + float(rng.uniform(-jitter, jitter)), 4) for k in range(n)]


def window(face_x: float, y_range, z_range, rgba: RGBA = GLASS) -> Box:
    """A dark glass pane drawn just proud of a door face (visual only)."""
    (y0, y1), (z0, z1) = y_range, z_range
    return box_from_bounds((face_x, y0, z0), (face_x + 0.002, y1, z1), rgba, collide=False)


def feet(x_range, y_range, height: float, size: float, round_feet: bool, rgba: RGBA, inset: float = 0.03) -> list[Part]:
    """Four feet under the corners of a footprint, from z = 0 to ``height``."""
    (x0, x1), (y0, y1) = x_range, y_range
    out: list[Part] = []
    for x in (x0 + inset + size / 2, x1 - inset - size / 2):
        for y in (y0 + inset + size / 2, y1 - inset - size / 2):
            if round_feet:
                out.append(Cylinder((x, y, height / 2), size / 2, height, "z", rgba, sections=12))
            else:
                out.append(Box((x, y, height / 2), (size, size, height), rgba))
    return out


def wire_rack(low, high, bar: float, spacing: float, rgba: RGBA, rim_height: float = 0.0) -> list[Part]:
    """A wire rack: visual bars along x over a frame, collision as one thin slab (+ rim walls).

    ``low``..``high`` bound the rack's base (its z extent is the bar thickness).
    The collision slab makes the rack a flat shelf for objects; the visual bars make
    it look like a rack.
    """
    low, high = np.asarray(low, float), np.asarray(high, float)
    parts: list[Part] = [box_from_bounds(low, high, rgba, visible=False)]
    (x0, y0, z0), (x1, y1, z1) = low, high
    # frame
    parts.append(box_from_bounds((x0, y0, z0), (x1, y0 + bar, z1), rgba, collide=False))
    parts.append(box_from_bounds((x0, y1 - bar, z0), (x1, y1, z1), rgba, collide=False))
    parts.append(box_from_bounds((x0, y0, z0), (x0 + bar, y1, z1), rgba, collide=False))
    parts.append(box_from_bounds((x1 - bar, y0, z0), (x1, y1, z1), rgba, collide=False))
    n = max(2, int((y1 - y0) / spacing))
    for y in np.linspace(y0 + spacing / 2, y1 - spacing / 2, n):
        parts.append(box_from_bounds((x0, y - bar / 2, z0), (x1, y + bar / 2, z1), rgba, collide=False))
    if rim_height > 0:
        top = z1 + rim_height
        parts += [
            box_from_bounds((x0, y0, z1), (x1, y0 + bar, top), rgba),
            box_from_bounds((x0, y1 - bar, z1), (x1, y1, top), rgba),
            box_from_bounds((x0, y0 + bar, z1), (x0 + bar, y1 - bar, top), rgba),
            box_from_bounds((x1 - bar, y0 + bar, z1), (x1, y1 - bar, top), rgba),
        ]
    return parts


def boxes_overlap(a: np.ndarray, b: np.ndarray, tol: float = 1e-6) -> bool:
    """Do two (2, 3) axis-aligned bounds overlap by more than ``tol`` on every axis?"""
    return bool(np.all(np.minimum(a[1], b[1]) - np.maximum(a[0], b[0]) > tol))


def interior_lining(inside, rgba: RGBA, skin: float = 0.001) -> list[Box]:
    """Visual-only skins on the five inner faces of a cavity (``inside`` is (2, 3) bounds).

    Lets the outside of a shell keep its finish while the cavity gets its own colour
    (enamel, plastic liner...). No collision: the walls already collide.
    """
    (x0, y0, z0), (x1, y1, z1) = np.asarray(inside, float)
    def skin_box(lo, hi):
        return box_from_bounds(lo, hi, rgba, collide=False)
    return [
        skin_box((x0, y0, z0), (x0 + skin, y1, z1)),  # back
        skin_box((x0, y0, z0), (x1, y1, z0 + skin)),  # floor
        skin_box((x0, y0, z1 - skin), (x1, y1, z1)),  # ceiling
        skin_box((x0, y0, z0), (x1, y0 + skin, z1)),  # side -y
        skin_box((x0, y1 - skin, z0), (x1, y1, z1)),  # side +y
    ]
