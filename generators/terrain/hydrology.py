"""Hydrology of a heightfield: depression filling, multiple-flow-direction drainage
area, slope and stream power (Paris et al. 2019, section 6.1, "River canyons").

Depression filling (Barnes et al. 2014, Priority-Flood + epsilon)
    Cells are visited from the boundary inwards in order of increasing elevation
    (a priority queue seeded with the border). A neighbour lower than the cell
    that reaches it lies in a depression: it is raised to that cell's height plus
    ``epsilon`` and queued in a plain FIFO (pits are visited in flooding order, so
    no sort is needed for them). With ``epsilon = 0`` the result is the classical
    filled DEM (the least surface above the DEM with no pit); with
    ``epsilon > 0`` every interior cell gets a *strictly* lower neighbour, so flow
    crosses flats towards their spill point.

Drainage area (Freeman 1991, multiple flow direction)
    Every cell receives its own area ``dx dy`` and passes what it holds to its
    lower 8-neighbours in proportion to ``tan(beta_i)^p`` (``beta_i`` the slope
    towards neighbour ``i`` over the centre distance, ``p = 1.1`` as Freeman
    recommends), so flow may diverge on convex slopes. Cells are processed from
    the highest down, so each cell has received all its inflow before passing
    it on. A cell with no lower neighbour (after filling, only on the border)
    is an outlet. The result ``A`` is the upstream area in square metres.

Stream power
    ``sigma = A^(1/2) s`` with ``s`` the local slope (gradient norm of the DEM),
    the stress of river erosion in the paper (after Cordonnier et al. 2016).

References
----------
Barnes, R., Lehman, C., Mulla, D. (2014). Priority-flood: An optimal
depression-filling and watershed-labeling algorithm for digital elevation
models. Computers & Geosciences 62, 117-127.
Freeman, T. G. (1991). Calculating catchment area with divergent flow based on
a regular grid. Computers & Geosciences 17(3), 413-422.
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), section 6.1.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["fill_depressions", "flow_accumulation", "slope", "stream_power", "pits", "label_extrema"]

#: Row and column offsets of the eight neighbours (shared with landscape_evolution).
NEIGHBOUR_DI = np.array([-1, -1, -1, 0, 0, 1, 1, 1], dtype=np.int64)
NEIGHBOUR_DJ = np.array([-1, 0, 1, -1, 1, -1, 0, 1], dtype=np.int64)


@numba.njit(cache=True)
def heap_push(keys, vals, n, key, val):
    """Push ``(key, val)`` on the binary min-heap held in ``keys[:n]``, ``vals[:n]``; returns ``n + 1``.

    Ties are ordered by ``val`` (a cell index), so fills are deterministic. Written
    out for numba: ``heapq`` there needs typed lists of tuples, and the arrays are
    reused across the whole fill.
    """
    i = n
    keys[i] = key
    vals[i] = val
    while i > 0:
        parent = (i - 1) >> 1
        # Ties broken by insertion index: the fill is then deterministic.
        if keys[parent] > keys[i] or (keys[parent] == keys[i] and vals[parent] > vals[i]):
            keys[parent], keys[i] = keys[i], keys[parent]
            vals[parent], vals[i] = vals[i], vals[parent]
            i = parent
        else:
            break
    return n + 1


@numba.njit(cache=True)
def heap_pop(keys, vals, n):
    """Pop the smallest ``(key, val)`` of the heap of :func:`heap_push`; returns ``(key, val, n - 1)``."""
    key, val = keys[0], vals[0]
    n -= 1
    keys[0], vals[0] = keys[n], vals[n]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= n:
            break
        c = left
        right = left + 1
        if right < n and (keys[right] < keys[left] or (keys[right] == keys[left] and vals[right] < vals[left])):
            c = right
        if keys[c] < keys[i] or (keys[c] == keys[i] and vals[c] < vals[i]):
            keys[c], keys[i] = keys[i], keys[c]
            vals[c], vals[i] = vals[i], vals[c]
            i = c
        else:
            break
    return key, val, n


@numba.njit(cache=True)
def _priority_flood(H, epsilon, di, dj):
    ny, nx = H.shape
    Z = H.copy()
    done = np.zeros((ny, nx), dtype=np.bool_)
    keys = np.empty(ny * nx, dtype=np.float64)
    vals = np.empty(ny * nx, dtype=np.int64)
    pit = np.empty(ny * nx, dtype=np.int64)
    n = 0
    for j in range(ny):
        for i in range(nx):
            if j == 0 or i == 0 or j == ny - 1 or i == nx - 1:
                n = heap_push(keys, vals, n, Z[j, i], j * nx + i)
                done[j, i] = True
    head = 0
    tail = 0
    while n > 0 or head < tail:
        if head < tail:
            c = pit[head]
            head += 1
        else:
            _, c, n = heap_pop(keys, vals, n)
        cj, ci = c // nx, c % nx
        zc = Z[cj, ci]
        for k in range(8):
            j, i = cj + di[k], ci + dj[k]
            if j < 0 or i < 0 or j >= ny or i >= nx or done[j, i]:
                continue
            done[j, i] = True
            floor = zc + epsilon if epsilon > 0 else zc
            if epsilon > 0 and floor <= zc:  # epsilon below the float spacing at zc
                floor = np.nextafter(zc, np.inf)
            if Z[j, i] <= floor:
                Z[j, i] = floor
                pit[tail] = j * nx + i
                tail += 1
            else:
                n = heap_push(keys, vals, n, Z[j, i], j * nx + i)
        if head == tail:
            head = 0
            tail = 0
    return Z


def fill_depressions(heights, epsilon=0.0):
    """Fill the depressions of a DEM (Barnes et al. 2014, Priority-Flood + epsilon).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` finite elevations in metres.
    epsilon : float
        Rise imposed from cell to cell across a filled depression or flat, in
        metres. ``0`` gives the classical filled DEM (flats stay flat);
        ``> 0`` (or a value below float spacing, which falls back to the next
        representable float) makes every interior cell drain to a strictly lower
        neighbour.

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` float64 filled elevations, ``>= heights`` everywhere and equal
        on the border.

    References
    ----------
    Barnes, R., Lehman, C., Mulla, D. (2014). Priority-flood. Computers &
    Geosciences 62, 117-127.
    """
    H = np.ascontiguousarray(heights, dtype=np.float64)
    if H.ndim != 2 or min(H.shape) < 2:
        raise ValueError("fill_depressions needs a 2-D array of at least 2x2 heights")
    if not np.all(np.isfinite(H)):
        raise ValueError("fill_depressions needs finite heights")
    return _priority_flood(H, float(epsilon), NEIGHBOUR_DI, NEIGHBOUR_DJ)


@numba.njit(cache=True)
def _mfd(Z, order, dx, dy, p, di, dj):
    ny, nx = Z.shape
    A = np.full((ny, nx), dx * dy)
    dist = np.empty(8)
    for k in range(8):
        dist[k] = np.sqrt((dj[k] * dx) ** 2 + (di[k] * dy) ** 2)
    w = np.empty(8)
    for c in order:
        cj, ci = c // nx, c % nx
        z = Z[cj, ci]
        total = 0.0
        for k in range(8):
            j, i = cj + di[k], ci + dj[k]
            w[k] = 0.0
            if j < 0 or i < 0 or j >= ny or i >= nx:
                continue
            drop = z - Z[j, i]
            if drop > 0:
                w[k] = (drop / dist[k]) ** p
                total += w[k]
        if total > 0:
            a = A[cj, ci] / total
            for k in range(8):
                if w[k] > 0:
                    A[cj + di[k], ci + dj[k]] += a * w[k]
    return A


def flow_accumulation(heights, cell_size=1.0, exponent=1.1, fill=True):
    """Upstream (drainage) area by Freeman's multiple flow direction.

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations in metres.
    cell_size : float or (float, float)
        ``dx`` or ``(dx, dy)`` in metres.
    exponent : float
        Freeman's ``p`` (1.1 in the paper's reference).
    fill : bool
        Fill depressions first (Priority-Flood + epsilon), as the paper does, so
        that no flow is trapped in a pit.

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` upstream area ``A`` in square metres (own cell included).

    References
    ----------
    Freeman, T. G. (1991). Computers & Geosciences 17(3), 413-422.
    """
    dx, dy = (float(cell_size), float(cell_size)) if np.isscalar(cell_size) else map(float, cell_size)
    H = np.ascontiguousarray(heights, dtype=np.float64)
    # An epsilon of a millionth of the cell keeps flats drainable yet far below any relief.
    Z = fill_depressions(H, epsilon=1e-6 * min(dx, dy)) if fill else H
    order = np.argsort(-Z, axis=None, kind="stable").astype(np.int64)
    return _mfd(Z, order, dx, dy, float(exponent), NEIGHBOUR_DI, NEIGHBOUR_DJ)


def slope(heights, cell_size=1.0):
    """Local slope ``s = |grad h|`` (rise over run) by central differences.

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations in metres.
    cell_size : float or (float, float)
        ``dx`` or ``(dx, dy)`` in metres.

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` slopes (dimensionless).
    """
    dx, dy = (float(cell_size), float(cell_size)) if np.isscalar(cell_size) else map(float, cell_size)
    gy, gx = np.gradient(np.asarray(heights, dtype=np.float64), dy, dx)
    return np.hypot(gx, gy)


def stream_power(heights, cell_size=1.0, exponent=1.1):
    """Stream power ``sigma = A^(1/2) s`` (Paris et al. 2019, section 6.1).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations in metres.
    cell_size : float or (float, float)
        Cell size in metres.
    exponent : float
        Freeman's flow exponent ``p``.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray, numpy.ndarray)
        ``sigma``, the drainage area ``A`` (m^2) and the slope ``s``.
    """
    A = flow_accumulation(heights, cell_size, exponent)
    s = slope(heights, cell_size)
    return np.sqrt(A) * s, A, s


def pits(heights):
    """Sinks of a DEM: interior cells whose 8 neighbours are all strictly higher.

    The seeds of karst percolation (Paris et al. 2019, section 6.2, after Barnes
    et al. 2014).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations.

    Returns
    -------
    numpy.ndarray
        ``(k, 2)`` int64 ``(row, column)`` indices, lowest first.
    """
    H = np.asarray(heights, dtype=np.float64)
    c = H[1:-1, 1:-1]
    lower = np.ones_like(c, dtype=bool)
    ny, nx = H.shape
    for a, b in zip(NEIGHBOUR_DI, NEIGHBOUR_DJ):
        lower &= H[1 + a:ny - 1 + a, 1 + b:nx - 1 + b] > c
    rc = np.argwhere(lower) + 1
    return rc[np.argsort(H[rc[:, 0], rc[:, 1]], kind="stable")].astype(np.int64)


def label_extrema(values, labels, n):
    """The smallest and largest of ``values`` over the cells of each label ``1..n``.

    What ``scipy.ndimage.minimum`` and ``maximum`` (with ``index = 1..n``) return, the same
    numbers, read with ``numpy.minimum.at`` / ``maximum.at`` over the labelled cells
    only. Why not scipy's: it sorts every cell by label first; on the Sea-scale coast
    (1025^2 cells, a twentieth labelled) a call took 0.2-0.4 s, this one 0.01 s.

    Parameters
    ----------
    values : array_like
        Values per cell.
    labels : numpy.ndarray
        Integer labels of the same shape (0: no label), as ``scipy.ndimage.label`` gives.
    n : int
        The largest label.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        ``(n,)`` minima and maxima in ``values``' float dtype (float64 for integers;
        ``+inf`` and ``-inf`` for a label with no cell).
    """
    lab = np.asarray(labels).ravel()
    at = np.flatnonzero(lab)
    v = np.asarray(values)
    v = v.astype(v.dtype if v.dtype.kind == "f" else np.float64).ravel()[at]  # scipy keeps a float dtype
    lab = lab[at]
    lo, hi = np.full(n + 1, np.inf, dtype=v.dtype), np.full(n + 1, -np.inf, dtype=v.dtype)
    np.minimum.at(lo, lab, v)
    np.maximum.at(hi, lab, v)
    return lo[1:], hi[1:]
