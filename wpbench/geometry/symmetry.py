"""Rotational symmetry groups of objects, expressed in the object's own frame.

Convention: a symmetry ``S`` (3, 3) is a rotation of the object about its own
origin, in object coordinates, that leaves the object looking the same: an
object at world orientation ``R_o`` is indistinguishable from one at
``R_o S``. A group is a finite set of such rotations (``discrete``, always
containing the identity) optionally composed with every rotation about one
object-frame ``axis`` (a continuous symmetry, e.g. a cylinder or a bowl).
Elements are ``S_k Rot(axis, theta)``; every ``S_k`` must map the axis to
``+-axis`` so the set is a group.

How metrics use it (``metrics.rotation_error_deg``): see that module.
Matrices are stored in float64 and cast to the caller's dtype on use.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import torch

__all__ = ["Symmetry"]

_TOLERANCE = 1e-6


def _as_axis(axis: object) -> torch.Tensor:
    vector = torch.as_tensor(axis, dtype=torch.float64).detach().clone()
    if vector.shape != (3,):
        raise ValueError(f"axis must have shape (3,), got {tuple(vector.shape)}")
    norm = torch.linalg.vector_norm(vector)
    if not bool(torch.isfinite(vector).all()) or float(norm) == 0.0:
        raise ValueError(f"axis must be a finite non-zero vector, got {vector.tolist()}")
    return vector / norm


def _half_turn_about(axis: torch.Tensor) -> torch.Tensor:
    """Rotation by 180 degrees about unit ``axis`` (3,): ``2 a a^T - I``."""
    return 2.0 * torch.outer(axis, axis) - torch.eye(3, dtype=torch.float64)


def _perpendicular(axis: torch.Tensor) -> torch.Tensor:
    """A unit vector perpendicular to unit ``axis`` (3,)."""
    helper = torch.zeros(3, dtype=torch.float64)
    helper[int(torch.argmin(axis.abs()))] = 1.0
    perpendicular = torch.linalg.cross(axis, helper)
    return perpendicular / torch.linalg.vector_norm(perpendicular)


def _index_of(rotation: torch.Tensor, rotations: torch.Tensor) -> int | None:
    """Index of ``rotation`` (3, 3) in ``rotations`` (K, 3, 3), or None."""
    distance = (rotations - rotation).abs().flatten(1).amax(dim=1)
    hits = (distance < _TOLERANCE).nonzero().flatten()
    return int(hits[0]) if len(hits) else None


@dataclass(frozen=True)
class Symmetry:
    """Rotational symmetry group of an object, in its own frame.

    Attributes:
        discrete: (K, 3, 3) float64 rotations, including the identity, closed
            under composition.
        axis: (3,) float64 unit vector of a continuous symmetry, or None.
    """

    discrete: torch.Tensor
    axis: torch.Tensor | None = None

    def __post_init__(self) -> None:
        discrete = torch.as_tensor(self.discrete, dtype=torch.float64).detach().clone()
        if discrete.dim() != 3 or discrete.shape[1:] != (3, 3) or discrete.shape[0] == 0:
            raise ValueError(f"discrete must have shape (K, 3, 3) with K >= 1, got {tuple(discrete.shape)}")
        if not bool(torch.isfinite(discrete).all()):
            raise ValueError("discrete contains NaN/inf")
        eye = torch.eye(3, dtype=torch.float64)
        orthogonality = (discrete @ discrete.transpose(-1, -2) - eye).abs().amax()
        if float(orthogonality) > _TOLERANCE or bool((torch.linalg.det(discrete) < 0).any()):
            raise ValueError("discrete must hold rotations (orthonormal, det = +1); reflections are not symmetries here")
        if _index_of(eye, discrete) is None:
            raise ValueError("discrete must include the identity; Symmetry.from_discrete adds it for you")
        products = (discrete[:, None] @ discrete[None]).reshape(-1, 1, 3, 3)  # (K*K, 1, 3, 3)
        distance = (products - discrete[None]).abs().flatten(2).amax(-1)  # (K*K, K)
        if not bool((distance.amin(-1) < _TOLERANCE).all()):
            raise ValueError(
                "discrete is not closed under composition (not a group); "
                "list every product of its rotations, or use a ready-made group such as Symmetry.cube()"
            )
        axis = None if self.axis is None else _as_axis(self.axis)
        if axis is not None:
            images = discrete @ axis  # (K, 3)
            preserved = (images - axis).abs().amax(1) < _TOLERANCE
            reversed_ = (images + axis).abs().amax(1) < _TOLERANCE
            if not bool((preserved | reversed_).all()):
                raise ValueError("every discrete rotation must map axis to +axis or -axis (else it is not a group)")
        object.__setattr__(self, "discrete", discrete)
        object.__setattr__(self, "axis", axis)

    # ------------------------------------------------------------------ queries
    @property
    def order(self) -> int:
        """Number of discrete rotations K."""
        return int(self.discrete.shape[0])

    @property
    def is_trivial(self) -> bool:
        """True for the identity-only group (no symmetry)."""
        return self.axis is None and self.order == 1

    def discrete_as(self, like: torch.Tensor) -> torch.Tensor:
        """Discrete rotations (K, 3, 3) in ``like``'s dtype and device."""
        return self.discrete.to(dtype=like.dtype, device=like.device)

    def axis_as(self, like: torch.Tensor) -> torch.Tensor | None:
        """Continuous axis (3,) in ``like``'s dtype and device, or None."""
        return None if self.axis is None else self.axis.to(dtype=like.dtype, device=like.device)

    # ------------------------------------------------------- ready-made groups
    @classmethod
    def none(cls) -> Symmetry:
        """No symmetry: the identity only."""
        return cls(torch.eye(3, dtype=torch.float64)[None])

    @classmethod
    def from_discrete(cls, mats: object) -> Symmetry:
        """Group from a finite list of rotations (K, 3, 3) (tensor, array or list of 3x3); the identity is added if missing."""
        if isinstance(mats, (list, tuple)):
            rotations = torch.stack([torch.as_tensor(m, dtype=torch.float64) for m in mats]) if mats else torch.zeros(0, 3, 3)
        else:
            rotations = torch.as_tensor(mats, dtype=torch.float64)
        if rotations.dim() == 2:
            rotations = rotations[None]
        eye = torch.eye(3, dtype=torch.float64)
        if rotations.dim() == 3 and rotations.shape[1:] == (3, 3) and _index_of(eye, rotations) is None:
            rotations = torch.cat([eye[None], rotations])
        return cls(rotations)

    @classmethod
    def cube(cls) -> Symmetry:
        """The 24 rotations of a cube centred at the origin with axis-aligned faces.

        They are exactly the signed permutation matrices with determinant +1.
        """
        rotations = []
        for perm in itertools.permutations(range(3)):
            for signs in itertools.product((1.0, -1.0), repeat=3):
                matrix = torch.zeros(3, 3, dtype=torch.float64)
                for row, column in enumerate(perm):
                    matrix[row, column] = signs[row]
                if float(torch.linalg.det(matrix)) > 0:
                    rotations.append(matrix)
        # Put the identity first so index 0 is "no symmetry used".
        rotations.sort(key=lambda m: -float(torch.trace(m)))
        return cls(torch.stack(rotations))

    @classmethod
    def box(cls) -> Symmetry:
        """A box with three different side lengths: identity and the half turns about x, y, z."""
        eye = torch.eye(3, dtype=torch.float64)
        return cls(torch.stack([eye] + [_half_turn_about(eye[i]) for i in range(3)]))

    @classmethod
    def axial(cls, axis: object = (0.0, 0.0, 1.0)) -> Symmetry:
        """Continuous symmetry about ``axis`` (3,) only, e.g. a bowl or a cup without handle."""
        return cls(torch.eye(3, dtype=torch.float64)[None], axis=axis)

    @classmethod
    def cylinder(cls, axis: object = (0.0, 0.0, 1.0)) -> Symmetry:
        """A closed cylinder: continuous about ``axis`` plus the 180 degree flip end over end.

        The flip is a half turn about a direction perpendicular to the axis;
        composed with the continuous part it covers every perpendicular flip.
        """
        unit = _as_axis(axis)
        flip = _half_turn_about(_perpendicular(unit))
        return cls(torch.stack([torch.eye(3, dtype=torch.float64), flip]), axis=unit)
