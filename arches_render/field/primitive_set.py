"""Thousands to millions of capsules (and spheres) as arrays behind a sparse grid.

Unrolling a union of N primitives into the kernel makes JIT compilation explode
(an unrolled tree of 300 nodes compiled 17x slower in a prototype). A
:class:`CapsuleSet` instead stores the segments ``[a_i, b_i]`` and radii ``r_i`` in
Dr.Jit arrays, and a grid of cells each listing the primitives whose box, grown by
a margin ``m``, overlaps the cell. A point looks at its own cell only and returns

    f(p) = max(-m, max_{i in cell(p)} (r_i - dist(p, [a_i, b_i]))).

Why this is exact where it matters: a primitive missing from ``cell(p)`` lies
farther than ``m`` from ``p``, so its exact distance field is ``<= -m`` there. Hence
``f = max(-m, union)`` *everywhere* in the grid: the surface is exact, the field is
1-Lipschitz and continuous, and it is merely clamped at ``-m`` far from matter
(a sphere tracer then steps ``m`` at a time through empty cells). Outside the grid
box (which contains every primitive grown by ``m``) ``f = -m - dist(p, box)``, which
is below the true union field and joins it continuously at the box.

The grid (:class:`~arches_render.field.brick_grid.BrickGrid`) stores its cells in
bricks of 8^3, only where some grown box reaches, so cells stay as small as the
capsules at any count (a dense grid capped at 64^3 cells held 174 capsules a cell at
a million); capsules are sorted by cell and packed in 32-byte records.

Empty space: a distance transform of the occupied cells gives, for each cell, the
gap (box to box) to the nearest cell holding a primitive of its own
(:func:`~arches_render.field.brick_grid.cell_gaps`); every primitive point lies in
such a cell, so from any ``p`` in the cell the set is at least that far away (per
brick on large grids, see :mod:`~arches_render.field.brick_grid`). ``eval_bounds``
returns the larger of that and ``-f``, so rays cross sparse sets in strides longer
than ``m``.

Spheres are capsules with ``a = b``.

References
----------
Amanatides, J., Woo, A. (1987). A fast voxel traversal algorithm for ray tracing.
Eurographics '87 (uniform grids for ray queries).
Museth, K. (2013). VDB: High-resolution sparse volumes with dynamic topology. ACM
TOG 32(3) (leaf bricks of 8^3 voxels).
Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
38(5) (a grid/BVH over primitive boxes to accelerate large construction trees).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .brick_grid import BRICK, MAX_BRICKS, BrickGrid, cell_gaps, cell_ranges
from .node import Node, box_distance, opaque_float
from .packed_columns import gather_columns, pack_columns

#: Floats a capsule takes in the record array (a, b, r, padding to 32 bytes).
CAPSULE_RECORD = 8


def grid_lists(lo_boxes, hi_boxes, grid_lo, cell, res, balls=None):
    """CSR lists of the primitives overlapping each cell (vectorized over primitives).

    Parameters
    ----------
    lo_boxes, hi_boxes : ndarray
        ``(N, 3)`` primitive boxes.
    grid_lo, cell, res
        The grid's corner, cell edge and cells per axis.
    balls : (ndarray, ndarray), optional
        ``(N, 3)`` centres and ``(N,)`` radii of balls that hold the primitives: a cell
        that its primitive's box overlaps but its ball misses is left out (a ball of
        radius ``R`` touches about 0.74 of the cells its box does when cells are ``R``
        wide: the box's corners).

    Returns
    -------
    (start, count, index)
        ``prod(res)`` uint32 list starts and lengths (cells in ``(z, y, x)`` order) and
        the uint32 entries, each cell's in increasing primitive order.
    """
    i0 = np.clip(np.floor((lo_boxes - grid_lo) / cell).astype(np.int64), 0, res - 1)
    i1 = np.clip(np.floor((hi_boxes - grid_lo) / cell).astype(np.int64), 0, res - 1)
    span = i1 - i0 + 1
    counts = span.prod(axis=1)
    prim = np.repeat(np.arange(len(lo_boxes)), counts)
    # Enumerate each primitive's block of cells with a per-primitive local index.
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    sx, sy = span[prim, 0], span[prim, 1]
    cx = i0[prim, 0] + local % sx
    cy = i0[prim, 1] + (local // sx) % sy
    cz = i0[prim, 2] + local // (sx * sy)
    if balls is not None:
        centre, radius = balls
        corner = np.stack([cx, cy, cz], axis=1) * cell + grid_lo
        gap = np.clip(centre[prim], corner, corner + cell) - centre[prim]
        touch = np.einsum("ij,ij->i", gap, gap) <= radius[prim] ** 2
        prim, cx, cy, cz = prim[touch], cx[touch], cy[touch], cz[touch]
    cell_id = (cz * res[1] + cy) * res[0] + cx
    order = np.argsort(cell_id, kind="stable")
    n_cells = int(np.prod(res))
    cell_count = np.bincount(cell_id, minlength=n_cells)
    cell_start = np.concatenate([[0], np.cumsum(cell_count)[:-1]])
    return cell_start.astype(np.uint32), cell_count.astype(np.uint32), prim[order].astype(np.uint32)


def empty_distance(lo_boxes, hi_boxes, grid_lo, cell, res):
    """Per cell, a lower bound of the distance from any of its points to the set: the
    gap to the nearest cell a box touches (:func:`.brick_grid.cell_gaps`)."""
    i0 = np.clip(np.floor((lo_boxes - grid_lo) / cell).astype(np.int64), 0, res - 1)
    i1 = np.clip(np.floor((hi_boxes - grid_lo) / cell).astype(np.int64), 0, res - 1)
    occupied = np.zeros(tuple(res[::-1]), dtype=bool)  # (z, y, x) to match the cell index
    for (x0, y0, z0), (x1, y1, z1) in zip(i0, i1):
        occupied[z0:z1 + 1, y0:y1 + 1, x0:x1 + 1] = True
    return (cell_gaps(occupied) * cell).ravel()


#: Cell entries :func:`unlisted_gaps` enumerates at a time (bounds its memory).
GAP_CHUNK = 1 << 22


def unlisted_gaps(lo_boxes, hi_boxes, grid_lo, cell, res, margin, reach):
    """Per cell, a lower bound of the distance from any of its points to the boxes *left
    out* of its list of boxes grown by ``margin`` (:func:`grid_lists`), at most ``reach``.

    A box is left out of a cell's list where, along some axis, the cell's index lies
    outside the (clipped) range of cells the grown box overlaps: there the box is more
    than ``margin`` from the cell, so ``margin`` always bounds the gap. The bound is
    usually much larger: the smallest Euclidean box-to-box distance from the cell to
    the boxes left out, found over the lists of boxes grown by ``reach`` (a box left
    out of those is at least ``reach`` away, by the same argument). A tracer that
    stops its steps at ``margin`` (the nearest unlisted primitive could be there) may
    then go as far as this gap.

    Parameters
    ----------
    lo_boxes, hi_boxes : numpy.ndarray
        ``(N, 3)`` boxes.
    grid_lo, cell, res
        The grid, as for :func:`grid_lists`.
    margin : float
        The growth of the boxes of the lists the gaps complement.
    reach : float
        Largest gap reported (``>= margin``); cost grows with ``(reach / cell)^3`` a box.

    Returns
    -------
    numpy.ndarray
        ``(prod(res),)`` float64 gaps in the cell order of :func:`grid_lists`, a part
        in 1e5 of the gap and 1e-4 cell edges shaved off (float32 rounding of a
        point's cell lookup cannot overstate a gap), never below ``margin`` less that.
    """
    def ranges(grow):
        i0 = np.clip(np.floor((lo_boxes - grow - grid_lo) / cell).astype(np.int64), 0, res - 1)
        i1 = np.clip(np.floor((hi_boxes + grow - grid_lo) / cell).astype(np.int64), 0, res - 1)
        return i0, i1

    n0, n1 = ranges(margin)
    r0, r1 = ranges(reach)
    gaps = np.full(int(np.prod(res)), float(reach))
    span = r1 - r0 + 1
    counts = span.prod(axis=1)
    first = 0
    while first < len(counts):
        # Boxes [first, last) enumerate at most GAP_CHUNK cells (at least one box).
        last = max(first + 1, int(np.searchsorted(np.cumsum(counts[first:]), GAP_CHUNK)) + first)
        sl = slice(first, last)
        c = counts[sl]
        prim = np.repeat(np.arange(first, last), c)
        local = np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c)
        sx, sy = span[prim, 0], span[prim, 1]
        idx = np.stack([r0[prim, 0] + local % sx, r0[prim, 1] + (local // sx) % sy,
                        r0[prim, 2] + local // (sx * sy)], axis=1)
        out = ((idx < n0[prim]) | (idx > n1[prim])).any(axis=1)
        idx, prim = idx[out], prim[out]
        cell_lo = grid_lo + idx * cell
        gap = np.maximum(np.maximum(lo_boxes[prim] - (cell_lo + cell), cell_lo - hi_boxes[prim]), 0.0)
        cell_id = (idx[:, 2] * res[1] + idx[:, 1]) * res[0] + idx[:, 0]
        np.minimum.at(gaps, cell_id, np.sqrt(np.sum(gap * gap, axis=1)))
        first = last
    return np.maximum(gaps * (1.0 - 1e-5) - 1e-4 * cell, 0.0)


class CapsuleSet(Node):
    """Union of capsules ``(a_i, b_i, r_i)`` evaluated through a grid.

    Parameters
    ----------
    a, b : array_like
        ``(N, 3)`` segment end points (equal for spheres).
    radius : array_like
        ``(N,)`` radii, > 0.
    cell_size : float, optional
        Grid cell edge; default about twice the median primitive size.
    margin : float, optional
        The clamp ``m``; default one cell edge.
    max_cells : int
        Upper bound on the number of stored cells (8 bytes each); the cell edge
        grows where a set would need more.
    """

    kind = "capsule_set"

    def __init__(self, a, b, radius, cell_size=None, margin=None, max_cells=1 << 23):
        a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
        r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(a),)).copy()
        if len(a) == 0 or a.shape != b.shape:
            raise ValueError("capsule_set needs matching, non-empty (N, 3) arrays a and b")
        if not np.all(r > 0):
            raise ValueError("capsule_set radii must be > 0")
        self.n = len(a)
        self.a_np, self.b_np, self.r_np = a, b, r
        lo_p = np.minimum(a, b) - r[:, None]
        hi_p = np.maximum(a, b) + r[:, None]
        self.prim_lo, self.prim_hi = lo_p.min(axis=0), hi_p.max(axis=0)
        size = float(np.median((hi_p - lo_p).max(axis=1)))
        cell = float(cell_size) if cell_size else size
        # Cells as small as the primitives; coarser only where the stored bricks (or
        # the top grid of bricks) would pass their limits: a huge, dense set.
        while True:
            m = float(margin) if margin else 0.5 * cell
            grid_lo = self.prim_lo - m
            res = np.maximum(np.ceil((self.prim_hi + m - grid_lo) / cell).astype(np.int64), 1)
            if np.prod(-(-res // BRICK)) <= MAX_BRICKS:
                i0, i1 = cell_ranges(lo_p - m, hi_p + m, grid_lo, cell, res)
                stored = BrickGrid.stored_bricks(i0, i1, res)
                if int(stored.sum()) * BRICK ** 3 <= max_cells:
                    break
            cell *= 1.25
        self.margin_np = m
        # Primitives in the order of the cells of their centres: a cell's list then
        # reads nearby memory (the field's value does not depend on the order).
        centre = 0.5 * (lo_p + hi_p)
        order = np.argsort(BrickGrid.cell_order(centre, grid_lo, cell, res), kind="stable")
        a, b, r, lo_p, hi_p = a[order], b[order], r[order], lo_p[order], hi_p[order]
        self.grid = BrickGrid(i0[order], i1[order], lo_p, hi_p, grid_lo, cell, res, stored)
        self.grid_lo, self.cell, self.res = grid_lo, cell, res
        self.grid_hi = grid_lo + res * cell
        self.max_per_cell, self.list_len = self.grid.max_per_cell, self.grid.list_len
        # One record of 8 floats (a, b, r, unused) a capsule: a list entry costs one
        # cache line, not seven (the arrays of a large set do not fit in caches), and
        # one packet gather (:mod:`.packed_columns`; 10^4 capsules, random points:
        # 22 -> 32 M evaluations/s).
        self._records, _ = pack_columns([*a.T, *b.T, r])
        self._m = opaque_float(m)
        self._glo = [opaque_float(v) for v in grid_lo]
        self._ghi = [opaque_float(v) for v in self.grid_hi]

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        f = self.eval(p)
        empty = self.grid.empty_distance(p)
        return f, tuple(dr.maximum(dr.maximum(-f - c, 0.0), empty - c) for c in levels)

    def eval(self, p):
        start, count = self.grid.cell_list(p)
        index = self.grid.index

        def body(i, f):
            field = gather_columns(self._records, dr.gather(mi.UInt32, index, start + i), CAPSULE_RECORD, 7)
            a = mi.Point3f(*field[0:3])
            pa, ba = p - a, mi.Point3f(*field[3:6]) - a
            t = dr.clip(dr.dot(pa, ba) / dr.maximum(dr.squared_norm(ba), 1e-20), 0.0, 1.0)
            d = field[6] - dr.norm(pa - ba * t)
            return i + 1, dr.maximum(f, d)

        _, inside = dr.while_loop((mi.UInt32(0), -self._m + mi.Float(0.0)),
                                  lambda i, f: i < count, body, label="capsule_set")
        outside = box_distance(p, self._glo, self._ghi)
        return dr.select(outside > 0.0, -self._m - outside, inside)

    def bounds(self):
        return self.prim_lo.copy(), self.prim_hi.copy()

    # Clamped at -m inside the grid: slower than unit rate beyond m from the box.
    unit_falloff = False

    @property
    def cost(self):
        return 3.0 + min(self.max_per_cell, 16)

    @property
    def lipschitz(self):
        return 1.0

    def nbytes(self):
        return 64 + self.n * CAPSULE_RECORD * 4 + self.grid.nbytes()
