"""A sparse two-level grid over primitive boxes: bricks of 8^3 cells, stored where occupied.

A uniform grid over a large primitive set either has few cells (many primitives
per cell: a point loops over hundreds) or many (memory for every empty cell of the
air above a terrain). Here a dense *top* grid of bricks holds, per brick, a slot
number or ``NO_SLOT``; only bricks that some primitive's box touches store their
``8^3`` cells (CSR list offsets and an empty-space bound). A point finds
its cell with one more gather than in a dense grid::

    brick = top[(iz >> 3, iy >> 3, ix >> 3)]        # slot or NO_SLOT
    cell  = brick * 512 + ((iz & 7) * 8 + (iy & 7)) * 8 + (ix & 7)

so cells can stay as small as the primitives at any set size: a million capsules
at the density of ten thousand cost the same per evaluation (the lists are built
by a counting sort, :mod:`.brick_grid_kernels`).

Thin grids and sparse bands. A :class:`BrickLayout` built from a grid's cells
(:meth:`BrickLayout.of_cells`) takes bricks no deeper than the grid on each axis
(:func:`brick_shape`: ``8 x 8 x 4`` for a grid four cells deep), and smaller bricks
where they take less memory (a band of cells along a coast), with the same lookup by
shifts and masks.

List offsets. A cell's list is read between its offset and the next; in a set whose
entries are 16-bit, the offsets are too, relative to each brick's first
(:func:`relative_offsets`: 2 bytes a cell instead of 4, for one more gather a lookup).

Empty space. For each stored cell, a lower bound of the distance from its points
to the primitives' boxes: the gap, box to box, between the cell and the nearest cell
a box touches (:func:`cell_gaps`); for an unstored brick, the same at brick scale.
The transform runs on the whole fine grid while it is small (``DENSE_EDT_CELLS``: the
bound is then the exact one of a dense grid); beyond, each stored brick is transformed
on its own and the bound also capped by the distance to the brick's faces (anything
nearer than that lies inside the brick).

References
----------
Museth, K. (2013). VDB: High-resolution sparse volumes with dynamic topology. ACM
TOG 32(3) (a shallow tree of dense leaf bricks of 8^3 voxels).
Danielsson, P.-E. (1980). Euclidean distance mapping. CGIP 14 (the distance
transform; ``scipy.ndimage.distance_transform_edt``).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .node import cell_index, opaque_float

__all__ = ["BrickGrid", "BrickLayout", "BRICK", "brick_shape", "DENSE_EDT_CELLS", "MAX_BRICKS", "cell_gaps",
           "half_up", "list_entry", "pack_narrow", "relative_offsets"]

#: Cells along a brick's edge (a power of two: cell -> brick is a shift).
BRICK = 8
BRICK_CELLS = BRICK ** 3
#: The slot of a brick that holds no cell.
NO_SLOT = np.uint32(0xFFFFFFFF)

#: Fine grids up to this many cells get the exact (dense) distance transform.
DENSE_EDT_CELLS = 1 << 22
#: The top grid's size limit (4 bytes a brick).
MAX_BRICKS = 1 << 21


def cell_ranges(lo, hi, grid_lo, cell, res):
    """Inclusive cell index ranges ``(i0, i1)`` of boxes ``[lo, hi]`` (clipped to the grid)."""
    i0 = np.clip(np.floor((lo - grid_lo) / cell).astype(np.int64), 0, res - 1)
    i1 = np.clip(np.floor((hi - grid_lo) / cell).astype(np.int64), 0, res - 1)
    return i0, i1


class BrickLayout:
    """Which bricks of a grid are stored, and where: the top level of a brick grid.

    Parameters
    ----------
    slots : numpy.ndarray
        ``(bricks,)`` uint32, z-major: the brick's slot among the stored ones, or
        ``NO_SLOT``.
    grid_lo : numpy.ndarray
        ``(3,)`` corner of the grid.
    cell : float
        Cell edge.
    res : numpy.ndarray
        ``(3,)`` cells per axis.
    shape : sequence of 3 ints, optional
        Cells along a brick's ``x``, ``y``, ``z`` edges, powers of two up to ``BRICK``
        (default ``BRICK`` on every axis; :meth:`of_cells` chooses :func:`brick_shape`).
    """

    def __init__(self, slots, grid_lo, cell, res, shape=(BRICK, BRICK, BRICK)):
        self.slots_np = np.asarray(slots, dtype=np.uint32)
        self.grid_lo, self.cell = np.asarray(grid_lo, dtype=np.float64), float(cell)
        self.res = np.asarray(res, dtype=np.int64)
        self.shape = tuple(int(v) for v in shape)
        if any(v < 1 or v > BRICK or v & (v - 1) for v in self.shape):
            raise ValueError(f"brick edges must be powers of two up to {BRICK} (got {self.shape})")
        self.brick_cells = self.shape[0] * self.shape[1] * self.shape[2]
        self.bricks = -(-self.res // np.asarray(self.shape, dtype=np.int64))
        self.stored = self.slots_np != NO_SLOT
        self.stored_cells = int(self.stored.sum()) * self.brick_cells
        self._slots = mi.UInt32(self.slots_np)
        self._glo = [opaque_float(v) for v in self.grid_lo]
        self._inv_cell = opaque_float(1.0 / self.cell)

    @classmethod
    def of_cells(cls, nonzero, grid_lo, cell, res, cell_bytes=8, brick_bytes=4,
                 edges=(BRICK, BRICK // 2, BRICK // 4)) -> "BrickLayout":
        """The layout storing every brick that holds a ``True`` cell of ``nonzero``
        (a dense ``(z, y, x)``-ordered flat array of ``prod(res)`` cells), in the bricks
        that take the least memory.

        Bricks of each edge of ``edges`` (no deeper than the grid on a thin axis,
        :func:`brick_shape`) are tried; each costs ``brick_bytes`` a brick of the top
        grid (its slot, and any per-brick datum) and ``cell_bytes`` a stored cell.
        Why: a coast's carving spheres touch a narrow band of cells; at Sea scale (48,143 primitives, a grid of
        416 x 416 x 4) bricks of 8 x 8 x 4 stored 255k cells, bricks of 2^3 153k for a
        top grid of 87k bricks (2.4 -> 1.6 MB). A dense set keeps its bricks of 8^3 (the
        lookup is the same shifts and masks).

        Parameters
        ----------
        nonzero : array_like
            ``(prod(res),)`` bools, ``(z, y, x)`` order: the cells that hold a datum.
        grid_lo, cell, res
            The grid (as :class:`BrickLayout`).
        cell_bytes, brick_bytes : int
            Bytes a stored cell and a brick of the top grid take.
        edges : sequence of int
            The brick edges to try, powers of two up to ``BRICK`` (a grid whose
            unstored bricks answer a bound per brick may want one size only).

        Returns
        -------
        BrickLayout
        """
        nonzero = np.asarray(nonzero, dtype=bool)
        thin = brick_shape(res)
        best = None
        for edge in edges:
            shape = tuple(min(edge, t) for t in thin)
            occupied = cls._bricked(nonzero, res, False, shape).any(axis=(1, 2, 3))
            cost = brick_bytes * len(occupied) + cell_bytes * int(occupied.sum()) * int(np.prod(shape))
            if best is None or cost < best[0]:
                best = cost, shape, occupied
        _, shape, occupied = best
        slots = np.full(len(occupied), NO_SLOT, dtype=np.uint32)
        slots[occupied] = np.arange(int(occupied.sum()), dtype=np.uint32)
        return cls(slots, grid_lo, cell, res, shape)

    @staticmethod
    def _bricked(dense, res, fill, shape=(BRICK, BRICK, BRICK)):
        """A dense ``(z, y, x)`` flat array as ``(brick, z, y, x)`` blocks of ``shape``
        (``x, y, z`` edges; padded with ``fill``)."""
        rx, ry, rz = (int(v) for v in res)
        ex, ey, ez = (int(v) for v in shape)
        bx, by, bz = -(-rx // ex), -(-ry // ey), -(-rz // ez)
        padded = np.full((bz * ez, by * ey, bx * ex), fill, dtype=dense.dtype)
        padded[:rz, :ry, :rx] = dense.reshape(rz, ry, rx)
        blocks = padded.reshape(bz, ez, by, ey, bx, ex).transpose(0, 2, 4, 1, 3, 5)
        return blocks.reshape(-1, ez, ey, ex)

    def compact(self, dense) -> np.ndarray:
        """The stored cells' entries of a dense ``(z, y, x)`` flat per-cell array."""
        dense = np.asarray(dense)
        return np.ascontiguousarray(self._bricked(dense, self.res, 0, self.shape)[self.stored].reshape(-1))

    def compact_lists(self, start, count, index, narrow=False):
        """Per-cell lists (dense CSR ``start``, ``count``, ``index``) kept for the stored cells
        only, in their order: ``(offsets, index)``, cell ``c``'s list ``index[offset[c]:
        offset[c + 1]]`` in its order, read by :meth:`list_range`. One offset a cell
        instead of a start and a count (the next cell's offset is the count's, usually
        in the same cache line).

        With ``narrow`` (every entry below ``2^16``), the entries are packed two to a
        32-bit word (:func:`pack_narrow`; read them with :func:`list_entry`) and, where
        no brick's lists hold ``2^16`` entries or more, so are the offsets
        (:func:`relative_offsets`). ``offsets`` is then ``(words, base)``, else
        ``(offset,)``."""
        count = self.compact(count).astype(np.int64)
        start = self.compact(start).astype(np.int64)
        offset = np.zeros(len(count) + 1, dtype=np.int64)
        np.cumsum(count, out=offset[1:])
        at = np.repeat(start - offset[:-1], count) + np.arange(int(offset[-1]), dtype=np.int64)
        entries = np.asarray(index)[at]
        if not narrow:
            return (offset.astype(np.uint32),), np.ascontiguousarray(entries, np.uint32)
        relative = relative_offsets(offset, self.brick_cells)
        return relative or (offset.astype(np.uint32),), pack_narrow(entries)

    def list_range(self, offsets, cell, active=True):
        """``(start, count)`` (``mi.UInt32``) of the lists of the stored cells ``cell``
        (valid where ``active``) from :meth:`compact_lists`' ``offsets`` (as Dr.Jit arrays).
        Relative offsets cost one more gather (the brick's base) and save 2 bytes a cell."""
        if len(offsets) == 1:
            start = dr.gather(mi.UInt32, offsets[0], cell, active)
            return start, dr.gather(mi.UInt32, offsets[0], cell + 1, active) - start
        words, base = offsets
        slot = cell >> (self.brick_cells.bit_length() - 1)
        at = cell + slot  # brick_cells + 1 offsets a brick
        first = list_entry(words, at, True, active)
        return (dr.gather(mi.UInt32, base, slot, active) + first,
                list_entry(words, at + 1, True, active) - first)

    def blocks(self, dense, fill) -> np.ndarray:
        """A dense ``(z, y, x)`` flat per-cell array as ``(brick, z, y, x)`` blocks, one a
        brick of the top grid, padded past the grid with ``fill``."""
        return self._bricked(np.asarray(dense), self.res, fill, self.shape)

    def brick_min(self, dense) -> np.ndarray:
        """Per brick, the smallest entry of a dense per-cell array over the brick's cells."""
        return self.blocks(dense, np.inf).min(axis=(1, 2, 3))

    def cell_coordinates(self, p):
        """``(fx, fy, fz)``: ``p`` in cell units from the grid's corner (``mi.Float``)."""
        return tuple((p[i] - self._glo[i]) * self._inv_cell for i in range(3))

    def lookup(self, p):
        """``(cell, stored, brick)`` of the points ``p``: the stored cell index (valid where
        ``stored``) and the brick's index in the top grid (points outside the grid
        take the nearest cell)."""
        rx, ry, rz = (int(v) for v in self.res)
        bx, by = int(self.bricks[0]), int(self.bricks[1])
        sx, sy, sz = (v.bit_length() - 1 for v in self.shape)  # edges as shifts
        fx, fy, fz = self.cell_coordinates(p)
        ix, iy, iz = cell_index(fx, rx), cell_index(fy, ry), cell_index(fz, rz)
        brick = ((iz >> sz) * by + (iy >> sy)) * bx + (ix >> sx)
        slot = dr.gather(mi.UInt32, self._slots, brick)
        stored = slot != int(NO_SLOT)
        local = ((iz & ((1 << sz) - 1)) << (sx + sy)) | ((iy & ((1 << sy) - 1)) << sx) | (ix & ((1 << sx) - 1))
        cell = slot * self.brick_cells + local
        return cell, stored, brick

    def nbytes(self) -> int:
        """Bytes of the top grid."""
        return len(self.slots_np) * 4


def half_up(values):
    """``values`` as float16, each rounded *up* to the next float16 (never below it), or
    ``None`` when one is beyond float16's range or not finite. Why: per-cell upper bounds
    (slopes, value maxima) in half the bytes stay upper bounds; they grow by at most a
    part in 1024 (float16's 10-bit mantissa)."""
    v = np.asarray(values, dtype=np.float32)
    if v.size and not (np.all(np.isfinite(v)) and float(np.max(np.abs(v))) <= 65504.0):
        return None
    h = v.astype(np.float16)
    low = h.astype(np.float32) < v
    h[low] = np.nextafter(h[low], np.float16(np.inf))
    return h


def pack_narrow(entries) -> np.ndarray:
    """Entries below ``2^16`` packed two to a ``uint32`` word: entry ``k`` in the low half
    of word ``k // 2`` for even ``k``, the high half for odd ``k`` (a zero pads an odd
    count). Why: a set of fewer than 65,536 primitives needs only 16 bits an entry, and
    its lists were most of its memory (Sea scale: 2.2 M entries, 8.6 of 15.8 MB)."""
    entries = np.asarray(entries, np.int64)
    if entries.size and (entries.min() < 0 or entries.max() >= 1 << 16):
        raise ValueError("narrow list entries must lie in [0, 65536)")
    half = np.zeros(2 * ((len(entries) + 1) // 2), np.uint32)
    half[:len(entries)] = entries
    return np.ascontiguousarray(half[0::2] | (half[1::2] << np.uint32(16)))


def relative_offsets(offset, brick_cells):
    """List offsets in 16 bits: ``(words, base)``, or ``None`` when some brick's lists
    hold ``2^16`` entries or more.

    Per stored brick ``s``, ``base[s]`` (uint32) is the offset of its first cell and
    ``brick_cells + 1`` offsets relative to it follow, packed two to a word
    (:func:`pack_narrow`): its cells' starts and, last, its end, so that a cell's
    count is the difference of two neighbours within its brick. Why: a set of 16-bit
    entries still spent 4 bytes a cell on offsets (Sea scale: 0.77 of 4.55 MB).

    Parameters
    ----------
    offset : ndarray
        ``(stored cells + 1,)`` absolute offsets (:meth:`BrickLayout.compact_lists`).
    brick_cells : int
        Cells a brick.

    Returns
    -------
    (ndarray, ndarray) or None
        The packed relative offsets (uint32 words) and the bricks' bases (uint32).
    """
    offset = np.asarray(offset, np.int64)
    bricks = (len(offset) - 1) // brick_cells
    starts = offset[:-1].reshape(bricks, brick_cells)
    base = starts[:, 0]
    ends = offset[brick_cells::brick_cells]
    relative = np.concatenate([starts, ends[:, None]], axis=1) - base[:, None]
    if relative.size and relative.max() >= 1 << 16:
        return None
    return pack_narrow(relative.reshape(-1)), np.ascontiguousarray(base, np.uint32)


def list_entry(words, k, narrow: bool, active=True):
    """Entry ``k`` (``mi.UInt32``) of a list array from :meth:`BrickLayout.compact_lists`:
    a gather, and with ``narrow`` (a Python bool: one kernel or the other) the half of
    the word that holds it."""
    if not narrow:
        return dr.gather(mi.UInt32, words, k, active)
    word = dr.gather(mi.UInt32, words, k >> 1, active)
    return (word >> ((k & 1) << 4)) & 0xFFFF


def brick_shape(res):
    """Cells along a brick's ``x``, ``y``, ``z`` edges for a grid of ``res`` cells:
    ``BRICK``, or the smallest power of two holding the grid where it is thinner.

    Why: a coast's set of carving spheres is a grid four cells deep; bricks of 8^3
    stored it padded to eight, half of every per-cell array (Sea scale, 48,143
    primitives: 510,464 cells stored for 255,232, 12.3 of the set's 24 MB).
    """
    return tuple(min(BRICK, 1 << max(int(v) - 1, 0).bit_length()) for v in res)


def cell_gaps(occupied):
    """Per cell of a boolean grid, the gap (in cells, box to box) to the nearest occupied
    cell, as a float array of the grid's shape (1e10 everywhere when none is: finite,
    so that a product with 0 stays 0).

    Cells whose indices differ by ``d`` are ``sqrt(sum max(|d_i| - 1, 0)^2)`` cells apart:
    the distance from the cell to the occupied cells grown by one (3x3x3), which one
    Euclidean distance transform gives exactly. (The centre-to-centre distance less
    ``sqrt 3``, used before, is up to 1.7 cells less.) A part in 1e5 is shaved off, so
    that float32 rounding of the product with the cell edge cannot overstate a gap.
    """
    # scipy on use: keeps `import arches_render.field` light
    from scipy.ndimage import binary_dilation, distance_transform_edt
    if not occupied.any():
        return np.full(occupied.shape, 1e10)
    grown = binary_dilation(occupied, structure=np.ones((3,) * occupied.ndim, dtype=bool))
    if grown.all():
        return np.zeros(occupied.shape)
    return distance_transform_edt(~grown) * (1.0 - 1e-5)


class BrickGrid:
    """Cells of edge ``cell`` from ``grid_lo``, ``res`` per axis, stored in bricks of 8^3.

    Parameters
    ----------
    list_i0, list_i1 : numpy.ndarray
        ``(N, 3)`` inclusive cell ranges (:func:`cell_ranges`) that put a primitive on a
        cell's list (its box grown by a margin, say).
    occupied_lo, occupied_hi : numpy.ndarray
        ``(N, 3)`` boxes holding the primitives (the empty-space bound's targets),
        inside the list boxes.
    grid_lo : numpy.ndarray
        ``(3,)`` corner of the grid.
    cell : float
        Cell edge.
    res : numpy.ndarray
        ``(3,)`` cells per axis.
    bricks_occupied : numpy.ndarray, optional
        The result of :meth:`stored_bricks` for these ranges, if already computed.
    """

    def __init__(self, list_i0, list_i1, occupied_lo, occupied_hi, grid_lo, cell, res, bricks_occupied=None):
        from . import brick_grid_kernels as K  # on use: numba is slow to import

        self.grid_lo, self.cell = np.asarray(grid_lo, dtype=np.float64), float(cell)
        self.res = np.asarray(res, dtype=np.int64)
        self.bricks = -(-self.res // BRICK)
        i0, i1 = list_i0, list_i1
        occupied = K.mark_bricks(i0, i1, self.bricks) if bricks_occupied is None else bricks_occupied
        slots = np.full(len(occupied), NO_SLOT, dtype=np.uint32)
        slots[occupied] = np.arange(int(occupied.sum()), dtype=np.uint32)
        n_cells = int(occupied.sum()) * BRICK_CELLS
        count = K.count_cells(i0, i1, slots, self.bricks, n_cells)
        # CSR offsets, one more than cells: a list is [offset[c], offset[c + 1]).
        offset = np.zeros(n_cells + 1, dtype=np.uint32)
        np.cumsum(count, out=offset[1:])
        index = K.fill_cells(i0, i1, slots, self.bricks, offset, int(offset[-1]))
        o0, o1 = cell_ranges(occupied_lo, occupied_hi, self.grid_lo, self.cell, self.res)
        touched = K.count_cells(o0, o1, slots, self.bricks, n_cells) > 0
        empty, brick_empty = self._empty_bounds(touched, occupied, slots)
        self.slots_np, self.offset_np, self.index_np = slots, offset, index
        self.stored_cells, self.list_len = n_cells, len(index)
        self.max_per_cell = int(count.max()) if n_cells else 0
        self.layout = BrickLayout(slots, self.grid_lo, self.cell, self.res)
        self._offset = mi.UInt32(offset)
        self.index = mi.UInt32(index)  # read by the owner's loop over a list
        self._empty, self._brick_empty = mi.Float(empty), mi.Float(brick_empty)

    @staticmethod
    def stored_bricks(list_i0, list_i1, res) -> np.ndarray:
        """Which bricks a grid of these list ranges would store (bool per brick, z-major)."""
        from . import brick_grid_kernels as K  # on use: numba is slow to import
        return K.mark_bricks(list_i0, list_i1, -(-np.asarray(res, dtype=np.int64) // BRICK))

    def _empty_bounds(self, touched, stored, slots):
        """Per stored cell and per brick, a lower bound of the distance to the touched cells."""
        bx, by, bz = (int(v) for v in self.bricks)
        per_brick = touched.reshape(-1, BRICK, BRICK, BRICK)  # (slot, z, y, x)
        if int(np.prod(self.res)) <= DENSE_EDT_CELLS:
            dense = np.zeros((bz, by, bx, BRICK, BRICK, BRICK), dtype=bool)
            dense.reshape(-1, BRICK, BRICK, BRICK)[stored] = per_brick
            dense = dense.transpose(0, 3, 1, 4, 2, 5).reshape(bz * BRICK, by * BRICK, bx * BRICK)
            bound = cell_gaps(dense) * self.cell
            bricked = bound.reshape(bz, BRICK, by, BRICK, bx, BRICK).transpose(0, 2, 4, 1, 3, 5)
            bricked = bricked.reshape(-1, BRICK, BRICK, BRICK)
            return (bricked[stored].reshape(-1).astype(np.float32),
                    bricked.min(axis=(1, 2, 3)).astype(np.float32))
        # Large grids: each stored brick on its own, with the chessboard distance
        # (|d|_inf <= |d|_2, so the bound stays a lower one; separable, compiled) capped
        # by the distance to the brick's faces, beyond which the brick-scale bound
        # takes over. The exact transform took 2.9 s on the 6 M stored cells of a
        # million capsules.
        from .brick_grid_kernels import chessboard_in_bricks
        local = np.arange(BRICK)
        to_face = np.minimum(local + 1, BRICK - local)
        face = np.minimum(np.minimum(to_face[:, None, None], to_face[None, :, None]), to_face[None, None, :])
        k = np.minimum(chessboard_in_bricks(per_brick), face).astype(np.float64)
        # Cells k apart in the chessboard metric have a gap of at least k - 1 cells.
        cell_bound = np.maximum(k - 1.0, 0.0) * self.cell
        brick_touched = np.zeros(len(slots), dtype=bool)
        brick_touched[stored] = per_brick.any(axis=(1, 2, 3))
        brick_bound = cell_gaps(brick_touched.reshape(bz, by, bx)).reshape(-1) * (BRICK * self.cell)
        # A stored brick that no primitive itself touches (only grown boxes) keeps its
        # brick-scale bound where that is the larger.
        cell_bound = np.maximum(cell_bound, brick_bound[stored][:, None, None, None])
        return cell_bound.reshape(-1).astype(np.float32), brick_bound.astype(np.float32)

    @staticmethod
    def cell_order(points, grid_lo, cell, res) -> np.ndarray:
        """A sort key of points: the brick of their cell, then the cell in the brick."""
        res = np.asarray(res, dtype=np.int64)
        i = np.clip(np.floor((points - grid_lo) / cell).astype(np.int64), 0, res - 1)
        bricks = -(-res // BRICK)
        brick = ((i[:, 2] // BRICK) * bricks[1] + i[:, 1] // BRICK) * bricks[0] + i[:, 0] // BRICK
        return brick * BRICK_CELLS + ((i[:, 2] % BRICK) * BRICK + i[:, 1] % BRICK) * BRICK + i[:, 0] % BRICK

    def cell_centres(self) -> np.ndarray:
        """``(stored_cells, 3)`` centres of the stored cells, in storage order."""
        stored = np.flatnonzero(self.slots_np != NO_SLOT)
        bx, by = int(self.bricks[0]), int(self.bricks[1])
        b = np.repeat(stored, BRICK_CELLS)
        local = np.tile(np.arange(BRICK_CELLS), len(stored))
        ix = (b % bx) * BRICK + (local & 7)
        iy = ((b // bx) % by) * BRICK + ((local >> 3) & 7)
        iz = (b // (bx * by)) * BRICK + (local >> 6)
        return self.grid_lo + (np.stack([ix, iy, iz], -1) + 0.5) * self.cell

    def order_lists(self, key) -> None:
        """Sort every cell's list by ``key(centres, entries)`` (ascending; e.g. the
        distance from the cell's centre to each listed primitive: nearest first, for
        loops that stop early)."""
        count = np.diff(self.offset_np.astype(np.int64))
        cell = np.repeat(np.arange(len(count)), count)
        centres = self.cell_centres()[cell]
        order = np.lexsort((key(centres, self.index_np), cell))
        self.index_np = self.index_np[order]
        self.index = mi.UInt32(self.index_np)

    def cell_list(self, p):
        """``(start, count)`` of the list of the cell holding ``p`` (count 0 in unstored bricks)."""
        cell, stored, _ = self.layout.lookup(p)
        # Both offsets usually share a cache line: no separate count array to miss in.
        start = dr.gather(mi.UInt32, self._offset, cell, stored)
        return start, dr.gather(mi.UInt32, self._offset, cell + 1, stored) - start

    def empty_distance(self, p):
        """A lower bound of the distance from ``p`` to the occupied boxes (0 near them)."""
        cell, stored, brick = self.layout.lookup(p)
        return dr.select(stored, dr.gather(mi.Float, self._empty, cell, stored),
                         dr.gather(mi.Float, self._brick_empty, brick, ~stored))

    def nbytes(self) -> int:
        """Bytes of the grid's arrays (top slots and bounds, per cell offset and bound, lists)."""
        return len(self.slots_np) * 8 + self.stored_cells * 8 + self.list_len * 4
