"""Compiled walkers of :mod:`.material_stacks`: loops over the CSR layer arrays.

Each function takes the raw arrays of a :class:`.material_stacks.MaterialStacks`
(``offsets`` of ``ncol + 1`` entries, ``material`` and ``count`` of one entry a
layer; see that module's docstring for the layout) and walks them column by
column in numba: the column heights, the merged intervals of some materials, the
dense decoding of a window of levels and the rewriting of such a window. They
index without bounds checks, so the arrays must be consistent
(:meth:`.material_stacks.MaterialStacks.load` checks a file's arrays before use).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def column_heights(offsets, count):
    """Top level of every column (sum of its layer counts)."""
    n = len(offsets) - 1
    out = np.zeros(n, dtype=np.int64)
    for c in range(n):
        s = 0
        for k in range(offsets[c], offsets[c + 1]):
            s += count[k]
        out[c] = s
    return out


@njit(cache=True)
def _merged_intervals(offsets, material, count, sel):
    n = len(offsets) - 1
    off = np.zeros(n + 1, dtype=np.int64)
    lo = np.empty(len(material), dtype=np.float64)
    hi = np.empty(len(material), dtype=np.float64)
    k_out = 0
    for c in range(n):
        z = 0
        open_ = False
        for k in range(offsets[c], offsets[c + 1]):
            t = count[k]
            if sel[material[k]]:
                if open_:
                    hi[k_out - 1] = z + t
                else:
                    lo[k_out] = z
                    hi[k_out] = z + t
                    k_out += 1
                    open_ = True
            else:
                open_ = False
            z += t
        off[c + 1] = k_out
    return off, lo[:k_out].copy(), hi[:k_out].copy()


@njit(cache=True)
def _decode_window(offsets, material, count, cols, lev0, n):
    out = np.zeros((len(cols), n), dtype=np.uint8)
    for r in range(len(cols)):
        c = cols[r]
        z = 0
        for k in range(offsets[c], offsets[c + 1]):
            a, b = z, z + count[k]
            lo, hi = max(a, lev0), min(b, lev0 + n)
            for l in range(lo, hi):
                out[r, l - lev0] = material[k]
            z = b
    return out


@njit(cache=True)
def _rewrite(offsets, material, count, cols, lev0, block, n_levels):
    ncol = len(offsets) - 1
    nb = block.shape[1]
    touched = np.full(ncol, -1, dtype=np.int64)
    for r in range(len(cols)):
        touched[cols[r]] = r
    # Encode every touched column into scratch runs.
    cap = 0
    for r in range(len(cols)):
        c = cols[r]
        cap += offsets[c + 1] - offsets[c] + nb + 2
    sm = np.empty(cap, dtype=np.uint8)
    sn = np.empty(cap, dtype=np.int64)
    s_start = np.zeros(len(cols) + 1, dtype=np.int64)
    buf = np.zeros(n_levels, dtype=np.uint8)
    pos = 0
    for r in range(len(cols)):
        c = cols[r]
        z = 0
        for k in range(offsets[c], offsets[c + 1]):
            for l in range(z, z + count[k]):
                buf[l] = material[k]
            z += count[k]
        top = z
        for l in range(lev0, min(lev0 + nb, n_levels)):
            v = block[r, l - lev0]
            if v >= 0:
                buf[l] = v
                if l + 1 > top:
                    top = l + 1
        # Run-length encode [0, top), drop trailing air, then clear the buffer.
        last = top
        while last > 0 and buf[last - 1] == 0:
            last -= 1
        s_start[r] = pos
        l = 0
        while l < last:
            m = buf[l]
            e = l
            while e < last and buf[e] == m:
                e += 1
            # uint16 counts: a run can never exceed n_levels <= 65535.
            sm[pos] = m
            sn[pos] = e - l
            pos += 1
            l = e
        for l in range(top):
            buf[l] = 0
        s_start[r + 1] = pos
    new_off = np.zeros(ncol + 1, dtype=np.uint32)
    for c in range(ncol):
        r = touched[c]
        ln = (s_start[r + 1] - s_start[r]) if r >= 0 else (offsets[c + 1] - offsets[c])
        new_off[c + 1] = new_off[c] + ln
    total = new_off[ncol]
    nm = np.empty(total, dtype=np.uint8)
    nn = np.empty(total, dtype=np.uint16)
    for c in range(ncol):
        r = touched[c]
        o = new_off[c]
        if r >= 0:
            for q in range(s_start[r], s_start[r + 1]):
                nm[o] = sm[q]
                nn[o] = sn[q]
                o += 1
        else:
            for k in range(offsets[c], offsets[c + 1]):
                nm[o] = material[k]
                nn[o] = count[k]
                o += 1
    return new_off, nm, nn
