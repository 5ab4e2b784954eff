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
def _greedy(order, start, nbr, keep):
    for i in order:
        ok = True
        for k in range(start[i], start[i + 1]):
            if keep[nbr[k]]:
                ok = False
                break
        keep[i] = ok
    return keep


def poisson_thin(points, radius, rng):
    """Keep a subset of points no two of which are closer than ``radius``.

    Greedy dart throwing over the candidates in random order (a candidate is kept
    when no kept point lies within ``radius``), with a KD-tree for the pairs: on
    a dense enough candidate set this is a maximal Poisson-disc sample.

    Parameters
    ----------
    points : numpy.ndarray
        ``(N, d)`` candidates.
    radius : float
        Minimum distance between kept points.
    rng : numpy.random.Generator
        Order of the candidates.

    Returns
    -------
    numpy.ndarray
        Indices of the kept points, sorted.
    """
    from scipy.spatial import cKDTree
    P = np.asarray(points, dtype=np.float64)
    n = len(P)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    pairs = cKDTree(P).query_pairs(radius, output_type="ndarray").astype(np.int64)
    start, nbr = _adjacency(pairs, n)
    keep = _greedy(rng.permutation(n).astype(np.int64), start, nbr, np.zeros(n, dtype=np.bool_))
    return np.flatnonzero(keep)


@numba.njit(cache=True)
def _csr_fill(pairs, start, nbr):
    fill = start[:-1].copy()
    for k in range(pairs.shape[0]):
        i, j = pairs[k, 0], pairs[k, 1]
        nbr[fill[i]] = j
        fill[i] += 1
        nbr[fill[j]] = i
        fill[j] += 1
    return nbr


def _adjacency(pairs, n):
    """CSR neighbour lists of an undirected pair list (linear time, no sort)."""
    count = np.bincount(pairs[:, 0], minlength=n) + np.bincount(pairs[:, 1], minlength=n)
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(count, out=start[1:])
    return start, _csr_fill(pairs, start, np.empty(2 * len(pairs), dtype=np.int64))


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
