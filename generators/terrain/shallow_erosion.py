"""Shallow procedural erosion: the two-phase template shared by sea and river erosion.

Paris et al. (2019), section 6.1. Phase one computes an erosion *intensity* at
sample points of the terrain surface from the rock resistance ``rho`` (the
geology tree) and the stress ``sigma`` of an erosive agent:

    e(rho, sigma) = sigma (1 - rho) (1 - beta) + sigma beta,

a bilinear interpolation with ``e(rho, 0) = 0`` (no stress, no erosion) and
``e(1, 1) = beta`` (the erosion of the hardest rock under full stress). Phase two
places, at Poisson-disc samples ``p_k`` of the eroded region, carving primitives
whose strength grows with ``e(p_k)``; samples with ``e`` below a threshold are
discarded (negligible primitives).

This module holds ``e``, the Poisson-disc sampling of a mesh surface and of a 2-D mask, and the container of
the resulting primitives (:class:`ErosionPrimitives`): centres, the radius of
the cavity each one carves, and its intensity. Turning them into field nodes
(negative-energy skeletal primitives summed with the terrain) is the job of
:mod:`~arches_render.generators.terrain.amplify`.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), section 6.1.
Bridson, R. (2007). Fast Poisson disk sampling in arbitrary dimensions.
SIGGRAPH sketches (the minimum-distance property kept here by thinning).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["erosion_intensity", "poisson_thin", "sample_mesh", "sample_mask",
           "ErosionPrimitives"]


def erosion_intensity(rho, sigma, beta=0.2):
    """``e(rho, sigma) = sigma (1 - rho)(1 - beta) + sigma beta`` (section 6.1).

    Parameters
    ----------
    rho : array_like
        Resistance in ``[0, 1]`` (clipped).
    sigma : array_like
        Stress in ``[0, 1]`` (clipped).
    beta : float
        Erosion of the most resistant rock under full stress, in ``[0, 1]``.

    Returns
    -------
    numpy.ndarray
        Intensity in ``[0, 1]``.
    """
    if not 0.0 <= beta <= 1.0:
        raise ValueError(f"beta must be in [0, 1] (got {beta})")
    r = np.clip(np.asarray(rho, dtype=np.float64), 0.0, 1.0)
    s = np.clip(np.asarray(sigma, dtype=np.float64), 0.0, 1.0)
    return s * (1.0 - r) * (1.0 - beta) + s * beta


@numba.njit(cache=True)
def _greedy_in_columns(P, order, cell, radius):
    """Greedy dart throwing over ``order`` on columns ``(i, j)`` at least ``radius`` wide.

    The candidates are counting-sorted by column, so the columns ``(i, j - 1 ..
    j + 1)`` around a candidate are one contiguous run of the sorted copy: a kept
    point within ``radius`` of it lies in one of three runs, whatever its height.
    The runs of a block of candidates are looked up before its greedy pass (loads
    that do not wait on each other), which then reads them in order: the pass is
    bound by memory latency, not arithmetic.
    """
    n = P.shape[0]
    lo0, lo1 = P[:, 0].min(), P[:, 1].min()
    column = np.empty(n, dtype=np.int64)
    nx = np.int64((P[:, 0].max() - lo0) / cell) + 1
    ny = np.int64((P[:, 1].max() - lo1) / cell) + 1
    column_start = np.zeros(nx * ny + 1, dtype=np.int64)
    for q in range(n):
        column[q] = np.int64((P[q, 0] - lo0) / cell) * ny + np.int64((P[q, 1] - lo1) / cell)
        column_start[column[q] + 1] += 1
    for c in range(nx * ny):
        column_start[c + 1] += column_start[c]
    Ps = np.empty((n, 3))                          # sorted copy, contiguous runs
    slot = np.empty(n, dtype=np.int64)            # position of each candidate in Ps
    fill = column_start[:-1].copy()
    for q in range(n):
        s = fill[column[q]]
        fill[column[q]] += 1
        Ps[s] = P[q]
        slot[q] = s
    kept = np.zeros(n, dtype=np.bool_)
    r2 = radius * radius
    block = 1 << 18  # (14.7 MB of runs; smaller blocks ran slower)
    runs = np.zeros((block, 7), dtype=np.int64)  # slot, then (begin, end) of three runs
    for b in range(0, len(order), block):
        m = min(block, len(order) - b)
        for o in range(m):
            q = order[b + o]
            ci, cj = column[q] // ny, column[q] % ny
            runs[o, 0] = slot[q]
            for k in range(3):
                di = ci - 1 + k
                inside = 0 <= di < nx
                runs[o, 1 + 2 * k] = column_start[di * ny + max(cj - 1, 0)] if inside else 0
                runs[o, 2 + 2 * k] = column_start[di * ny + min(cj + 2, ny)] if inside else 0
        for o in range(m):
            s = runs[o, 0]
            x, y, z = Ps[s, 0], Ps[s, 1], Ps[s, 2]
            ok = True
            for k in range(3):
                for t in range(runs[o, 1 + 2 * k], runs[o, 2 + 2 * k]):
                    if kept[t]:
                        dx, dy, dz = Ps[t, 0] - x, Ps[t, 1] - y, Ps[t, 2] - z
                        if dx * dx + dy * dy + dz * dz <= r2:
                            ok = False
                            break
                if not ok:
                    break
            kept[s] = ok
    keep = np.empty(n, dtype=np.bool_)
    for q in range(n):
        keep[q] = kept[slot[q]]
    return keep


#: Cells per axis at most (the grid's tables stay small for any spread of points).
MAX_CELLS_PER_AXIS = 2048


def poisson_thin(points, radius, rng):
    """Keep a subset of points no two of which are closer than ``radius``.

    Greedy dart throwing over the candidates in random order (a candidate is kept
    when no kept point lies within ``radius``): on a dense enough candidate set
    this is a maximal Poisson-disc sample. Written by hand rather than with
    ``scipy.spatial.cKDTree.query_pairs``: that lists every conflicting pair
    (about 40 a candidate at the sea preset's oversampling) before the greedy
    pass can run, and took 1.5 of the Sea-scale amplification's 4.5 s; a grid
    of cells at least ``radius`` wide checks only the kept points around each
    candidate, in one compiled pass. Same order, same test (``|p - q| <= radius``
    rejects), so the same points are kept.

    Parameters
    ----------
    points : numpy.ndarray
        ``(N, d)`` candidates, ``d`` of 2 or 3.
    radius : float
        Minimum distance between kept points.
    rng : numpy.random.Generator
        Order of the candidates.

    Returns
    -------
    numpy.ndarray
        Indices of the kept points, sorted.
    """
    P = np.asarray(points, dtype=np.float64)
    n = len(P)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if not np.isfinite(P).all():
        raise ValueError("poisson_thin: the candidates must be finite points")
    P3 = np.zeros((n, 3))
    P3[:, :P.shape[1]] = P
    span = float(np.max(P3.max(axis=0) - P3.min(axis=0)))
    cell = max(float(radius), span / MAX_CELLS_PER_AXIS, 1e-300)
    order = rng.permutation(n).astype(np.int64)
    return np.flatnonzero(_greedy_in_columns(P3, order, cell, float(radius)))


def sample_mesh(mesh, spacing, face_weight=None, rng=None, oversample=4.0):
    """Poisson-disc samples of a mesh surface (optionally of a weighted part of it).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Surface to sample.
    spacing : float
        Minimum distance between samples, metres.
    face_weight : numpy.ndarray, optional
        ``(M,)`` per-face weights in ``[0, 1]`` (0 excludes a face); candidate
        density is proportional to ``area * weight``.
    rng : numpy.random.Generator
        Randomness (seeded by the caller).
    oversample : float
        Candidates per ``spacing^2`` of (weighted) area.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        ``(K, 3)`` points and ``(K,)`` indices of their faces.
    """
    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
    if face_weight is None:
        idx, fw = np.arange(len(F)), 1.0
    else:  # only the weighted faces are touched (a band of a large mesh)
        fw = np.clip(np.asarray(face_weight, dtype=np.float64), 0.0, 1.0)
        idx = np.flatnonzero(fw > 0)
        fw = fw[idx]
    T = V[F[idx]]
    w = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1) * fw
    total = float(w.sum())
    if total <= 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    count = int(min(max(oversample * total / spacing ** 2, 1), 5e6))
    local = rng.choice(len(w), size=count, p=w / total)
    faces = idx[local]
    tri = T[local]
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])
    keep = poisson_thin(pts, spacing, rng)
    return pts[keep], faces[keep]


def sample_mask(mask, extent, spacing, rng, oversample=4.0):
    """Poisson-disc samples ``(x, y)`` of the cells of a 2-D mask.

    Parameters
    ----------
    mask : numpy.ndarray
        ``(ny, nx)`` weights in ``[0, 1]`` over the grid of ``extent`` (cell
        ``[j, i]`` centred on sample ``(x0 + i dx, y0 + j dy)``).
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)``.
    spacing : float
        Minimum distance between samples.
    rng : numpy.random.Generator
        Randomness.
    oversample : float
        Candidates per ``spacing^2`` of weighted area.

    Returns
    -------
    numpy.ndarray
        ``(K, 2)`` points.
    """
    M = np.clip(np.asarray(mask, dtype=np.float64), 0.0, 1.0)
    ny, nx = M.shape
    x0, y0, x1, y1 = extent
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    total = float(M.sum()) * dx * dy
    if total <= 0:
        return np.zeros((0, 2))
    count = int(min(max(oversample * total / spacing ** 2, 1), 5e6))
    cells = rng.choice(M.size, size=count, p=M.ravel() / M.sum())
    j, i = np.divmod(cells, nx)
    pts = np.stack([x0 + (i + rng.random(count) - 0.5) * dx, y0 + (j + rng.random(count) - 0.5) * dy], 1)
    pts[:, 0] = np.clip(pts[:, 0], x0, x1)
    pts[:, 1] = np.clip(pts[:, 1], y0, y1)
    return pts[poisson_thin(pts, spacing, rng)]


@dataclass
class ErosionPrimitives:
    """Carving primitives of one erosion process (arrays of equal length).

    Attributes
    ----------
    center : numpy.ndarray
        ``(N, 3)`` skeleton points (sphere primitives); for tunnels, the start of
        each segment.
    end : numpy.ndarray
        ``(N, 3)`` segment ends (equal to ``center`` for spheres).
    radius : numpy.ndarray
        ``(N,)`` radius of the cavity each primitive carves in deep rock, metres.
    intensity : numpy.ndarray
        ``(N,)`` erosion intensity ``e`` in ``[0, 1]``.
    """

    center: np.ndarray
    end: np.ndarray
    radius: np.ndarray
    intensity: np.ndarray

    @classmethod
    def empty(cls):
        z = np.zeros((0, 3))
        return cls(z, z.copy(), np.zeros(0), np.zeros(0))

    def __len__(self):
        return len(self.radius)
