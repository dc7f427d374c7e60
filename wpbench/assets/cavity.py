"""Find the free cavity of a piece of furniture from its convex collision pieces.

No hand annotation: the cavity that a door closes is the free space that is
*enclosed* when the door is closed and *not enclosed* once the door is taken
away. On a voxel grid over the object (body frame, metres):

1. occupancy: a voxel is occupied when its cube may touch a convex piece
   (each piece's face planes pushed out by the voxel's half diagonal in the
   L1 sense; this over-marks near edges, which only makes the free space
   smaller, never leaky, so thin walls are never missed);
2. enclosure: a free voxel is enclosed when the grid rays in +x, -x, +y, -y,
   +z, -z from it all hit an occupied voxel;
3. released = enclosed(with door) AND NOT enclosed(without door); the cavity
   is the connected component of enclosed(with door) holding most released
   voxels (so space below a lip at the opening counts too);
4. the region is the largest axis-aligned box of whole free voxels inside the
   cavity (exhaustive over slab pairs along the shortest axis + largest
   rectangle in a histogram), shrunk by a margin, its bottom then lowered
   onto the supporting surface (:func:`drop_to_support`).

A drawer has no body-side cavity of its own: its region is the open drawer's
inner volume, found the same way from the drawer's pieces alone with the top
left open (rays in +z need not hit anything).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError

from wpbench.assets.spec import OrientedBox


@dataclass(frozen=True)
class CavityConfig:
    """How the cavity search discretises space.

    cells_along_largest: voxels along the largest side of the searched bounds.
    margin: metres by which the found box is shrunk on every side (keeps the
        region clear of the walls, so "inside" means well inside).
    """

    cells_along_largest: int = 64
    margin: float = 0.01


@dataclass(frozen=True)
class VoxelGrid:
    """Cubic voxels: voxel (i, j, k) spans ``origin + [i, i+1] * size`` (and so on per axis)."""

    origin: np.ndarray  # (3,)
    size: float
    shape: tuple[int, int, int]

    @classmethod
    def covering(cls, low: np.ndarray, high: np.ndarray, cells_along_largest: int) -> "VoxelGrid":
        low, high = np.asarray(low, float), np.asarray(high, float)
        size = float(np.max(high - low)) / cells_along_largest
        shape = tuple(int(n) for n in np.maximum(np.ceil((high - low) / size - 1e-9), 1))
        return cls(origin=low, size=size, shape=shape)

    def centers(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """(hi-lo product, 3) centres of voxels with index in [lo, hi) per axis, C order."""
        axes = [self.origin[a] + (np.arange(lo[a], hi[a]) + 0.5) * self.size for a in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def occupancy(pieces: list[np.ndarray], grid: VoxelGrid) -> np.ndarray:
    """Conservative occupancy (shape grid.shape, bool) of convex pieces given as vertex sets (K_i, 3)."""
    occ = np.zeros(grid.shape, dtype=bool)
    half = grid.size / 2
    for vertices in pieces:
        vmin, vmax = vertices.min(0), vertices.max(0)
        lo = np.clip(np.floor((vmin - half - grid.origin) / grid.size).astype(int), 0, grid.shape)
        hi = np.clip(np.ceil((vmax + half - grid.origin) / grid.size).astype(int) + 1, 0, grid.shape)
        if np.any(hi <= lo):
            continue
        centers = grid.centers(lo, hi)
        try:
            equations = ConvexHull(vertices).equations  # (F, 4): n . x + d <= 0 inside, |n| = 1
        except (QhullError, ValueError):
            # Flat piece (a wall of zero thickness): its bounding box, dilated, stands in for it.
            inside = np.all((centers >= vmin - half) & (centers <= vmax + half), axis=1)
        else:
            normals, offsets = equations[:, :3], equations[:, 3]
            slack = half * np.abs(normals).sum(1)
            inside = np.all(centers @ normals.T + offsets - slack <= 0, axis=1)
            inside &= np.all((centers >= vmin - half) & (centers <= vmax + half), axis=1)
        occ[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] |= inside.reshape(tuple(hi - lo))
    return occ


def _hit_along(occ: np.ndarray, axis: int, forward: bool) -> np.ndarray:
    """Whether a ray from each voxel along +axis (forward) or -axis meets an occupied voxel."""
    if forward:
        return np.flip(np.logical_or.accumulate(np.flip(occ, axis), axis=axis), axis)
    return np.logical_or.accumulate(occ, axis=axis)


def enclosed(occ: np.ndarray, open_top: bool = False) -> np.ndarray:
    """Free voxels whose six axis rays all hit occupied voxels (``open_top``: +z may escape)."""
    result = ~occ
    for axis in range(3):
        for forward in (True, False):
            if open_top and axis == 2 and forward:
                continue
            result &= _hit_along(occ, axis, forward)
    return result


def largest_component(mask: np.ndarray) -> np.ndarray:
    """The largest 6-connected component of a boolean mask (all False if empty)."""
    labels, count = ndimage.label(mask)
    if count == 0:
        return mask & False
    sizes = np.bincount(labels.ravel())[1:]
    return labels == (1 + int(np.argmax(sizes)))


def _largest_rectangle(mask2d: np.ndarray) -> tuple[int, tuple[int, int, int, int]]:
    """Largest all-True rectangle of a 2D mask: (area, (r0, r1, c0, c1)) with exclusive r1, c1."""
    rows, cols = mask2d.shape
    heights = [0] * cols
    best = (0, (0, 0, 0, 0))
    for r in range(rows):
        row = mask2d[r]
        for c in range(cols):
            heights[c] = heights[c] + 1 if row[c] else 0
        stack: list[int] = []  # column indices with increasing heights
        for c in range(cols + 1):
            h = heights[c] if c < cols else 0
            while stack and heights[stack[-1]] >= h:
                top = stack.pop()
                width = c - (stack[-1] + 1 if stack else 0)
                area = heights[top] * width
                if area > best[0]:
                    c0 = stack[-1] + 1 if stack else 0
                    best = (area, (r - heights[top] + 1, r + 1, c0, c))
            stack.append(c)
    return best


def largest_box(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Largest axis-aligned all-True box of a 3D mask: (lo, hi) voxel indices, hi exclusive; None if empty."""
    if not mask.any():
        return None
    nonzero = np.argwhere(mask)
    crop_lo, crop_hi = nonzero.min(0), nonzero.max(0) + 1
    sub = mask[tuple(slice(a, b) for a, b in zip(crop_lo, crop_hi))]
    # Slab pairs along the shortest axis keep the number of 2D problems small.
    axis = int(np.argmin(sub.shape))
    sub = np.moveaxis(sub, axis, 0)
    n = sub.shape[0]
    best_volume, best = 0, None
    for s0 in range(n):
        projection = sub[s0].copy()
        for s1 in range(s0 + 1, n + 1):
            if s1 > s0 + 1:
                projection &= sub[s1 - 1]
            thickness = s1 - s0
            if int(projection.sum()) * thickness <= best_volume:
                if not projection.any():
                    break
                continue
            area, (r0, r1, c0, c1) = _largest_rectangle(projection)
            if area * thickness > best_volume:
                best_volume, best = area * thickness, (s0, s1, r0, r1, c0, c1)
    s0, s1, r0, r1, c0, c1 = best
    lo_moved, hi_moved = np.array([s0, r0, c0]), np.array([s1, r1, c1])
    # Undo moveaxis: moved axis 0 is original `axis`, the rest keep their order.
    order = [axis] + [a for a in range(3) if a != axis]
    lo, hi = np.zeros(3, int), np.zeros(3, int)
    lo[order], hi[order] = lo_moved, hi_moved
    return lo + crop_lo, hi + crop_lo


def _box_from_voxels(
    grid: VoxelGrid, lo: np.ndarray, hi: np.ndarray, margin: float, limit_high: np.ndarray
) -> OrientedBox | None:
    """Box of whole voxels [lo, hi) shrunk by ``margin``; the grid overhangs ``limit_high``, so clip to it."""
    low = grid.origin + lo * grid.size + margin
    high = np.minimum(grid.origin + hi * grid.size, limit_high) - margin
    if np.any(high <= low):
        return None
    center = (low + high) / 2
    return OrientedBox(center=tuple(float(v) for v in center), half_extents=tuple(float(v) for v in (high - low) / 2))


def _vertical_extent(equations: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(bottom, top) z of a convex piece on vertical lines through ``xy`` (M, 2); bottom > top if missed."""
    normals, offsets = equations[:, :3], equations[:, 3]
    # Each face n . p + d <= 0 bounds z from above (n_z > 0) or below (n_z < 0) on a vertical line.
    rhs = -(offsets[None, :] + xy @ normals[:, :2].T)  # (M, F): n_z z <= rhs
    nz = normals[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = rhs / nz[None, :]
    top = np.min(np.where(nz[None, :] > 1e-9, bound, np.inf), axis=1)
    bottom = np.max(np.where(nz[None, :] < -1e-9, bound, -np.inf), axis=1)
    side_ok = np.all(np.where(np.abs(nz)[None, :] <= 1e-9, rhs >= 0, True), axis=1)
    return np.where(side_ok, bottom, np.inf), np.where(side_ok, top, -np.inf)


def drop_to_support(box: OrientedBox, pieces: list[np.ndarray], quantile: float = 0.2) -> OrientedBox:
    """Lower the box's bottom face onto the surface that holds up what is put in it.

    The voxel search leaves the bottom up to ~2 voxels (+ margin) above the real
    floor, because occupancy is conservative; an object released in the box
    would then settle below it. On an 8 x 8 grid of vertical lines through the
    box footprint, the support is the highest piece top below the box bottom;
    the new bottom is a low quantile of those heights (an uneven floor, a
    gap between pieces must not drag the box far down, hence not the minimum).
    """
    low = np.asarray(box.center) - np.asarray(box.half_extents)
    high = np.asarray(box.center) + np.asarray(box.half_extents)
    u = np.linspace(0.05, 0.95, 8)
    xy = np.stack(np.meshgrid(low[0] + u * (high[0] - low[0]), low[1] + u * (high[1] - low[1]),
                              indexing="ij"), axis=-1).reshape(-1, 2)
    support = np.full(len(xy), -np.inf)
    for vertices in pieces:
        vmin, vmax = vertices.min(0), vertices.max(0)
        if vmin[2] >= low[2] or np.any(vmax[:2] < low[:2]) or np.any(vmin[:2] > high[:2]):
            continue
        try:
            equations = ConvexHull(vertices).equations
        except (QhullError, ValueError):
            continue
        bottom, top = _vertical_extent(equations, xy)
        hit = (bottom <= top) & (top <= low[2] + 1e-6)
        support = np.where(hit, np.maximum(support, top), support)
    found = support[np.isfinite(support)]
    if len(found) == 0:
        return box
    floor = float(np.quantile(found, quantile))
    if floor >= low[2]:
        return box
    low[2] = floor
    return OrientedBox(center=tuple(float(v) for v in (low + high) / 2),
                       half_extents=tuple(float(v) for v in (high - low) / 2), rotation=box.rotation)


def door_cavity(
    anchor_pieces: list[np.ndarray],
    door_pieces: list[np.ndarray],
    low: np.ndarray,
    high: np.ndarray,
    config: CavityConfig = CavityConfig(),
) -> OrientedBox | None:
    """The box behind a closed door: free, enclosed with the door, open without it.

    anchor_pieces / door_pieces: body-frame vertex sets (K_i, 3) of convex pieces,
    door closed. low / high: (3,) bounds of the whole object. None if no cavity.
    """
    grid = VoxelGrid.covering(low, high, config.cells_along_largest)
    occ_anchor = occupancy(anchor_pieces, grid)
    occ_closed = occ_anchor | occupancy(door_pieces, grid)
    inside_closed = enclosed(occ_closed)
    released = inside_closed & ~enclosed(occ_anchor)
    # The cavity is all the enclosed space connected to what the door releases: a lip
    # at the opening keeps the space below it enclosed without the door, yet an object
    # put in falls there, so it belongs to the cavity.
    labels, _count = ndimage.label(inside_closed)
    counts = np.bincount(labels[released], minlength=labels.max() + 1)
    counts[0] = 0
    cavity = labels == int(np.argmax(counts)) if counts.max() > 0 else np.zeros_like(released)
    found = largest_box(cavity)
    box = None if found is None else _box_from_voxels(grid, *found, config.margin, np.asarray(high, float))
    return None if box is None else drop_to_support(box, anchor_pieces)


def drawer_inner_volume(
    drawer_pieces: list[np.ndarray], config: CavityConfig = CavityConfig()
) -> OrientedBox | None:
    """The box inside an (open) drawer: free, walled on four sides and below by the drawer itself."""
    all_vertices = np.concatenate(drawer_pieces)
    grid = VoxelGrid.covering(all_vertices.min(0), all_vertices.max(0), config.cells_along_largest)
    inside = largest_component(enclosed(occupancy(drawer_pieces, grid), open_top=True))
    found = largest_box(inside)
    box = None if found is None else _box_from_voxels(grid, *found, config.margin, all_vertices.max(0))
    return None if box is None else drop_to_support(box, drawer_pieces)
