"""Compiled loops of :mod:`.brick_grid`: marking bricks and filling cell lists.

Why hand-written loops (numba) rather than numpy: a million primitives overlap
some 20 million (primitive, cell) pairs; enumerating them as numpy arrays and
sorting them by cell (the dense grid's :func:`.primitive_set.grid_lists`) takes
seconds and gigabytes of temporaries, while two passes over the primitives, one
counting and one filling (a counting sort), take a fraction of a second and no
memory beyond the lists themselves. Imported on use: numba adds 0.2 s to an import.
"""

from __future__ import annotations

import numba
import numpy as np

from .brick_grid import BRICK, BRICK_CELLS, NO_SLOT


@numba.njit(cache=True, nogil=True)
def mark_bricks(i0, i1, bricks):
    """Occupancy of the bricks touched by the cell ranges ``[i0, i1]`` (inclusive)."""
    occupied = np.zeros(bricks[0] * bricks[1] * bricks[2], dtype=np.bool_)
    for k in range(i0.shape[0]):
        for bz in range(i0[k, 2] // BRICK, i1[k, 2] // BRICK + 1):
            for by in range(i0[k, 1] // BRICK, i1[k, 1] // BRICK + 1):
                for bx in range(i0[k, 0] // BRICK, i1[k, 0] // BRICK + 1):
                    occupied[(bz * bricks[1] + by) * bricks[0] + bx] = True
    return occupied


@numba.njit(cache=True, nogil=True, inline="always")
def _cell_id(x, y, z, slots, bricks):
    brick = ((z // BRICK) * bricks[1] + y // BRICK) * bricks[0] + x // BRICK
    local = ((z % BRICK) * BRICK + y % BRICK) * BRICK + x % BRICK
    return np.int64(slots[brick]) * BRICK_CELLS + local


@numba.njit(cache=True, nogil=True)
def count_cells(i0, i1, slots, bricks, n_cells):
    """Primitives listed in each stored cell (ranges must lie in stored bricks)."""
    count = np.zeros(n_cells, dtype=np.uint32)
    for k in range(i0.shape[0]):
        for z in range(i0[k, 2], i1[k, 2] + 1):
            for y in range(i0[k, 1], i1[k, 1] + 1):
                for x in range(i0[k, 0], i1[k, 0] + 1):
                    count[_cell_id(x, y, z, slots, bricks)] += 1
    return count


@numba.njit(cache=True, nogil=True)
def fill_cells(i0, i1, slots, bricks, offset, total):
    """CSR lists: each cell's primitives in increasing order (a counting sort)."""
    index = np.empty(total, dtype=np.uint32)
    cursor = offset[:-1].astype(np.int64)
    for k in range(i0.shape[0]):
        for z in range(i0[k, 2], i1[k, 2] + 1):
            for y in range(i0[k, 1], i1[k, 1] + 1):
                for x in range(i0[k, 0], i1[k, 0] + 1):
                    c = _cell_id(x, y, z, slots, bricks)
                    index[cursor[c]] = k
                    cursor[c] += 1
    return index


@numba.njit(cache=True, nogil=True, parallel=True)
def chessboard_in_bricks(touched):
    """Per brick ``(slot, z, y, x)``, the chessboard distance (in cells) from each cell to
    the nearest touched cell of the same brick (``BRICK`` where there is none).

    Separable: ``min_y max_i |x_i - y_i|`` is a min-max along one axis after another,
    ``O(BRICK)`` per cell and axis.
    """
    n = touched.shape[0]
    out = np.empty(touched.shape, dtype=np.uint8)
    for s in numba.prange(n):
        d = np.where(touched[s], 0, BRICK).astype(np.int64)
        for axis in range(3):
            e = np.empty_like(d)
            for u in range(BRICK):
                for v in range(BRICK):
                    for i in range(BRICK):
                        best = BRICK
                        for j in range(BRICK):
                            if axis == 0:
                                val = d[j, u, v]
                            elif axis == 1:
                                val = d[u, j, v]
                            else:
                                val = d[u, v, j]
                            best = min(best, max(abs(i - j), val))
                        if axis == 0:
                            e[i, u, v] = best
                        elif axis == 1:
                            e[u, i, v] = best
                        else:
                            e[u, v, i] = best
            d = e
        out[s] = d.astype(np.uint8)
    return out
