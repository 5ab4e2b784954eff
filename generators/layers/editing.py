"""Shared machinery of the editing tools: regions of stacks, level windows, landings, noise.

A tool (sculpt, sweep, deposit, erosion; Peytavie et al. 2009, section 4) touches
the stacks whose central axis crosses its region of influence. It classifies the
levels of those axes inside a window ``[lev0, lev0 + n)`` and rewrites them with
:meth:`MaterialStacks.rewrite`: the paper's "update the material stacks that
intersect R ... along the central axis of the material stack".
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .material_stacks import MaterialStacks


class Region:
    """Stacks and levels under an axis-aligned box of influence.

    Attributes
    ----------
    cols : numpy.ndarray
        Column indices ``j nx + i`` of the stacks whose axis lies in the box.
    x, y : numpy.ndarray
        Their axis coordinates.
    lev0, n : int
        The level window ``[lev0, lev0 + n)``.
    z : numpy.ndarray
        Centres of the window's levels (metres).
    """

    def __init__(self, stacks: MaterialStacks, lo, hi):
        x0, y0, z0 = stacks.origin
        s, dz = stacks.cell, stacks.dz
        i0 = max(0, int(np.ceil((lo[0] - x0) / s - 0.5)))
        i1 = min(stacks.nx - 1, int(np.floor((hi[0] - x0) / s - 0.5)))
        j0 = max(0, int(np.ceil((lo[1] - y0) / s - 0.5)))
        j1 = min(stacks.ny - 1, int(np.floor((hi[1] - y0) / s - 0.5)))
        self.lev0 = max(0, int(np.floor((lo[2] - z0) / dz)))
        lev1 = min(stacks.n_levels, int(np.ceil((hi[2] - z0) / dz)))
        self.n = max(0, lev1 - self.lev0)
        if i1 < i0 or j1 < j0 or self.n == 0:
            self.cols = np.zeros(0, dtype=np.int64)
            self.x = self.y = np.zeros(0)
        else:
            ii, jj = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1))
            self.cols = (jj * stacks.nx + ii).ravel().astype(np.int64)
            self.x = x0 + (ii.ravel() + 0.5) * s
            self.y = y0 + (jj.ravel() + 0.5) * s
        self.z = z0 + (self.lev0 + np.arange(self.n) + 0.5) * dz

    @property
    def empty(self) -> bool:
        return len(self.cols) == 0 or self.n == 0

    def points(self):
        """``(len(cols), n, 3)`` sample points on the axes."""
        k, n = len(self.cols), self.n
        P = np.empty((k, n, 3))
        P[..., 0] = self.x[:, None]
        P[..., 1] = self.y[:, None]
        P[..., 2] = self.z[None, :]
        return P


def landing_levels(stacks: MaterialStacks, cols, level):
    """Floor and ceiling (levels) of the air that each stack has at ``level``.

    Where the stack is solid at ``level``, the floor is the top of that solid run
    (material dropped there rests on it). Returns ``(floor, ceiling)`` int64 arrays;
    the ceiling of the open sky is ``n_levels``.
    """
    return _landing_csr(stacks.offsets, stacks.material, stacks.count,
                        np.asarray(cols, dtype=np.int64), int(level), stacks.n_levels)


@njit(cache=True)
def _landing_csr(offsets, material, count, cols, level, n_levels):
    floor = np.zeros(len(cols), dtype=np.int64)
    ceil = np.zeros(len(cols), dtype=np.int64)
    for r in range(len(cols)):
        c = cols[r]
        z = 0
        a, b = offsets[c], offsets[c + 1]
        floor[r] = -1
        k = a
        while k < b:
            lo, hi = z, z + count[k]
            if lo <= level < hi or (level < lo and floor[r] < 0):
                if material[k] == 0:
                    floor[r] = lo
                    ceil[r] = hi
                    break
                # Solid here: climb to the top of this solid run.
                while k < b and material[k] != 0:
                    z += count[k]
                    k += 1
                floor[r] = z
                ceil[r] = z + count[k] if k < b else n_levels
                break
            z = hi
            k += 1
        if floor[r] < 0:
            floor[r] = z
            ceil[r] = n_levels
    return floor, ceil


def value_noise(points, wavelength, seed):
    """Smooth 3-D value noise in ``[-1, 1]`` (trilinear, smoothstep-faded, hashed lattice).

    Deterministic for a given ``seed``; used to roughen the tools' regions.
    """
    rng = np.random.default_rng(seed)
    table = rng.uniform(-1.0, 1.0, 4096)
    perm = rng.permutation(4096)
    q = np.asarray(points, dtype=np.float64) / wavelength
    f = np.floor(q)
    t = q - f
    t = t * t * (3 - 2 * t)
    fi = f.astype(np.int64)
    out = 0.0
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                h = perm[(fi[..., 0] + dx) % 4096]
                h = perm[(h + fi[..., 1] + dy) % 4096]
                h = perm[(h + fi[..., 2] + dz) % 4096]
                w = ((t[..., 0] if dx else 1 - t[..., 0]) * (t[..., 1] if dy else 1 - t[..., 1])
                     * (t[..., 2] if dz else 1 - t[..., 2]))
                out = out + w * table[h]
    return out


def falloff(r, R):
    """The point-primitive potential ``g(r) = (1 - (r/R)^2)^2`` for ``r < R``, else 0 (section 4.1)."""
    x = np.clip(1.0 - (np.asarray(r, dtype=np.float64) / R) ** 2, 0.0, None)
    return x * x


def axis_mask(stacks: MaterialStacks, region: Region, inside, step=None):
    """Levels of the region's stack axes that lie inside a volume, ``(len(cols), n)`` bool.

    The axes are sampled every ``step`` metres (default a quarter cell) and every
    change of side is refined by bisection to the quantum ``dz``: the roots along
    the central axis of section 4.1, without evaluating the tool at every level.
    Parts of the volume thinner than ``step`` along an axis may be missed.

    Parameters
    ----------
    stacks : MaterialStacks
    region : Region
    inside : callable
        ``inside(points (N, 3)) -> bool (N,)``.
    step : float, optional
    """
    k, n = len(region.cols), region.n
    step = 0.25 * stacks.cell if step is None else float(step)
    zlo, zhi = region.z[0], region.z[-1]
    m = max(2, int(np.ceil((zhi - zlo) / step)) + 1)
    zs = np.linspace(zlo, zhi, m)

    def at(ci, z):
        return inside(np.stack([region.x[ci], region.y[ci], z], axis=1))

    ci_all = np.repeat(np.arange(k), m)
    coarse = at(ci_all, np.tile(zs, k)).reshape(k, m)
    ci, mi = np.nonzero(coarse[:, 1:] != coarse[:, :-1])
    a, b = zs[mi].copy(), zs[mi + 1].copy()
    va = coarse[ci, mi]
    if len(ci):
        for _ in range(int(np.ceil(np.log2(max((zs[1] - zs[0]) / stacks.dz, 1.0)))) + 1):
            mid = 0.5 * (a + b)
            same = at(ci, mid) == va
            a = np.where(same, mid, a)
            b = np.where(same, b, mid)
    # Toggle the side at the first level whose centre lies past each boundary.
    t = np.searchsorted(region.z, 0.5 * (a + b))
    acc = np.zeros((k, n + 1), dtype=np.int32)
    np.add.at(acc, (ci, t), 1)
    parity = (np.cumsum(acc, axis=1)[:, :n] % 2).astype(bool)
    return coarse[:, :1] ^ parity
