"""What every task needs to know about a piece of furniture, whatever its source.

Procedural furniture (``wpbench.assets.procedural``) writes these fields to a
``wpbench.json`` beside its ``mobility.urdf``; the real PartNet-Mobility loader
(``wpbench.assets.partnet``) infers them from the dataset folder. Tasks only see
:class:`FurnitureAsset`.

Frames: the *body frame* is the articulation root link's frame after scaling,
in metres, z up. Every position and box below is expressed in it.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

JointType = Literal["revolute", "prismatic"]


@dataclass(frozen=True)
class OrientedBox:
    """A box ``{c + R x : |x_k| <= h_k}`` in the body frame.

    ``rotation`` is the 3x3 matrix R (row-major nested lists), ``center`` c and
    ``half_extents`` h in metres.
    """

    center: tuple[float, float, float]
    half_extents: tuple[float, float, float]
    rotation: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """(..., 3) body-frame points -> (...) bool: inside the box shrunk by ``margin``."""
        p = np.asarray(points, dtype=np.float64)
        local = (p - np.asarray(self.center)) @ np.asarray(self.rotation)
        return np.all(np.abs(local) <= np.asarray(self.half_extents) - margin, axis=-1)

    def corners(self) -> np.ndarray:
        """(8, 3) corners in the body frame."""
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
        return np.asarray(self.center) + (signs * np.asarray(self.half_extents)) @ np.asarray(self.rotation).T


@dataclass(frozen=True)
class FurnitureAsset:
    """One articulated object ready to be loaded into a SAPIEN scene.

    Attributes:
        object_id: unique id ("oven-0003" for procedural, "101773" for PartNet-Mobility).
        category: "oven", "microwave", "dishwasher", "fridge", "safe", "storage", ...
        urdf: URDF to load; its collision geometry keeps cavities hollow.
        scale: uniform scale to pass to the URDF loader (1.0 when the URDF is in metres).
        target_link / target_joint: the door or drawer the tasks open (the action object).
        joint_type: "revolute" (door) or "prismatic" (drawer).
        closed_qpos / open_qpos: joint values of the closed and fully open states;
            the articulated goal is ``open_qpos`` (the joint limit on the open side).
        in_region: the free cavity behind the door, where "in" means inside.
        bounds_low / bounds_high: axis-aligned bounds of the whole closed object in the
            body frame; tasks put it on the floor by lifting the root by ``-bounds_low[2]``.
        front: unit vector in the body frame that the door faces (cameras and start
            positions of free objects go on this side).
        source: "procedural" or "partnet-mobility".
        split: "train", "val" or None when the source has no split.
    """

    object_id: str
    category: str
    urdf: Path
    scale: float
    target_link: str
    target_joint: str
    joint_type: JointType
    closed_qpos: float
    open_qpos: float
    in_region: OrientedBox
    bounds_low: tuple[float, float, float]
    bounds_high: tuple[float, float, float]
    front: tuple[float, float, float] = (1.0, 0.0, 0.0)
    source: str = "procedural"
    split: str | None = None
    extra: dict = field(default_factory=dict)

    def to_json(self, relative_to: Path | None = None) -> dict:
        d = asdict(self)
        urdf = Path(self.urdf)
        d["urdf"] = str(urdf.relative_to(relative_to)) if relative_to is not None else str(urdf)
        return d

    @classmethod
    def from_json(cls, d: dict, relative_to: Path | None = None) -> "FurnitureAsset":
        d = dict(d)
        box = d.pop("in_region")
        urdf = Path(d.pop("urdf"))
        if relative_to is not None and not urdf.is_absolute():
            urdf = Path(relative_to) / urdf
        return cls(
            urdf=urdf,
            in_region=OrientedBox(
                center=tuple(box["center"]),
                half_extents=tuple(box["half_extents"]),
                rotation=tuple(tuple(r) for r in box["rotation"]),
            ),
            bounds_low=tuple(d.pop("bounds_low")),
            bounds_high=tuple(d.pop("bounds_high")),
            front=tuple(d.pop("front")),
            **d,
        )

    def save(self, path: Path) -> None:
        path = Path(path)
        path.write_text(json.dumps(self.to_json(relative_to=path.parent), indent=2, sort_keys=True) + "\n")

    @classmethod
    def load(cls, path: Path) -> "FurnitureAsset":
        path = Path(path)
        return cls.from_json(json.loads(path.read_text()), relative_to=path.parent)


def rest_joint_values(asset: "FurnitureAsset", joint_names: list[str], limits: np.ndarray) -> np.ndarray:
    """Where each joint rests when the furniture is closed: the value the asset records
    (``extra["closed_qpos_by_joint"]``, PartNet-Mobility objects), else the end of its range
    nearest 0 (unlimited joints such as knobs rest at 0); the target joint at ``closed_qpos``.

    joint_names: the articulation's active joints in order; limits (J, 2). Returns (J,).
    """
    rest = np.clip(np.zeros(len(joint_names)), limits[:, 0], limits[:, 1])
    closed_by_joint = asset.extra.get("closed_qpos_by_joint", {})
    for i, name in enumerate(joint_names):
        if name in closed_by_joint:
            rest[i] = float(closed_by_joint[name])
        if name == asset.target_joint:
            rest[i] = asset.closed_qpos
    return rest
