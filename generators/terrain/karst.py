"""Karst cave networks by invasion percolation (Paris et al. 2019, section 6.2).

Invasion percolation (Wilkinson & Willemsen 1983) advances a slow fluid pore by
pore into the *least resistant* pore of its frontier. The paper's variant:

1. The queue ``Q`` starts with seed points: the sinks (pits) of the heightfield
   and user resurgence points.
2. While ``Q`` holds candidates, pop the one of least *perturbed* resistance
   ``rho(p) + epsilon (u - 1/2)`` (``u`` uniform; ``epsilon ~ 0.1`` adds variety).
3. Carve it if ``rho(p) < rho_0``: a tunnel primitive joins it to the point it was
   reached from, with a radius following ``e(rho, sigma)``
   (:func:`~arches_render.generators.terrain.shallow_erosion.erosion_intensity`,
   ``sigma = 1``: water is the agent everywhere underground).
4. Propagate: add new candidates in random directions of the *lower* hemisphere
   (water infiltrates downwards), only where their Poisson sphere meets no
   other candidate.

Pores live on a jittered lattice of spacing ``h`` (each site moved by up to
``jitter h`` inside its cell, seeded): two candidates of different sites are at
least ``(1 - 2 jitter) h`` apart, so "the Poisson sphere of a new sample meets no
other candidate" becomes "the site was never queued". The lower hemisphere is the
17 lattice neighbours with ``dz <= 0`` (8 beside, 9 below); each propagation
draws ``branching`` of them at random. The resistance of every site is evaluated
once, in one batch, from the geology tree; the queue is a binary heap in numba.

The output is a set of segments (parent site -> invaded site) and, for the seeds,
a shaft from the surface pit down to the first site: tunnel primitives for the
construction tree. Deviation: a sink on hard rock (``rho >= rho_0``) would never
start the paper's queue, so the water first descends the joint under the sink,
site by site, to the first soft site; the shaft reaches down to it.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), section 6.2, Fig. 14, 16.
Wilkinson, D., Willemsen, J. F. (1983). Invasion percolation: a new form of
percolation theory. J. Phys. A 16(14), 3365.
"""

from __future__ import annotations

import numba
import numpy as np

from .hydrology import fill_depressions, heap_pop, heap_push, pits
from .shallow_erosion import ErosionPrimitives, erosion_intensity

__all__ = ["PercolationLattice", "invasion_percolation", "karst_seeds", "karst_network"]

# The lower hemisphere of the 26-neighbourhood: dz in {-1, 0}, not the site itself.
_LOWER = np.array([(dx, dy, dz) for dz in (-1, 0) for dy in (-1, 0, 1) for dx in (-1, 0, 1)
                   if (dx, dy, dz) != (0, 0, 0)], dtype=np.int64)


class PercolationLattice:
    """Jittered lattice of pores over a box, with their resistance.

    Parameters
    ----------
    lo, hi : sequence of 3 floats
        Box of the lattice, metres.
    spacing : float
        Lattice spacing ``h``, metres.
    rng : numpy.random.Generator
        Jitter.
    jitter : float
        Largest displacement of a site, as a fraction of ``h`` (< 0.5).

    Attributes
    ----------
    shape : tuple
        ``(nz, ny, nx)``.
    positions : numpy.ndarray
        ``(nz * ny * nx, 3)`` site positions, flat index ``(k ny + j) nx + i``.
    """

    def __init__(self, lo, hi, spacing, rng, jitter=0.3):
        lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        if not 0 <= jitter < 0.5:
            raise ValueError("jitter must be in [0, 0.5)")
        n = np.maximum(np.floor((hi - lo) / spacing).astype(np.int64) + 1, 1)
        if np.prod(n) > 20_000_000:
            raise ValueError(f"percolation lattice of {n.tolist()} sites is too large; increase the spacing")
        self.spacing, self.lo = float(spacing), lo
        self.shape = (int(n[2]), int(n[1]), int(n[0]))
        k, j, i = np.meshgrid(np.arange(n[2]), np.arange(n[1]), np.arange(n[0]), indexing="ij")
        base = lo + spacing * np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
        self.positions = base + rng.uniform(-jitter, jitter, base.shape) * spacing

    def index(self, points):
        """Flat index of the site nearest to each point (clamped to the lattice)."""
        nz, ny, nx = self.shape
        q = np.rint((np.asarray(points, dtype=np.float64) - self.lo) / self.spacing).astype(np.int64)
        q = np.clip(q, 0, [nx - 1, ny - 1, nz - 1])
        return (q[:, 2] * ny + q[:, 1]) * nx + q[:, 0]


@numba.njit(cache=True)
def _percolate(shape, rho, perturbed, allowed, seeds, rho0, branching, max_sites, lower, choice_u):
    nz, ny, nx = shape
    n = nz * ny * nx
    keys = np.empty(n, dtype=np.float64)
    vals = np.empty(n, dtype=np.int64)
    queued = np.zeros(n, dtype=np.bool_)
    parent = np.full(n, -1, dtype=np.int64)
    order = np.empty(min(n, max_sites), dtype=np.int64)
    m = 0
    count = 0
    for s in seeds:
        if allowed[s] and not queued[s]:
            queued[s] = True
            m = heap_push(keys, vals, m, perturbed[s], s)
    u_at = 0
    nl = lower.shape[0]
    idx = np.arange(nl)
    while m > 0 and count < max_sites:
        _, c, m = heap_pop(keys, vals, m)
        if rho[c] >= rho0:
            continue
        order[count] = c
        count += 1
        k, rem = c // (ny * nx), c % (ny * nx)
        j, i = rem // nx, rem % nx
        # A random subset of the lower-hemisphere directions (partial Fisher-Yates).
        for a in range(nl):
            idx[a] = a
        for a in range(min(branching, nl)):
            b = a + int(choice_u[u_at % choice_u.shape[0]] * (nl - a))
            u_at += 1
            idx[a], idx[b] = idx[b], idx[a]
            di, dj, dk = lower[idx[a], 0], lower[idx[a], 1], lower[idx[a], 2]
            ii, jj, kk = i + di, j + dj, k + dk
            if ii < 0 or jj < 0 or kk < 0 or ii >= nx or jj >= ny or kk >= nz:
                continue
            q = (kk * ny + jj) * nx + ii
            if queued[q] or not allowed[q]:
                continue
            queued[q] = True
            parent[q] = c
            m = heap_push(keys, vals, m, perturbed[q], q)
    return order[:count], parent


def invasion_percolation(lattice, rho, seeds, rho0=0.5, epsilon=0.1, branching=6, max_sites=100_000,
                         allowed=None, rng=None):
    """Invasion percolation over a pore lattice (see module docstring).

    Parameters
    ----------
    lattice : PercolationLattice
        Sites.
    rho : numpy.ndarray
        ``(n_sites,)`` resistance in ``[0, 1]`` at the sites.
    seeds : array_like of int
        Flat site indices the fluid enters by.
    rho0 : float
        ``rho_0``: only sites with ``rho < rho0`` are invaded (carved).
    epsilon : float
        Range of the random perturbation of the queue order.
    branching : int
        Lower-hemisphere directions tried per invaded site (1..17).
    max_sites : int
        Budget of invaded sites.
    allowed : numpy.ndarray of bool, optional
        Sites that may be reached (inside the rock); default all.
    rng : numpy.random.Generator
        Perturbations and direction choices.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        Invaded sites in invasion order, and the parent of every site (-1 for
        seeds and for sites never reached).
    """
    rho = np.ascontiguousarray(rho, dtype=np.float64)
    n = len(rho)
    allowed = np.ones(n, dtype=np.bool_) if allowed is None else np.ascontiguousarray(allowed, dtype=np.bool_)
    perturbed = rho + epsilon * (rng.random(n) - 0.5)
    choice_u = rng.random(max(4 * branching * min(max_sites, n), 64))
    return _percolate(lattice.shape, rho, perturbed, allowed, np.asarray(seeds, dtype=np.int64).ravel(),
                      float(rho0), int(branching), int(max_sites), _LOWER, choice_u)


def karst_seeds(heights, extent, count, rng, min_depth=0.0):
    """Entry points of the water: the deepest sinks of the heightfield.

    Sinks (pits, cells lower than their 8 neighbours) are ranked by the depth of
    their depression (filled minus raw height, Barnes et al. 2014); at most half
    of the seeds are pits (a valley floor full of small pits would otherwise take
    them all). The rest are drawn at random among the flatter half of the upper
    half of the terrain (plateaus, where sinkholes form), away from the border.

    Returns
    -------
    numpy.ndarray
        ``(k, 3)`` surface points.
    """
    H = np.asarray(heights, dtype=np.float64)
    ny, nx = H.shape
    x0, y0, x1, y1 = extent
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    depth = fill_depressions(H) - H
    rc = pits(H)
    if len(rc):
        d = depth[rc[:, 0], rc[:, 1]]
        rank = np.argsort(-d, kind="stable")
        rc = rc[rank][d[rank] > min_depth][:(count + 1) // 2]
    if len(rc) < count:
        gy, gx = np.gradient(H, dy, dx)
        flat = np.hypot(gx, gy)
        inner = np.zeros_like(H, dtype=bool)
        inner[ny // 10: ny - ny // 10, nx // 10: nx - nx // 10] = True
        upper = H >= np.median(H[inner])
        cand = np.flatnonzero(inner & upper & (flat <= np.quantile(flat[inner & upper], 0.5)))
        extra = rng.choice(cand, size=min(count - len(rc), len(cand)), replace=False)
        rc = np.concatenate([rc.reshape(-1, 2), np.stack(np.divmod(extra, nx), axis=1)])
    return np.stack([x0 + rc[:, 1] * dx, y0 + rc[:, 0] * dy, H[rc[:, 0], rc[:, 1]]], axis=1)


def karst_network(height_at, extent, z_range, resistance, seeds, spacing, max_radius, rho0=0.5,
                  epsilon=0.1, beta=0.3, branching=6, max_sites=20_000, cover=None, seed=0):
    """Tunnel primitives of a karst network under a terrain.

    Parameters
    ----------
    height_at : callable
        ``h(x, y)`` (numpy arrays) of the terrain surface.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` of the lattice, metres.
    z_range : (float, float)
        Lowest and highest lattice elevation, metres.
    resistance : callable
        ``rho(points (N, 3)) -> (N,)`` in ``[0, 1]`` (the geology tree).
    seeds : array_like
        ``(k, 3)`` surface entry points (sinks).
    spacing : float
        Lattice spacing (Poisson radius), metres.
    max_radius : float
        Tunnel radius for ``e = 1``; a tunnel's radius is ``e(rho, 1) max_radius``.
    rho0, epsilon, beta, branching, max_sites :
        See :func:`invasion_percolation` and ``e(rho, sigma)``.
    cover : float, optional
        Least rock above a site, metres; default ``max_radius``.
    seed : int
        Seed of the jitter, perturbation and directions.

    Returns
    -------
    ErosionPrimitives
        Segments (``center`` -> ``end``) with radius and intensity; a shaft from
        each seed down to its first site comes first.
    """
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = extent
    lat = PercolationLattice((x0, y0, z_range[0]), (x1, y1, z_range[1]), spacing, rng)
    P = lat.positions
    cover = max_radius if cover is None else float(cover)
    allowed = P[:, 2] <= height_at(P[:, 0], P[:, 1]) - cover
    seeds = np.asarray(seeds, dtype=np.float64).reshape(-1, 3)
    if len(seeds) == 0 or not allowed.any():
        return ErosionPrimitives.empty()
    # Each sink enters at the highest allowed site below it.
    below = seeds - [0.0, 0.0, cover + 0.5 * spacing]
    start = lat.index(below)
    nz, ny, nx = lat.shape
    for _ in range(nz):
        blocked = ~allowed[start] & (start >= ny * nx)
        if not blocked.any():
            break
        start = np.where(blocked, start - ny * nx, start)
    ok = allowed[start]
    seeds, start = seeds[ok], start[ok]
    rho = np.clip(np.asarray(resistance(P), dtype=np.float64), 0.0, 1.0)
    # A sink on hard rock would never start the queue (the paper pops only rho < rho_0):
    # water goes down the joint under the sink to the first soft site (a vertical shaft).
    for _ in range(nz):
        hard = (rho[start] >= rho0) & (start >= ny * nx)
        if not hard.any():
            break
        start = np.where(hard, start - ny * nx, start)
    order, parent = invasion_percolation(lat, rho, start, rho0, epsilon, branching, max_sites, allowed, rng)
    if len(order) == 0:
        return ErosionPrimitives.empty()
    e = erosion_intensity(rho[order], 1.0, beta)
    r = e * max_radius
    # Shafts: from each sink (a little above the surface, so the entrance opens) to its first site.
    first = np.isin(start, order)
    shaft_top = seeds[first] + [0.0, 0.0, 0.5 * max_radius]
    shaft_r = erosion_intensity(rho[start[first]], 1.0, beta) * max_radius
    tunnels = parent[order] >= 0
    a = np.concatenate([shaft_top, P[parent[order[tunnels]]]])
    b = np.concatenate([P[start[first]], P[order[tunnels]]])
    radius = np.concatenate([shaft_r, r[tunnels]])
    inten = np.concatenate([erosion_intensity(rho[start[first]], 1.0, beta), e[tunnels]])
    return ErosionPrimitives(a, b, radius, inten)
