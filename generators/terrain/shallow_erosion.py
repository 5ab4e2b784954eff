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

    Each column holds the points kept in it so far, appended as they are kept, in a
    region of a column-sorted array as long as the column's candidates: a kept point
    within ``radius`` of a candidate lies in one of the nine columns around it,
    whatever its height, and only kept points are read (on the Sea-scale coast's
    cliffs a column holds 13 candidates on average, 63 at most, of which about one is
    kept). The test is a set's, so the order of a column's kept points does not
    change which candidates are kept. The candidates are read in ``order`` from a
    copy made in that order, and a column's region start and kept count share a
    cache line: the pass is bound by memory latency.
    """
    n = P.shape[0]
    lo0, lo1 = P[:, 0].min(), P[:, 1].min()
    nx = np.int64((P[:, 0].max() - lo0) / cell) + 1
    ny = np.int64((P[:, 1].max() - lo1) / cell) + 1
    Po = np.empty((n, 3))
    column = np.empty(n, dtype=np.int64)      # of the o-th candidate in order
    region = np.zeros((nx * ny + 1, 2), dtype=np.int64)  # (start of the region, kept so far)
    for o in range(n):
        q = order[o]
        Po[o, 0], Po[o, 1], Po[o, 2] = P[q, 0], P[q, 1], P[q, 2]
        column[o] = np.int64((P[q, 0] - lo0) / cell) * ny + np.int64((P[q, 1] - lo1) / cell)
        region[column[o] + 1, 0] += 1
    for c in range(nx * ny):
        region[c + 1, 0] += region[c, 0]
    Pk = np.empty((n, 3))                     # region start + k: the column's k-th kept point
    keep = np.zeros(n, dtype=np.bool_)
    r2 = radius * radius
    for o in range(n):
        x, y, z = Po[o, 0], Po[o, 1], Po[o, 2]
        ci, cj = column[o] // ny, column[o] % ny
        ok = True
        for di in range(max(ci - 1, 0), min(ci + 2, nx)):
            for dj in range(max(cj - 1, 0), min(cj + 2, ny)):
                c = di * ny + dj
                for t in range(region[c, 0], region[c, 0] + region[c, 1]):
                    dx, dy, dz = Pk[t, 0] - x, Pk[t, 1] - y, Pk[t, 2] - z
                    if dx * dx + dy * dy + dz * dz <= r2:
                        ok = False
                        break
                if not ok:
                    break
            if not ok:
                break
        if ok:
            c = column[o]
            t = region[c, 0] + region[c, 1]
            Pk[t, 0], Pk[t, 1], Pk[t, 2] = x, y, z
            region[c, 1] += 1
            keep[order[o]] = True
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
