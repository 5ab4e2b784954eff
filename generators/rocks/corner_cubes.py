"""Corner cubes over two colours and their grids of regions (Peytavie et al. 2009, sections 2-3).

A corner cube is a unit cube whose 8 corners carry a colour in ``{0, 1}``; the
complete set has ``2^8 = 256`` cubes. Colouring every integer lattice point at
random and placing at each lattice cube the corner cube of its corners gives a
stochastic, aperiodic tiling in which adjoining corners always match (section 6).

Every corner cube is divided into ``n^3`` cells. Cells are counted in global
cell coordinates: lattice point ``L`` is the cell corner ``n L``. Per axis a
cell is *near* a lattice plane when its index modulo ``n`` is in
``{n-2, n-1, 0, 1}`` (the two cells touching the plane and the ones next to
them) and *interior* otherwise. The set of near axes (a 3-bit ``mask``) names
the kind of the cell's *owner region*:

=====  ======================  ============  =====================================
mask   region                  colours       cells of the region (rel. to base)
=====  ======================  ============  =====================================
7      vertex (2 of them)      1             2 x 2 x 2 around a lattice point
3,5,6  edge  (12)              2             2 x 2 x (n-2) around a lattice edge
1,2,4  face  (48)              4             2 x (n-2) x (n-2) around a face
0      centre (256)            8             (n-2)^3 inside a cube
=====  ======================  ============  =====================================

The paper builds the seeds region by region: vertex regions and their
1-neighbourhood first, then edges (copying what the vertices made), faces,
centres. The cells a region fills are exactly the cells within one cell of it
that no lower-dimensional region reached; that is the *owner* of a cell
computed here in closed form (:func:`cell_owners`), so copying becomes a lookup:
a cell's seeds are a function of the owner's kind, the owner's corner colours
and the cell's place relative to the owner. For ``n >= 4`` every cell has
exactly one owner, and every cell within one cell of a region is owned by that
region or by one of its faces/edges/vertices (whose colours are a subset of
the region's), which is what makes rocks straddle cube faces consistently.

References
----------
Peytavie A., Galin E., Grosjean J., Merillou S. (2009). Procedural generation
of rock piles using aperiodic tiling. Computer Graphics Forum 28(7).
Lagae A., Dutre P. (2006). Poisson sphere distributions. VMV 2006.
"""

from __future__ import annotations

import itertools

import numpy as np

from .seed_points import hash_keys

__all__ = ["MIN_N", "REGION_MASKS", "regions", "region_index", "cube_colours", "lattice_colours",
           "cell_owners", "owner_colour_codes", "region_cells", "region_known_cells",
           "region_vertex_offsets", "cell_keys", "period_of_colouring"]

#: Smallest grid size for which every cell has exactly one owner region.
MIN_N = 4
#: Region kinds by their mask of near axes, vertex first (the paper's order).
REGION_MASKS = (7, 3, 5, 6, 1, 2, 4, 0)


def _free_axes(mask: int) -> list[int]:
    return [a for a in range(3) if not (mask >> a) & 1]


def region_vertex_offsets(mask: int) -> np.ndarray:
    """Lattice offsets of a region's corner points from its base point, in colour-code bit order.

    Bit ``j`` of a colour code is the colour of the vertex whose offsets along
    the free (interior) axes, in increasing axis order, are the bits of ``j``.
    """
    free = _free_axes(mask)
    out = np.zeros((1 << len(free), 3), dtype=np.int64)
    for j in range(1 << len(free)):
        for b, a in enumerate(free):
            out[j, a] = (j >> b) & 1
    return out


def regions() -> list[tuple[int, int]]:
    """All ``(mask, colour code)`` regions: 2 vertex, 12 edge, 48 face and 256 centre regions."""
    return [(m, c) for m in REGION_MASKS for c in range(1 << (1 << len(_free_axes(m))))]


_REGION_INDEX = {r: i for i, r in enumerate(regions())}


def region_index(mask, code) -> np.ndarray:
    """Index of ``(mask, code)`` in :func:`regions` (vectorised)."""
    table = np.full((8, 256), -1, dtype=np.int64)
    for (m, c), i in _REGION_INDEX.items():
        table[m, c] = i
    return table[np.asarray(mask), np.asarray(code)]


def lattice_colours(points, seed: int) -> np.ndarray:
    """Random colour in ``{0, 1}`` of integer lattice points: the stochastic tiling of section 6.

    Parameters
    ----------
    points : (N, 3) array_like of int
    seed : int

    Returns
    -------
    (N,) int64 array of 0/1
    """
    p = np.asarray(points, dtype=np.int64).reshape(-1, 3)
    return (hash_keys(seed, 0xC01, p[:, 0], p[:, 1], p[:, 2]) >> np.uint64(63)).astype(np.int64)


def cube_colours(config: int) -> np.ndarray:
    """The 8 corner colours of corner cube ``config`` (bit ``x + 2y + 4z`` is corner ``(x, y, z)``)."""
    if not 0 <= config < 256:
        raise ValueError(f"corner cube configuration must be in [0, 255] (got {config})")
    return np.array([(config >> i) & 1 for i in range(8)], dtype=np.int64)


def cell_owners(cells, n: int):
    """Owner region of global cells (see module docstring).

    Parameters
    ----------
    cells : (N, 3) array_like of int
        Global cell coordinates.
    n : int
        Cells per corner cube edge, ``>= MIN_N``.

    Returns
    -------
    mask : (N,) int64
        Near-axis mask: the owner's kind.
    base : (N, 3) int64
        Lattice point of the owner: the nearest plane on near axes, the lower
        plane of the interval on interior axes.
    rel : (N, 3) int64
        The cell relative to ``n * base``: in ``[-2, 1]`` on near axes and
        ``[2, n - 3]`` on interior axes.
    """
    if n < MIN_N:
        raise ValueError(f"n must be >= {MIN_N} so that regions do not overlap (got {n})")
    c = np.asarray(cells, dtype=np.int64).reshape(-1, 3)
    r = np.mod(c, n)
    near = (r <= 1) | (r >= n - 2)
    base = np.floor_divide(c, n) + (near & (r >= n - 2))
    rel = c - n * base
    mask = near[:, 0] * 1 + near[:, 1] * 2 + near[:, 2] * 4
    return mask.astype(np.int64), base, rel


def owner_colour_codes(mask, base, colour_of) -> np.ndarray:
    """Colour codes of owner regions from a lattice colouring ``colour_of(points) -> 0/1``."""
    mask = np.asarray(mask)
    code = np.zeros(len(mask), dtype=np.int64)
    for m in np.unique(mask):
        sel = np.nonzero(mask == m)[0]
        for j, off in enumerate(region_vertex_offsets(int(m))):
            code[sel] |= colour_of(base[sel] + off) << j
    return code


def cell_keys(mask, code, rel, seed: int) -> np.ndarray:
    """Context-free keys of cells: owner kind, owner colours, place in the owner, scene seed."""
    rel = np.asarray(rel)
    return hash_keys(seed, 0x5EED, mask, code, rel[:, 0], rel[:, 1], rel[:, 2])


def _axis_ranges(mask: int, n: int, margin: int):
    rng = []
    for a in range(3):
        if (mask >> a) & 1:
            rng.append(range(-1 - margin, 1 + margin))
        else:
            rng.append(range(1 - margin, n - 1 + margin))
    return rng


def region_cells(mask: int, n: int) -> np.ndarray:
    """Cells of a region relative to ``n * base``: 2 cells across near axes, ``n - 2`` along others."""
    return np.array(list(itertools.product(*_axis_ranges(mask, n, 0))), dtype=np.int64).reshape(-1, 3)


def region_known_cells(mask: int, n: int) -> np.ndarray:
    """The region's cells and their 1-neighbourhood: the cells whose seeds its rocks depend on."""
    return np.array(list(itertools.product(*_axis_ranges(mask, n, 1))), dtype=np.int64).reshape(-1, 3)


def region_colour_lookup(mask: int, code: int):
    """``colour_of(points)`` for a region placed with its base at the origin.

    Only the region's own corner points have a colour; asking for any other
    point is a bug of the caller (a cell outside the region's neighbourhood).
    """
    offsets = region_vertex_offsets(mask)
    table = {tuple(o): (code >> j) & 1 for j, o in enumerate(offsets)}

    def colour_of(points):
        try:
            return np.array([table[tuple(p)] for p in np.asarray(points).reshape(-1, 3)], dtype=np.int64)
        except KeyError as exc:
            raise AssertionError(f"lattice point {exc.args[0]} is not a corner of region "
                                 f"(mask {mask}, code {code})") from None
    return colour_of


def period_of_colouring(colours: np.ndarray, max_period: int) -> int | None:
    """Smallest translation period ``t <= max_period`` of a lattice colouring along axis 0, or None.

    Used to check aperiodicity: a periodic tiling repeats its colour pattern
    under some translation ``t``; ``colours`` is a 3-D 0/1 array.
    """
    for t in range(1, min(max_period, colours.shape[0] - 1) + 1):
        if np.array_equal(colours[t:], colours[:-t]):
            return t
    return None
