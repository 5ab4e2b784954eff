"""Discrete anisotropic Voronoi cells on the voxel grid ``G`` (Peytavie et al. 2009, section 4).

Every voxel ``G_ijk`` gets the index ``k`` of the seed minimising the
ellipsoidal distance ``d_k(v_ijk) = f_k(v_ijk) / g_k`` at its centre
``v_ijk`` (see :mod:`.seed_points`). The grid has ``V`` voxels per cell; the
paper uses ``n_G = 10 n`` voxels per corner cube edge, i.e. ``V = 10``.

Locality. The paper assumes that a rock depends only on the seeds of the
1-neighbourhood of its cell, which the exact multiplicatively weighted diagram
does not guarantee (with ``g`` up to 4 a cell can reach further). We make the
assumption exact: the candidates of a voxel are the seeds of the ``2 x 2 x 2``
cells around the cell corner nearest to it. A rock then lies within half a
cell of its own cell, and its voxels depend only on the seeds of the
``3 x 3 x 3`` cells around its cell, which the corner cube construction shares
between neighbouring cubes (:mod:`.corner_cubes`). Away from that clip the
diagram is the paper's.

Exactness. Voxel and seed positions enter as ``((i - V c) + 0.5) / V - offset``
with integers ``i`` (voxel) and ``c`` (seed cell), so a voxel gets bit-identical
distances, hence the same label, in every region grid that contains it; ties
are broken by the seeds' context-free ids. Assembled tiles therefore partition
space with no gap or duplicate.

The kernels are numba loops over the grid. The aperiodic one works in blocks
of ``V^3`` voxels that share their candidate cells (parallel over blocks): the
distance terms that depend on one axis are formed once per block and seed,
with the same operations in the same order as the per-voxel expression, so
the labels are the same bits as a voxel-by-voxel evaluation.
"""

from __future__ import annotations

import numba
import numpy as np

from .seed_points import Seeds

__all__ = ["CellIndex", "voronoi_labels", "periodic_voronoi_labels"]


class CellIndex:
    """Seeds sorted by cell inside a box of known cells (CSR lists), for the kernels.

    Parameters
    ----------
    seeds : Seeds
    lo : (3,) int
        Lowest known cell.
    shape : (3,) int
        Number of known cells per axis; seeds outside the box are dropped.
    """

    def __init__(self, seeds: Seeds, lo, shape):
        self.lo = np.asarray(lo, dtype=np.int64)
        self.shape = np.asarray(shape, dtype=np.int64)
        rel = seeds.cell - self.lo
        ok = np.all((rel >= 0) & (rel < self.shape), axis=1)
        flat = np.ravel_multi_index(rel[ok].T, self.shape) if ok.any() else np.zeros(0, np.int64)
        order = np.argsort(flat, kind="stable")
        self.index = np.nonzero(ok)[0][order]          # position in the caller's seed arrays
        self.seeds = seeds.take(self.index)
        counts = np.bincount(flat, minlength=int(np.prod(self.shape)))
        self.start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


@numba.njit(cache=True, nogil=True, inline="always")
def _offset(v, V, s, scell, soff, a):
    """Axis ``a`` of voxel ``v``'s centre minus seed ``s``, in cells: exact in the voxel and cell integers."""
    return (float(v - V * scell[s, a]) + 0.5) / V - soff[s, a]


@numba.njit(parallel=True, cache=True, nogil=True)
def _labels_kernel(g0, shape, V, clo, cshape, start, scell, soff, smet, suid, out):
    # A voxel's candidates are the 2 x 2 x 2 cells from (v + V/2) // V - 1 on: the same for
    # a block of V voxels per axis. Per block and candidate, the terms of the distance that
    # depend on one axis only are computed once (V per axis, not V^3).
    half = V // 2
    b0 = (g0 + half) // V
    nb = (g0 + shape - 1 + half) // V - b0 + 1
    for blk in numba.prange(nb[0] * nb[1] * nb[2]):
        b = np.array([blk // (nb[1] * nb[2]), (blk // nb[2]) % nb[1], blk % nb[2]]) + b0
        lo = np.maximum(b * V - half - g0, 0)
        hi = np.minimum((b + 1) * V - half - g0, shape)
        c0 = b - 1 - clo
        c1 = np.minimum(c0 + 2, cshape)
        c0 = np.maximum(c0, 0)
        cand = []
        for cx in range(c0[0], c1[0]):
            for cy in range(c0[1], c1[1]):
                for cz in range(c0[2], c1[2]):
                    c = (cx * cshape[1] + cy) * cshape[2] + cz
                    for s in range(start[c], start[c + 1]):
                        cand.append(s)
        nc = len(cand)
        nx, ny, nz = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
        dxx = np.empty((nc, nx))
        mxy = np.empty((nc, nx))
        mxz = np.empty((nc, nx))
        dy = np.empty((nc, ny))
        dyy = np.empty((nc, ny))
        myz = np.empty((nc, ny))
        dz = np.empty((nc, nz))
        dzz = np.empty((nc, nz))
        for q in range(nc):
            s = cand[q]
            for t in range(nx):
                x = _offset(g0[0] + lo[0] + t, V, s, scell, soff, 0)
                dxx[q, t] = smet[s, 0] * x * x
                mxy[q, t] = smet[s, 3] * x
                mxz[q, t] = smet[s, 4] * x
            for t in range(ny):
                y = _offset(g0[1] + lo[1] + t, V, s, scell, soff, 1)
                dy[q, t] = y
                dyy[q, t] = smet[s, 1] * y * y
                myz[q, t] = smet[s, 5] * y
            for t in range(nz):
                z = _offset(g0[2] + lo[2] + t, V, s, scell, soff, 2)
                dz[q, t] = z
                dzz[q, t] = smet[s, 2] * z * z
        best = np.empty(nz)
        bl = np.empty(nz, dtype=np.int64)
        bu = np.empty(nz, dtype=np.uint64)
        for i in range(nx):
            for j in range(ny):
                best[:] = np.inf
                bl[:] = -1
                bu[:] = 0
                # Candidates outside, a row of voxels inside: branch-free selects the compiler
                # vectorises. (d, uid) is a strict order, so the winner does not depend on
                # the candidates' order.
                for q in range(nc):
                    s = cand[q]
                    u = suid[s]
                    a = dxx[q, i] + dyy[q, j]
                    bx = mxy[q, i] * dy[q, j]
                    for k in range(nz):
                        # The expression of the reference distance, term by term:
                        # M_xx dx dx + M_yy dy dy + M_zz dz dz + 2 (M_xy dx dy + M_xz dx dz + M_yz dy dz).
                        d = a + dzz[q, k] + 2.0 * (bx + mxz[q, i] * dz[q, k] + myz[q, j] * dz[q, k])
                        win = d < best[k] or (d == best[k] and u < bu[k])
                        best[k] = d if win else best[k]
                        bl[k] = s if win else bl[k]
                        bu[k] = u if win else bu[k]
                for k in range(nz):
                    out[lo[0] + i, lo[1] + j, lo[2] + k] = bl[k]


def voronoi_labels(index: CellIndex, g0, shape, V: int) -> np.ndarray:
    """Seed label of every voxel of a grid (the discrete Voronoi volumes ``V_k``).

    Parameters
    ----------
    index : CellIndex
        Seeds of the known cells.
    g0 : (3,) int
        Global index of the grid's first voxel (voxel ``i`` spans
        ``[i / V, (i + 1) / V)`` in cell units).
    shape : (3,) int
        Voxels per axis.
    V : int
        Voxels per cell (even).

    Returns
    -------
    (nx, ny, nz) int32
        Index into ``index.seeds`` of the winning seed, ``-1`` where no
        candidate cell is known.

    References
    ----------
    Peytavie et al. 2009, section 4, "Discrete implementation".
    """
    if V % 2:
        raise ValueError(f"voxels per cell must be even (got {V})")
    out = np.empty(tuple(int(s) for s in shape), dtype=np.int32)
    s = index.seeds
    _labels_kernel(np.asarray(g0, np.int64), np.asarray(shape, np.int64), int(V), index.lo, index.shape,
                   index.start, s.cell, s.offset, s.metric, s.uid, out)
    return out


@numba.njit(parallel=True, cache=True, nogil=True)
def _periodic_kernel(N, pos, out):
    for i in numba.prange(N):
        for j in range(N):
            for k in range(N):
                x = (i + 0.5) / N
                y = (j + 0.5) / N
                z = (k + 0.5) / N
                best = np.inf
                bl = -1
                for s in range(pos.shape[0]):
                    dx = x - pos[s, 0]
                    dy = y - pos[s, 1]
                    dz = z - pos[s, 2]
                    dx -= np.floor(dx + 0.5)
                    dy -= np.floor(dy + 0.5)
                    dz -= np.floor(dz + 0.5)
                    d = dx * dx + dy * dy + dz * dz
                    if d < best:
                        best = d
                        bl = s
                out[i, j, k] = bl


def periodic_voronoi_labels(points, N: int) -> np.ndarray:
    """Euclidean Voronoi labels on an ``N^3`` grid of the periodic unit cube (Arches, section 5).

    Parameters
    ----------
    points : (K, 3) array_like
        Seeds in ``[0, 1)^3``.
    N : int
        Voxels per tile edge.

    Returns
    -------
    (N, N, N) int32
    """
    out = np.empty((N, N, N), dtype=np.int32)
    _periodic_kernel(int(N), np.ascontiguousarray(points, dtype=np.float64), out)
    return out
