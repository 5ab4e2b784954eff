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

The kernels are numba loops over the grid (parallel over slabs); they are the
hot spot of tile generation.
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


@numba.njit(parallel=True, cache=True, nogil=True)
def _labels_kernel(g0, shape, V, clo, cshape, start, scell, soff, smet, suid, out):
    half = V // 2
    for i in numba.prange(shape[0]):
        vx = g0[0] + i
        cx0 = (vx + half) // V - 1 - clo[0]
        for j in range(shape[1]):
            vy = g0[1] + j
            cy0 = (vy + half) // V - 1 - clo[1]
            for k in range(shape[2]):
                vz = g0[2] + k
                cz0 = (vz + half) // V - 1 - clo[2]
                best = np.inf
                bl = -1
                bu = np.uint64(0)
                for cx in range(max(cx0, 0), min(cx0 + 2, cshape[0])):
                    for cy in range(max(cy0, 0), min(cy0 + 2, cshape[1])):
                        for cz in range(max(cz0, 0), min(cz0 + 2, cshape[2])):
                            c = (cx * cshape[1] + cy) * cshape[2] + cz
                            for s in range(start[c], start[c + 1]):
                                dx = (float(vx - V * scell[s, 0]) + 0.5) / V - soff[s, 0]
                                dy = (float(vy - V * scell[s, 1]) + 0.5) / V - soff[s, 1]
                                dz = (float(vz - V * scell[s, 2]) + 0.5) / V - soff[s, 2]
                                d = (smet[s, 0] * dx * dx + smet[s, 1] * dy * dy + smet[s, 2] * dz * dz
                                     + 2.0 * (smet[s, 3] * dx * dy + smet[s, 4] * dx * dz
                                              + smet[s, 5] * dy * dz))
                                if d < best or (d == best and suid[s] < bu):
                                    best = d
                                    bl = s
                                    bu = suid[s]
                out[i, j, k] = bl


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
