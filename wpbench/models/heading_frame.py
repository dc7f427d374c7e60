"""The heading frame: a yaw about world z chosen from the scene itself.

Furniture stands at any yaw, and a point network that sees world xyz has to
learn the same function at every yaw (with yaw augmentation and many more
samples than a CPU budget allows). Instead the models run in a frame turned
about z so that the horizontal direction from the anchor's centroid to the
action's centroid is +x. In every wpbench scene that direction points roughly
out of the furniture's front (the door is on the front face; the free object
starts in front), so what is left to learn is a spread of tens of degrees,
not a full turn.

A second choice of direction, ``source="action_panel"``, is the normal of
the action object's footprint: the least-spread horizontal axis of its points,
signed to point away from the anchor's centroid. A closed door or drawer is
seen as a vertical panel on the furniture's front, so that normal is the
front direction itself, whereas a drawer's centroid sits above, below or
beside the chest's, hardly in front of it, so the centroid direction can be
far from the direction the drawer slides (docs/models.md has the numbers).

Either frame is a function of the input clouds, so a model run in it is exactly
equivariant to yaw: turning the scene by ``A`` turns the prediction to
``A T A^-1``. Gravity stays along z (only yaw is removed), and translation is
untouched (the encoders centre the clouds themselves).

Shapes: clouds (B, N, 3); rotations (B, 3, 3) act on column vectors, so a cloud
is mapped with ``points @ R.transpose(1, 2)``.
"""

from __future__ import annotations

import torch

from wpbench.models.configs import HEADING_SOURCES, HeadingSource

# Below this horizontal offset (m) the heading is undefined: keep the world frame.
MIN_OFFSET = 1e-6


def heading_rotation(action: torch.Tensor, anchor: torch.Tensor, source: HeadingSource = "centroids") -> torch.Tensor:
    """Rotation about z taking the scene's heading direction onto +x.

    source "centroids": the xy direction anchor centroid -> action centroid;
    "action_panel": the normal of the action's xy footprint, signed like that direction.
    action (B, NA, 3), anchor (B, NB, 3) -> R (B, 3, 3), with ``R @ heading`` along +x.
    Where the direction is undefined (centroids on one vertical line), R is the identity.
    """
    if action.dim() != 3 or anchor.dim() != 3 or action.shape[-1] != 3 or anchor.shape[-1] != 3:
        raise ValueError(f"expected (B, N, 3) clouds, got {tuple(action.shape)} and {tuple(anchor.shape)}")
    if source not in HEADING_SOURCES:
        raise ValueError(f"unknown heading source {source!r}; choose one of {HEADING_SOURCES}")
    with torch.no_grad():
        offset = action.mean(dim=1)[:, :2] - anchor.mean(dim=1)[:, :2]  # (B, 2)
        if source == "action_panel":
            offset = _footprint_normal(action, offset)
        length = offset.norm(dim=-1, keepdim=True)
        defined = length > MIN_OFFSET
        unit = torch.where(defined, offset / length.clamp_min(MIN_OFFSET), torch.tensor([1.0, 0.0], dtype=offset.dtype))
        c, s = unit[:, 0], unit[:, 1]
        R = torch.zeros(action.shape[0], 3, 3, dtype=action.dtype, device=action.device)
        # Rotation by -heading: [[c, s], [-s, c]] maps (c, s) to (1, 0).
        R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = c, s, -s, c
        R[:, 2, 2] = 1.0
    return R


def _footprint_normal(action: torch.Tensor, outward: torch.Tensor) -> torch.Tensor:
    """Unit minor axis (B, 2) of the action's xy scatter, on the side of ``outward`` (B, 2).

    Where ``outward`` is perpendicular to the axis (or zero), the sign is +; a round
    footprint has no minor axis and gets an arbitrary (but deterministic) one.
    """
    xy = action[..., :2] - action[..., :2].mean(dim=1, keepdim=True)
    scatter = xy.transpose(1, 2) @ xy  # (B, 2, 2)
    normal = torch.linalg.eigh(scatter).eigenvectors[..., 0]  # eigenvalues ascend: the least spread
    side = (normal * outward).sum(dim=-1, keepdim=True)
    return torch.where(side < 0, -normal, normal)


def to_heading_frame(rotation: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """World points or vectors (B, N, 3) -> heading frame, for R (B, 3, 3) from :func:`heading_rotation`."""
    return points @ rotation.transpose(1, 2)


def from_heading_frame(rotation: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Heading-frame points or vectors (B, N, 3) -> world frame (the inverse of :func:`to_heading_frame`)."""
    return points @ rotation
