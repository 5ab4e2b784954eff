"""The periodic rock tile of Arches (Peytavie et al. 2009, "Arches", section 5).

1. A Poisson sphere distribution of radius ``r`` in the unit cube ``C``,
   considered periodic (centres ``p_i`` at least ``2 r`` apart through the
   cube's faces), by dart throwing.
2. Euclidean Voronoi cells ``V_i`` of the periodic point set, on an ``N^3``
   voxel grid that wraps around, so the cells tile space periodically.
3. One random contact point ``c_ij`` on the face between every two touching
   cells, a Gaussian resistance ``exp(-|p - c_ij|^2 / r^2)`` around it, and
   spheroidal erosion weighted by ``1 - max resistance``
   (:mod:`.damped_erosion`).
4. One closed mesh per cell, unwrapped around its centre (a rock crossing the
   tile's faces is stored whole, once).

Coordinates are stored in cells: the tile edge is ``K^(1/3)`` cells for ``K``
rocks, so a rock is about one cell across as in the aperiodic tiles and the
scene's ``rock_size`` means the same for both tilings.
"""

from __future__ import annotations

import time

import numpy as np

from .anisotropic_voronoi import periodic_voronoi_labels
from .contact_points import random_face_contacts
from .damped_erosion import GAUSSIAN, damping_field, erode
from .rock_meshes import anchor_voxels, blur_field, bounding_radius, field_padding, mesh_rock
from .rock_store import RockStore
from .seed_points import hash_keys
from .tile_params import TileParams

__all__ = ["poisson_points", "build_periodic_tile"]


def poisson_points(radius: float, seed: int, failures: int = 3000) -> np.ndarray:
    """Periodic Poisson sphere distribution in ``[0, 1)^3`` by dart throwing.

    Parameters
    ----------
    radius : float
        Sphere radius ``r``; centres are at least ``2 r`` apart (minimum image).
    seed : int
    failures : int
        Stop after this many rejected darts in a row (near saturation).

    Returns
    -------
    (K, 3) float64

    References
    ----------
    Lagae A., Dutre P. (2006). Poisson sphere distributions. VMV 2006.
    """
    rng = np.random.default_rng(int(hash_keys(seed, 0xA5C4E5)[()]))
    pts = np.zeros((0, 3))
    misses = 0
    d2 = (2.0 * radius) ** 2
    while misses < failures:
        batch = rng.random((256, 3))
        for c in batch:
            d = pts - c
            d -= np.round(d)
            if len(pts) and np.min(np.einsum("ij,ij->i", d, d)) < d2:
                misses += 1
                if misses >= failures:
                    break
                continue
            pts = np.vstack([pts, c])
            misses = 0
    return pts


def build_periodic_tile(params: TileParams, progress=None) -> RockStore:
    """The periodic rock tile (see module docstring).

    Parameters
    ----------
    params : TileParams
        With ``tiling = 'periodic'``; uses ``poisson_radius``, ``periodic_voxels``,
        ``seed``, ``erosion`` (steps, rate, smoothing), ``anchors``, ``mesh_step``.
    progress : callable, optional
        ``progress(done_rocks, total_rocks)``.

    Returns
    -------
    RockStore
        One slot; ``meta['cells_per_period']`` is the tile edge in cells.

    References
    ----------
    Peytavie A., Galin E., Merillou S., Grosjean J. (2009). Arches: a framework
    for modeling complex terrains. Computer Graphics Forum 28(2), section 5.
    """
    if params.tiling != "periodic":
        raise ValueError("build_periodic_tile needs tiling = 'periodic'")
    t0 = time.perf_counter()
    N, r, er = params.periodic_voxels, params.poisson_radius, params.erosion
    pts = poisson_points(r, params.seed)
    K = len(pts)
    labels = periodic_voronoi_labels(pts, N)
    pairs, cpts = random_face_contacts(labels, params.seed)
    omega = damping_field(labels, (0, 0, 0), N, K, pairs, cpts, r, kind=GAUSSIAN, periodic=True)
    rho = erode(labels, np.ones(K, bool), omega, er.steps, er.rate, periodic=True)

    P = float(K) ** (1.0 / 3.0)                  # tile edge in cells
    pad = field_padding(er.smoothing, params.mesh_step)
    flat = labels.ravel()
    order = np.argsort(flat, kind="stable")
    starts = np.searchsorted(flat[order], np.arange(K + 1))
    rocks = []
    for k in range(K):
        idx = np.stack(np.unravel_index(order[starts[k]:starts[k + 1]], labels.shape), axis=1)
        s = np.floor(pts[k] * N).astype(np.int64)
        u = s + np.mod(idx - s + N // 2, N) - N // 2          # unwrapped around the centre
        lo = u.min(axis=0) - pad
        field = np.zeros(tuple(u.max(axis=0) + 1 + pad - lo), dtype=np.float32)
        field[tuple((u - lo).T)] = rho[tuple(idx.T)]
        field = blur_field(field, er.smoothing)
        mesh = mesh_rock(field, lo, N, params.mesh_step)
        if progress:
            progress(k + 1, K)
        if mesh is None:
            continue
        verts, faces, normals = mesh
        anchors = (anchor_voxels(field, params.anchors) + lo + 0.5) / N * P
        p = pts[k] * P
        v = verts.astype(np.float64) * P
        rocks.append(dict(vertices=v.astype(np.float32), faces=faces, normals=normals, seed=p,
                          radius=bounding_radius(v, p),
                          uid=hash_keys(params.seed, 0x9E81, k)[()], slot=0,
                          anchors=anchors.astype(np.float32)))
    meta = dict(tiling="periodic", params=params.to_dict(), cells_per_period=P, voxels_per_cell=N / P,
                poisson_points=K, contacts=len(pairs), build_seconds=time.perf_counter() - t0)
    return RockStore.from_rocks(rocks, 1, meta)
