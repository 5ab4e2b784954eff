"""numba kernel of :mod:`.support_distances` (imported on use: numba's import costs a
process 0.15-0.2 s, which a scene without a skeletal set need not pay)."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def centre_minima(a, b, reach, glo, cell, res, margin, out):
    """``out[z, y, x] = min(out, |c - s_i(c)| - reach_i)`` over the primitives whose box
    grown by ``margin`` overlaps the cell, ``c`` the cell's centre."""
    for i in range(a.shape[0]):
        lo = np.empty(3, np.int64)
        hi = np.empty(3, np.int64)
        for k in range(3):
            m = min(a[i, k], b[i, k]) - reach[i] - margin
            M = max(a[i, k], b[i, k]) + reach[i] + margin
            lo[k] = max(int(np.floor((m - glo[k]) / cell)), 0)
            hi[k] = min(int(np.floor((M - glo[k]) / cell)), res[k] - 1)
        bax, bay, baz = b[i, 0] - a[i, 0], b[i, 1] - a[i, 1], b[i, 2] - a[i, 2]
        len2 = bax * bax + bay * bay + baz * baz
        for z in range(lo[2], hi[2] + 1):
            cz = glo[2] + (z + 0.5) * cell
            for y in range(lo[1], hi[1] + 1):
                cy = glo[1] + (y + 0.5) * cell
                for x in range(lo[0], hi[0] + 1):
                    cx = glo[0] + (x + 0.5) * cell
                    px, py, pz = cx - a[i, 0], cy - a[i, 1], cz - a[i, 2]
                    t = 0.0
                    if len2 > 0.0:
                        t = min(max((px * bax + py * bay + pz * baz) / len2, 0.0), 1.0)
                    dx, dy, dz = px - t * bax, py - t * bay, pz - t * baz
                    d = np.sqrt(dx * dx + dy * dy + dz * dz) - reach[i]
                    if d < out[z, y, x]:
                        out[z, y, x] = d
    return out
