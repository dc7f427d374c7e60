"""What a category builder hands back, and the checks every generated object must pass.

A category module (``oven.py``, ``fridge.py``, ...) turns a random generator into a
:class:`Blueprint`: the articulated model plus the task facts (target joint, open
limit, the "in" region). ``generate.py`` writes blueprints to disk.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from wpbench.assets.procedural.parts import boxes_overlap
from wpbench.assets.procedural.writer import ArticulatedModel, JointModel, LinkModel

# The free-floating task drops a Ravens block of up to 16 cm side into the cavity;
# every in-region must be at least this big on each axis (block + 2 cm each side).
MIN_CAVITY_EXTENT = 0.20


@dataclass
class Blueprint:
    """One procedural object before it is written.

    ``in_region`` is an axis-aligned (2, 3) low/high box in the body frame: the free
    cavity behind the target door (for drawers: the open drawer's inside that is out
    of the carcass, see ``storage.py``).
    """

    model: ArticulatedModel
    target_link: str
    target_joint: str
    joint_type: Literal["revolute", "prismatic"]
    open_qpos: float
    in_region: np.ndarray
    extra: dict = field(default_factory=dict)
    closed_qpos: float = 0.0


def uniform(rng: np.random.Generator, low: float, high: float, decimals: int = 4) -> float:
    """A uniform draw rounded so that the files print the same number that the JSON stores."""
    return round(float(rng.uniform(low, high)), decimals)


def choose(rng: np.random.Generator, options):
    """One element of ``options`` (a tuple), as a plain Python value."""
    return options[int(rng.integers(len(options)))]


def check_blueprint(bp: Blueprint) -> None:
    """Raise ValueError if the object breaks an invariant the tasks rely on.

    - the in-region is at least MIN_CAVITY_EXTENT on every axis;
    - no collision part of a moving link overlaps a body part at q = 0 (closed doors
      and drawers rest without contact forces);
    - the target joint exists and opens (open_qpos > closed_qpos, equal to its upper limit);
    - the object stands on z = 0.
    """
    name = bp.model.name
    extent = bp.in_region[1] - bp.in_region[0]
    if np.any(extent < MIN_CAVITY_EXTENT - 1e-9):
        raise ValueError(f"{name}: in-region {extent.round(3)} smaller than {MIN_CAVITY_EXTENT} m on some axis")
    body = [p.bounds() for p in bp.model.links[0].parts if p.collide]
    for link in bp.model.links[1:]:
        for part in link.parts:
            if not part.collide:
                continue
            for b in body:
                if boxes_overlap(part.bounds(), b, tol=1e-5):
                    raise ValueError(f"{name}: {link.name} part {part.bounds().round(3).tolist()} overlaps the body when closed")
    joints = {j.name: j for j in bp.model.joints}
    if bp.target_joint not in joints:
        raise ValueError(f"{name}: target joint {bp.target_joint} missing")
    joint = joints[bp.target_joint]
    if not (bp.open_qpos > bp.closed_qpos and abs(joint.upper - bp.open_qpos) < 1e-9):
        raise ValueError(f"{name}: open_qpos {bp.open_qpos} must be the joint's upper limit {joint.upper}")
    low = bp.model.bounds()[0]
    if abs(low[2]) > 1e-9:
        raise ValueError(f"{name}: the object must stand on z = 0, its lowest point is {low[2]}")


class ModelBuilder:
    """Collects the body parts and the moving links of one object, PartNet-style names.

    The body is ``link_0`` (joined to ``base`` by the fixed ``joint_0``); each moving
    part added becomes ``link_k`` with joint ``joint_k``, k = 1, 2, ...
    """

    def __init__(self, name: str, body_semantic: str):
        self.name = name
        self.body_semantic = body_semantic
        self.body = LinkModel("link_0")
        self.links = [self.body]
        self.joints = [JointModel("joint_0", "fixed", "base", "link_0")]

    def add_body(self, *parts) -> None:
        for p in parts:
            if isinstance(p, list):
                self.body.parts.extend(p)
            else:
                self.body.parts.append(p)

    def add_moving(self, parts, kind, origin, axis, upper: float, mass: float, semantic: str) -> tuple[str, str]:
        """Add a door (kind "revolute") or drawer ("prismatic"); return (link name, joint name)."""
        k = len(self.links)
        link = LinkModel(f"link_{k}", list(parts), mass=mass)
        joint = JointModel(
            f"joint_{k}", kind, "link_0", link.name, tuple(map(float, origin)), tuple(map(float, axis)),
            0.0, float(upper), semantic,
        )
        self.links.append(link)
        self.joints.append(joint)
        return link.name, joint.name

    def model(self) -> ArticulatedModel:
        return ArticulatedModel(self.name, self.links, self.joints, self.body_semantic)
