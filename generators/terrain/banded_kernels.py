"""numba kernels of the banded sampler (:mod:`.banded`), on *windows*.

A window is the sub-volume ``(sx, sy, sz)`` of one column tile (see
:mod:`.tiled_mc`) over a run of levels ``[k0, k0 + sz)`` in which some column of
the tile has band voxels; windows are stored one after the other in flat buffers
(``off[w]`` is the first entry of window ``w``, layout ``(i, j, k)`` C order). Every
kernel loops over windows only, so its cost is that of the windows, not of the grid.

The band is given as *column intervals* ``K0[m], K1[m]`` (``(nx, ny)`` int arrays,
empty where ``K0 > K1``) and inclusive index *boxes* ``(i0, j0, k0, i1, j1, k1)``.
"""

from __future__ import annotations

import numba
import numpy as np

#: Window fields: i0, j0, sx, sy, k0, sz.
WIN = 6


@numba.njit(cache=True, parallel=True)
def neighbour_range(h):
    """Minimum and maximum of each column's 3 x 3 neighbourhood, edges repeated
    (scipy's ``minimum_filter`` / ``maximum_filter`` with ``size=3, mode="nearest"``, the
    same values), in one parallel pass instead of scipy's four serial ones."""
    nx, ny = h.shape
    lo = np.empty_like(h)
    hi = np.empty_like(h)
    for i in numba.prange(nx):
        for j in range(ny):
            a, b = h[i, j], h[i, j]
            for di in range(max(i - 1, 0), min(i + 2, nx)):
                for dj in range(max(j - 1, 0), min(j + 2, ny)):
                    a = min(a, h[di, dj])
                    b = max(b, h[di, dj])
            lo[i, j], hi[i, j] = a, b
    return lo, hi


@numba.njit(cache=True)
def _tile_range(a, b, tile, ntiles):
    """Tiles whose vertex columns ``[t tile, t tile + tile]`` meet ``[a, b]``."""
    t0 = max(-((tile - a) // tile), 0)  # ceil((a - tile) / tile)
    t1 = min(b // tile, ntiles - 1)
    return t0, t1


@numba.njit(cache=True)
def tile_levels(tile, ntx, nty, nz, K0, K1, boxes):
    """``occ[tx, ty, k]``: some vertex column of the tile has a band voxel at level k;
    and the boxes of each tile as CSR ``(ptr, idx)``."""
    diff = np.zeros((ntx, nty, nz + 1), dtype=np.int32)
    nx, ny = K0.shape[1], K0.shape[2]
    for m in range(K0.shape[0]):
        for i in range(nx):
            ta, tb = _tile_range(i, i, tile, ntx)
            for j in range(ny):
                a, b = K0[m, i, j], K1[m, i, j]
                if a > b:
                    continue
                ua, ub = _tile_range(j, j, tile, nty)
                for tx in range(ta, tb + 1):
                    for ty in range(ua, ub + 1):
                        diff[tx, ty, a] += 1
                        diff[tx, ty, b + 1] -= 1
    count = np.zeros(ntx * nty + 1, dtype=np.int64)
    for n in range(boxes.shape[0]):
        ta, tb = _tile_range(boxes[n, 0], boxes[n, 3], tile, ntx)
        ua, ub = _tile_range(boxes[n, 1], boxes[n, 4], tile, nty)
        for tx in range(ta, tb + 1):
            for ty in range(ua, ub + 1):
                count[tx * nty + ty + 1] += 1
                diff[tx, ty, boxes[n, 2]] += 1
                diff[tx, ty, boxes[n, 5] + 1] -= 1
    count = np.cumsum(count)
    idx = np.empty(count[-1], dtype=np.int64)
    fill = count.copy()
    for n in range(boxes.shape[0]):
        ta, tb = _tile_range(boxes[n, 0], boxes[n, 3], tile, ntx)
        ua, ub = _tile_range(boxes[n, 1], boxes[n, 4], tile, nty)
        for tx in range(ta, tb + 1):
            for ty in range(ua, ub + 1):
                idx[fill[tx * nty + ty]] = n
                fill[tx * nty + ty] += 1
    occ = np.zeros((ntx, nty, nz), dtype=np.bool_)
    for tx in range(ntx):
        for ty in range(nty):
            s = 0
            for k in range(nz):
                s += diff[tx, ty, k]
                occ[tx, ty, k] = s > 0
    return occ, count, idx


@numba.njit(cache=True, parallel=True)
def window_mask(win, off, tile, nty, K0, K1, boxes, ptr, idx, mask):
    """Mark each window's band voxels in the flat ``mask``; returns the band count.
    (Windows are disjoint in ``mask``: they are marked in parallel.)"""
    band = 0
    for w in numba.prange(win.shape[0]):
        i0, j0, sx, sy, k0, sz = win[w, 0], win[w, 1], win[w, 2], win[w, 3], win[w, 4], win[w, 5]
        o = off[w]
        for m in range(K0.shape[0]):
            for di in range(sx):
                for dj in range(sy):
                    a = max(K0[m, i0 + di, j0 + dj], k0)
                    b = min(K1[m, i0 + di, j0 + dj], k0 + sz - 1)
                    base = o + (di * sy + dj) * sz - k0
                    for k in range(a, b + 1):
                        mask[base + k] = True
        t = (i0 // tile) * nty + j0 // tile
        for q in range(ptr[t], ptr[t + 1]):
            n = idx[q]
            for i in range(max(boxes[n, 0], i0), min(boxes[n, 3], i0 + sx - 1) + 1):
                for j in range(max(boxes[n, 1], j0), min(boxes[n, 4], j0 + sy - 1) + 1):
                    base = o + ((i - i0) * sy + (j - j0)) * sz - k0
                    for k in range(max(boxes[n, 2], k0), min(boxes[n, 5], k0 + sz - 1) + 1):
                        mask[base + k] = True
        for q in range(o, o + sx * sy * sz):
            band += mask[q]
    return band


@numba.njit(cache=True, inline="always")
def _direct_value(x, y, z, hc, kind, P, boxes):
    """The closed form of the root from the column's elevation ``hc`` (float32);
    NaN within float32 rounding of 0 (left to the tree)."""
    one, two, zero = np.float32(1.0), np.float32(2.0), np.float32(0.0)
    if kind == 0:
        v = hc - z
        m = min(abs(v), P[0])
        st = m + m * m * (P[1] + P[2] * m)
        if v < 0:
            st = -st
        dx = max(max(P[4] - x, x - P[7]), zero)
        dy = max(max(P[5] - y, y - P[8]), zero)
        dz = max(max(P[6] - z, z - P[9]), zero)
        u = np.sqrt(dx * dx + dy * dy + dz * dz) / P[0]
        w = max(one - u * u, zero)
        f = min(st, P[3] * (two * w * w * w - one))
    else:
        qx = abs(x - P[0]) - P[3]
        qy = abs(y - P[1]) - P[4]
        qz = abs(z - P[2]) - P[5]
        out = np.sqrt(max(qx, zero) ** 2 + max(qy, zero) ** 2 + max(qz, zero) ** 2)
        f = min(hc - z, -(out + min(max(max(qx, qy), qz), zero)))
    scale = abs(hc) + abs(z) + abs(x) + abs(y) + abs(P[0]) + abs(P[3])
    for b in range(boxes.shape[0]):
        qx = abs(x - boxes[b, 0]) - boxes[b, 3]
        qy = abs(y - boxes[b, 1]) - boxes[b, 4]
        qz = abs(z - boxes[b, 2]) - boxes[b, 5]
        out = np.sqrt(max(qx, zero) ** 2 + max(qy, zero) ** 2 + max(qz, zero) ** 2)
        f = min(f, boxes[b, 6] - (out + min(max(max(qx, qy), qz), zero)))
    # Within float32 rounding of 0 the sign could differ from the tree's own
    # evaluation: leave those to the tree (NaN marks them).
    if abs(f) <= np.float32(1e-5) * scale:
        return np.float32(np.nan)
    return f


@numba.njit(cache=True, parallel=True)
def direct_fill(vol, mask, win, off, direct, h, lo, voxel, kind, P, boxes):
    """Closed-form values of the band voxels of direct columns; returns their count.
    (Windows are disjoint in ``vol``: they are filled in parallel.)"""
    count = 0
    for w in numba.prange(win.shape[0]):
        i0, j0, sx, sy, k0, sz = win[w, 0], win[w, 1], win[w, 2], win[w, 3], win[w, 4], win[w, 5]
        for di in range(sx):
            for dj in range(sy):
                if not direct[i0 + di, j0 + dj]:
                    continue
                x = lo[0] + np.float32(i0 + di) * voxel
                y = lo[1] + np.float32(j0 + dj) * voxel
                hc = h[i0 + di, j0 + dj]
                base = off[w] + (di * sy + dj) * sz
                for dk in range(sz):
                    if mask[base + dk]:
                        z = lo[2] + np.float32(k0 + dk) * voxel
                        f = _direct_value(x, y, z, hc, kind, P, boxes)
                        vol[base + dk] = f
                        count += f == f
    return count


@numba.njit(cache=True, inline="always")
def _evaluated(vol, mask, d, q):
    """Whether the band voxel at flat ``q`` is left to the tree (not direct, or NaN)."""
    return mask[q] and (not d or vol[q] != vol[q])


@numba.njit(cache=True, parallel=True)
def to_evaluate(vol, mask, win, off, direct):
    """Flat positions (ascending) and grid indices ``(N, 3)`` of the band voxels the
    tree evaluates (non-direct columns, and direct values left as NaN). Two passes
    over the windows in parallel: counts, then each window's entries at its offset."""
    nw = win.shape[0]
    count = np.zeros(nw + 1, dtype=np.int64)
    for w in numba.prange(nw):
        sx, sy, sz = win[w, 2], win[w, 3], win[w, 5]
        c = 0
        for di in range(sx):
            for dj in range(sy):
                d = direct[win[w, 0] + di, win[w, 1] + dj]
                base = off[w] + (di * sy + dj) * sz
                for dk in range(sz):
                    c += _evaluated(vol, mask, d, base + dk)
        count[w + 1] = c
    start = np.cumsum(count)
    pos = np.empty(start[-1], dtype=np.int64)
    ijk = np.empty((start[-1], 3), dtype=np.int64)
    for w in numba.prange(nw):
        i0, j0, sx, sy, k0, sz = win[w, 0], win[w, 1], win[w, 2], win[w, 3], win[w, 4], win[w, 5]
        n = start[w]
        for di in range(sx):
            for dj in range(sy):
                d = direct[i0 + di, j0 + dj]
                base = off[w] + (di * sy + dj) * sz
                for dk in range(sz):
                    if _evaluated(vol, mask, d, base + dk):
                        pos[n] = base + dk
                        ijk[n, 0], ijk[n, 1], ijk[n, 2] = i0 + di, j0 + dj, k0 + dk
                        n += 1
    return pos, ijk


@numba.njit(cache=True, parallel=True)
def grid_points(ijk, lo, voxel):
    """``float32(lo + ijk voxel)`` (the sum in double, as numpy's ``lo + ijk * voxel``
    rounded to float32 by :func:`~arches_render.field.node.evaluate`): the grid's points."""
    pts = np.empty(ijk.shape, dtype=np.float32)
    for q in numba.prange(ijk.shape[0]):
        for a in range(3):
            pts[q, a] = np.float32(lo[a] + np.float64(ijk[q, a]) * voxel)
    return pts


@numba.njit(cache=True)
def _ijk(pos, win, off):
    """Grid indices of ascending flat positions."""
    ijk = np.empty((len(pos), 3), dtype=np.int64)
    w = 0
    for n in range(len(pos)):
        while pos[n] >= off[w + 1]:
            w += 1
        r = pos[n] - off[w]
        sy, sz = win[w, 3], win[w, 5]
        ijk[n, 0] = win[w, 0] + r // (sy * sz)
        ijk[n, 1] = win[w, 1] + (r // sz) % sy
        ijk[n, 2] = win[w, 4] + r % sz
    return ijk


@numba.njit(cache=True, parallel=True)
def fill_gaps(vol, mask, win, off, voxel):
    """Give each window column's non-band voxels ``+-voxel`` with the sign of the
    nearest band voxel below (above for the lowest run); returns the flat start and
    grid index of the window columns without band voxels (one evaluation each), in
    ascending order. (Windows in parallel: a pass that fills and counts, one that lists.)"""
    nw = win.shape[0]
    count = np.zeros(nw + 1, dtype=np.int64)
    for w in numba.prange(nw):
        sx, sy, sz = win[w, 2], win[w, 3], win[w, 5]
        empty = 0
        for c in range(sx * sy):
            base = off[w] + c * sz
            first = -1
            last = np.float32(0.0)
            for k in range(sz):
                if mask[base + k]:
                    last = voxel if vol[base + k] > 0 else -voxel
                    if first < 0:
                        first = k
                        for q in range(k):
                            vol[base + q] = last
                elif first >= 0:
                    vol[base + k] = last
            empty += first < 0
        count[w + 1] = empty
    start = np.cumsum(count)
    starts = np.empty(start[-1], dtype=np.int64)
    for w in numba.prange(nw):
        sz = win[w, 5]
        n = start[w]
        for c in range(win[w, 2] * win[w, 3]):
            base = off[w] + c * sz
            banded = False
            for k in range(sz):
                if mask[base + k]:
                    banded = True
                    break
            if not banded:
                starts[n] = base
                n += 1
    return starts, _ijk(starts, win, off)


@numba.njit(cache=True)
def _crossing_layers(v, i0, i1, j0, j1, cross):
    """``cross[k]``: a cube ``(i, j, k)``, ``i0 <= i < i1``, ``j0 <= j < j1``, of the 3-D
    array ``v`` has corners on both sides of 0 (``> 0`` as marching cubes)."""
    cross[:] = False
    for i in range(i0, i1):
        for j in range(j0, j1):
            for k in range(v.shape[2] - 1):
                if cross[k]:
                    continue
                pos = 0
                for di in range(2):
                    for dj in range(2):
                        for dk in range(2):
                            pos += v[i + di, j + dj, k + dk] > 0
                if 0 < pos < 8:
                    cross[k] = True


@numba.njit(cache=True)
def _append_runs(out, n, cross, head):
    """Append ``(*head, c0, c1)`` for each run ``c0 .. c1`` of true ``cross`` layers
    (``out`` grows by doubling); returns ``(out, n)``."""
    k = 0
    while k < len(cross) - 1:
        if cross[k]:
            c0 = k
            while k + 1 < len(cross) - 1 and cross[k + 1]:
                k += 1
            if n == out.shape[0]:
                grown = np.empty((2 * n, out.shape[1]), dtype=np.int64)
                grown[:n] = out
                out = grown
            for q in range(len(head)):
                out[n, q] = head[q]
            out[n, len(head)], out[n, len(head) + 1] = c0, k
            n += 1
        k += 1
    return out, n


@numba.njit(cache=True, parallel=True)
def crossing_runs(vol, win, off):
    """Runs ``(w, c0, c1)`` of consecutive cube layers of window ``w`` holding a cube
    whose corners do not all share a sign (levels ``c0 .. c1 + 1`` of the window),
    by window. (Windows in parallel: their crossing layers, then the runs in order.)"""
    nw = win.shape[0]
    lstart = np.zeros(nw + 1, dtype=np.int64)
    for w in range(nw):
        lstart[w + 1] = lstart[w] + win[w, 5]
    cross = np.zeros(lstart[-1], dtype=np.bool_)
    count = np.zeros(nw + 1, dtype=np.int64)
    for w in numba.prange(nw):
        sx, sy, sz = win[w, 2], win[w, 3], win[w, 5]
        v = vol[off[w]:off[w + 1]].reshape((sx, sy, sz))
        layers = cross[lstart[w]:lstart[w + 1]]
        _crossing_layers(v, 0, sx - 1, 0, sy - 1, layers)
        runs = 0
        for k in range(sz - 1):
            runs += layers[k] and (k == 0 or not layers[k - 1])
        count[w + 1] = runs
    start = np.cumsum(count)
    out = np.empty((start[-1], 3), dtype=np.int64)
    for w in numba.prange(nw):  # (each window's slice holds exactly its runs)
        _append_runs(out[start[w]:start[w + 1]], 0, cross[lstart[w]:lstart[w + 1]], np.full(1, w, dtype=np.int64))
    return out


@numba.njit(cache=True)
def tile_crossing_runs(vol, tile):
    """:func:`crossing_runs` of a whole ``(nx, ny, nz)`` grid cut into column tiles:
    ``(i0, j0, sx, sy, c0, c1)`` per run, in tile order (the dense reference)."""
    nx, ny, nz = vol.shape
    out = np.empty((16, 6), dtype=np.int64)
    n = 0
    cross = np.zeros(nz, dtype=np.bool_)
    head = np.empty(4, dtype=np.int64)
    for i0 in range(0, nx - 1, tile):
        for j0 in range(0, ny - 1, tile):
            sx, sy = min(tile, nx - 1 - i0) + 1, min(tile, ny - 1 - j0) + 1
            _crossing_layers(vol, i0, i0 + sx - 1, j0, j0 + sy - 1, cross)
            head[0], head[1], head[2], head[3] = i0, j0, sx, sy
            out, n = _append_runs(out, n, cross, head)
    return out[:n]
