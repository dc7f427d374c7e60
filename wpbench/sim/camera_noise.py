"""What a real depth camera and segmenter get wrong, applied to a clean SAPIEN picture.

Three effects, each off by default (the benchmark's published numbers use a clean camera):

- depth noise: every pixel's point slides along its viewing ray by a normal error whose
  standard deviation grows with the square of the distance, as a structured-light or
  stereo sensor's does (``depth_std`` is the standard deviation at 1 m);
- holes: pixels the sensor returns no depth for, at random (``hole_fraction``) and at depth
  edges, where a real sensor's returns break down (``edge_holes``);
- segmentation errors at part boundaries: pixels within ``boundary_px`` of another segment
  take a neighbour's label with probability one half, as a segmenter blurs a door's rim
  into the body around it.

Pictures are SAPIEN's: ``Position`` (H, W, 4) in the OpenGL camera frame (the camera looks
down -z), segmentation (H, W) of per-scene ids, 0 for background.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EDGE_JUMP = 0.05   # m: neighbouring pixels whose depths differ by more than this straddle a depth edge


@dataclass(frozen=True)
class CameraNoise:
    """How imperfect the camera is. depth_std: m of depth error at 1 m (scales with depth^2);
    hole_fraction: share of pixels dropped at random; edge_holes: drop pixels at depth edges;
    boundary_px: segmentation errors within this many pixels of a segment boundary."""

    depth_std: float = 0.0
    hole_fraction: float = 0.0
    edge_holes: bool = False
    boundary_px: int = 0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.depth_std) and self.depth_std >= 0):
            raise ValueError(f"depth_std must be a finite number >= 0, got {self.depth_std}")
        if not 0.0 <= self.hole_fraction < 1.0:
            raise ValueError(f"hole_fraction must be in [0, 1), got {self.hole_fraction}")
        if int(self.boundary_px) != self.boundary_px or self.boundary_px < 0:
            raise ValueError(f"boundary_px must be a whole number >= 0, got {self.boundary_px}")

    @property
    def is_clean(self) -> bool:
        return self.depth_std == 0 and self.hole_fraction == 0 and not self.edge_holes and self.boundary_px == 0

    @classmethod
    def from_settings(cls, settings: "CameraNoise | dict | None") -> "CameraNoise":
        """A CameraNoise from itself, a dict of its fields (as run.json stores it) or None (clean)."""
        if settings is None:
            return cls()
        if isinstance(settings, cls):
            return settings
        unknown = sorted(set(settings) - set(cls.__dataclass_fields__))
        if unknown:
            raise ValueError(f"unknown camera noise settings {unknown}; valid: {', '.join(cls.__dataclass_fields__)}")
        return cls(**settings)

    def settings(self) -> dict:
        """The fields that differ from a clean camera ({} for a clean one): what run.json records."""
        clean = CameraNoise()
        return {name: getattr(self, name) for name in self.__dataclass_fields__
                if getattr(self, name) != getattr(clean, name)}

    def tag(self) -> str:
        """A short folder-name suffix for these settings ("" for a clean camera)."""
        parts = {"depth_std": "depth{}", "hole_fraction": "holes{}", "edge_holes": "edges", "boundary_px": "seg{}px"}
        return "-".join(parts[name].format(value) for name, value in self.settings().items())


def apply_camera_noise(
    position: np.ndarray, segmentation: np.ndarray, noise: CameraNoise, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """(position (H, W, 4), segmentation (H, W)) as an imperfect camera would give them.

    Dropped pixels become background (segmentation 0). Returns new arrays; a clean
    ``noise`` returns the inputs unchanged (same objects, no random draws).
    """
    position = np.asarray(position)
    segmentation = np.asarray(segmentation)
    if position.ndim != 3 or position.shape[2] < 3 or segmentation.shape != position.shape[:2]:
        raise ValueError(f"need position (H, W, 4) and segmentation (H, W), "
                         f"got {position.shape} and {segmentation.shape}")
    if noise.is_clean:
        return position, segmentation
    xyz = position[..., :3].astype(np.float64)
    seg = segmentation.copy()
    distance = np.linalg.norm(xyz, axis=-1)
    seen = seg != 0
    if noise.boundary_px:
        seg = _blur_boundaries(seg, int(noise.boundary_px), rng)
    if noise.depth_std:
        error = rng.normal(0.0, 1.0, size=distance.shape) * noise.depth_std * distance**2
        scale = np.where(distance > 0, (distance + error) / np.maximum(distance, 1e-9), 1.0)
        xyz = xyz * scale[..., None]
    drop = np.zeros(seg.shape, dtype=bool)
    if noise.hole_fraction:
        drop |= rng.random(seg.shape) < noise.hole_fraction
    if noise.edge_holes:
        drop |= _depth_edges(-position[..., 2].astype(np.float64), seen)
    seg = np.where(drop, 0, seg)
    out = position.copy()
    out[..., :3] = xyz.astype(position.dtype)
    return out, seg


def _depth_edges(depth: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels with a 4-neighbour more than EDGE_JUMP nearer or farther, or next to background."""
    depth = np.where(seen, depth, np.inf)
    edge = np.zeros(depth.shape, dtype=bool)
    for axis in (0, 1):
        ahead = np.diff(depth, axis=axis)
        jump = ~(np.abs(ahead) <= EDGE_JUMP)          # inf - inf and inf - x count as jumps
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        edge[tuple(lo)] |= jump
        edge[tuple(hi)] |= jump
    return edge & seen


def _blur_boundaries(seg: np.ndarray, radius: int, rng: np.random.Generator) -> np.ndarray:
    """Pixels of an object within ``radius`` (Chebyshev) of another object's pixel take that
    object's label (the nearest such pixel's) with probability one half."""
    height, width = seg.shape
    neighbour = np.zeros_like(seg)
    offsets = sorted(((dy, dx) for dy in range(-radius, radius + 1) for dx in range(-radius, radius + 1)
                      if (dy, dx) != (0, 0)), key=lambda o: (max(abs(o[0]), abs(o[1])), o))
    for dy, dx in offsets:
        shifted = np.zeros_like(seg)
        ys, yd = slice(max(0, dy), height + min(0, dy)), slice(max(0, -dy), height + min(0, -dy))
        xs, xd = slice(max(0, dx), width + min(0, dx)), slice(max(0, -dx), width + min(0, -dx))
        shifted[yd, xd] = seg[ys, xs]          # shifted[y, x] = seg[y + dy, x + dx]
        other = (neighbour == 0) & (shifted != 0) & (seg != 0) & (shifted != seg)
        neighbour = np.where(other, shifted, neighbour)
    flip = (neighbour != 0) & (rng.random(seg.shape) < 0.5)
    return np.where(flip, neighbour, seg)
