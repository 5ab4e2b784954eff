"""The nearest-neighbour graph of the tile samples, cut by fractures into clusters.

Paris et al. (2020, section 4.1, Figure 4): the samples ``P`` of the tile are linked
by the geometric neighbour graph ``G``; edges crossing a fracture disc are removed,
and the connected sub-graphs ``G_i`` (*clusters*) become the blocks. The paper then
checks that "all the points in a given cluster are visible to each other, i.e.
that fractures do not cut an edge connecting any pair of points in the cluster",
so that clusters do not spread around a disc.

Details of this implementation:

* Neighbour threshold. The paper links ``p_i, p_j`` when ``|p_i - p_j| < r`` with
  ``r`` the Poisson radius; Poisson samples are at least ``r`` apart, so that graph
  has no edge. We use ``2 r`` (about 13 neighbours per sample).
* Periodicity. The tile is a torus: edges use the minimum image, and a cluster is
  *unwrapped* by a breadth-first walk (each sample gets the position of its parent
  plus the edge vector). A cluster that closes on itself around the torus (an
  unbroken bed of a tabular tile) has no finite unwrapping, and one longer than
  the tile (an open strip winding around it) would make a hull covering other
  blocks; both are cut on the tile faces of those axes (an extra joint every
  ``s`` metres).
* Visibility. A cluster fails the paper's check when a disc image has samples of
  the cluster on both sides of its plane whose projections fall inside the disc:
  the segment between two such samples crosses the plane inside the (convex)
  disc, so they do not see each other. Such a cluster is split by the whole plane
  of the disc that hides the most samples (the smaller side's count; every
  cluster edge crossing the plane is removed): the fracture propagates through
  the block it had only partly cut, which is how partial discs still make convex
  blocks. This repeats until every cluster passes (only clusters changed by the
  last round are checked again). Taking the *first* failing disc instead favours
  the orientation of the first disc set and flattened equidimensional blocks.

References
----------
Paris et al. (2020), section 4.1 (fracturing), Figure 4.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .fracture_discs import Discs, cut_edges, disc_images

__all__ = ["neighbour_graph", "fracture_clusters"]


def neighbour_graph(points: np.ndarray, size: float, threshold: float):
    """Edges ``(i, j, d)`` with ``d`` the minimum-image vector ``p_j - p_i``, ``|d| < threshold``."""
    tree = cKDTree(points, boxsize=float(size))
    pairs = tree.query_pairs(float(threshold), output_type="ndarray")
    i, j = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    d = points[j] - points[i]
    d -= size * np.round(d / size)
    return i, j, d


def _labels(n, i, j, alive):
    g = coo_matrix((np.ones(int(alive.sum())), (i[alive], j[alive])), shape=(n, n))
    return connected_components(g, directed=False)[1]


@numba.njit(cache=True)
def _unwrap(points, i, j, d, alive, labels, n_labels, size):
    """Breadth-first unwrapping; flags the axes along which a cluster wraps."""
    n = len(points)
    deg = np.zeros(n + 1, dtype=np.int64)
    for e in range(len(i)):
        if alive[e]:
            deg[i[e] + 1] += 1
            deg[j[e] + 1] += 1
    start = np.cumsum(deg)
    fill = start[:-1].copy()
    nbr = np.empty(start[-1], dtype=np.int64)
    sgn = np.empty(start[-1], dtype=np.int64)  # +1: edge stored as i->j, -1: reversed
    eid = np.empty(start[-1], dtype=np.int64)
    for e in range(len(i)):
        if alive[e]:
            a, b = i[e], j[e]
            nbr[fill[a]] = b
            sgn[fill[a]] = 1
            eid[fill[a]] = e
            fill[a] += 1
            nbr[fill[b]] = a
            sgn[fill[b]] = -1
            eid[fill[b]] = e
            fill[b] += 1
    u = np.empty_like(points)
    seen = np.zeros(n, dtype=np.bool_)
    wraps = np.zeros((n_labels, 3), dtype=np.bool_)
    queue = np.empty(n, dtype=np.int64)
    for root in range(n):
        if seen[root]:
            continue
        seen[root] = True
        u[root] = points[root]
        head, tail = 0, 1
        queue[0] = root
        while head < tail:
            c = queue[head]
            head += 1
            for k in range(start[c], start[c + 1]):
                b = nbr[k]
                e = eid[k]
                if not seen[b]:
                    seen[b] = True
                    for a in range(3):
                        u[b, a] = u[c, a] + sgn[k] * d[e, a]
                    queue[tail] = b
                    tail += 1
                else:
                    for a in range(3):
                        gap = u[b, a] - (u[c, a] + sgn[k] * d[e, a])
                        if abs(gap) > 0.5 * size:
                            wraps[labels[root], a] = True
    return u, wraps


@numba.njit(cache=True)
def _find_splits(u, order, cstart, center, normal, radius, size, check):
    """Per cluster, the disc image (disc index, image shift) that it sees on both
    sides with the most samples (``min`` of the two sides' counts of samples whose
    projection falls inside the disc): the most significant hidden fracture, so
    that no orientation is favoured by the order of the discs."""
    n_c = len(cstart) - 1
    found = -np.ones(n_c, dtype=np.int64)
    shift = np.zeros((n_c, 3))
    for c in range(n_c):
        a0, a1 = cstart[c], cstart[c + 1]
        if a1 - a0 < 2 or not check[c]:
            continue
        lo = np.full(3, 1e30)
        hi = np.full(3, -1e30)
        for q in range(a0, a1):
            for a in range(3):
                lo[a] = min(lo[a], u[order[q], a])
                hi[a] = max(hi[a], u[order[q], a])
        best = 0
        for dsc in range(len(radius)):
            r = radius[dsc]
            if not np.isfinite(r):
                continue  # infinite planes cut every crossing edge already
            klo = np.empty(3, dtype=np.int64)
            khi = np.empty(3, dtype=np.int64)
            for a in range(3):
                klo[a] = int(np.floor((lo[a] - center[dsc, a] - r) / size))
                khi[a] = int(np.ceil((hi[a] - center[dsc, a] + r) / size))
            for kx in range(klo[0], khi[0] + 1):
                for ky in range(klo[1], khi[1] + 1):
                    for kz in range(klo[2], khi[2] + 1):
                        cx = center[dsc, 0] + kx * size
                        cy = center[dsc, 1] + ky * size
                        cz = center[dsc, 2] + kz * size
                        # Skip a plane that misses the cluster's box (all corners
                        # on one side): it cannot hide samples from each other.
                        smin = 1e30
                        smax = -1e30
                        for corner in range(8):
                            qx = hi[0] if corner & 1 else lo[0]
                            qy = hi[1] if corner & 2 else lo[1]
                            qz = hi[2] if corner & 4 else lo[2]
                            sd0 = ((qx - cx) * normal[dsc, 0] + (qy - cy) * normal[dsc, 1]
                                   + (qz - cz) * normal[dsc, 2])
                            smin = min(smin, sd0)
                            smax = max(smax, sd0)
                        if smin >= 0.0 or smax <= 0.0:
                            continue
                        pos = 0
                        neg = 0
                        for q in range(a0, a1):
                            p = order[q]
                            vx, vy, vz = u[p, 0] - cx, u[p, 1] - cy, u[p, 2] - cz
                            sd = vx * normal[dsc, 0] + vy * normal[dsc, 1] + vz * normal[dsc, 2]
                            if sd == 0.0:
                                continue
                            # Projection on the disc plane, relative to the centre.
                            wx = vx - sd * normal[dsc, 0]
                            wy = vy - sd * normal[dsc, 1]
                            wz = vz - sd * normal[dsc, 2]
                            if wx * wx + wy * wy + wz * wz < r * r:
                                if sd > 0:
                                    pos += 1
                                else:
                                    neg += 1
                        score = min(pos, neg)
                        if score > best:
                            best = score
                            found[c] = dsc
                            shift[c, 0] = kx * size
                            shift[c, 1] = ky * size
                            shift[c, 2] = kz * size
    return found, shift


@numba.njit(cache=True)
def _cut_by_planes(u, i, d, alive, labels, found, shift, center, normal):
    changed = 0
    for e in range(len(i)):
        if not alive[e]:
            continue
        c = labels[i[e]]
        dsc = found[c]
        if dsc < 0:
            continue
        da = 0.0
        db = 0.0
        for a in range(3):
            o = center[dsc, a] + shift[c, a]
            da += (u[i[e], a] - o) * normal[dsc, a]
            db += (u[i[e], a] + d[e, a] - o) * normal[dsc, a]
        if (da > 0 and db < 0) or (da < 0 and db > 0) or (da == 0 and db != 0) or (db == 0 and da != 0):
            alive[e] = False
            changed += 1
    return changed


def fracture_clusters(points: np.ndarray, size: float, discs: Discs, threshold: float,
                      max_rounds: int = 40):
    """Clusters of the fractured neighbour graph of a periodic tile.

    Parameters
    ----------
    points : numpy.ndarray
        ``(N, 3)`` samples in ``[0, size)^3`` (periodic Poisson disc).
    size : float
        Tile edge ``s``.
    discs : Discs
        Fracture discs (their periodic images are taken into account here).
    threshold : float
        Neighbour distance of the graph (``2 r``).
    max_rounds : int
        Bound on the split rounds (a round splits every failing cluster once).

    Returns
    -------
    labels : numpy.ndarray
        ``(N,)`` cluster index of each sample.
    unwrapped : numpy.ndarray
        ``(N, 3)`` positions with every cluster in one piece (shifted by multiples of
        ``s`` from ``points``), its centroid inside the tile.
    stats : dict
        ``edges``, ``cut_edges`` (by the discs), ``rounds`` (of wrap cuts and splits).

    References
    ----------
    Paris et al. (2020), section 4.1.
    """
    s = float(size)
    n = len(points)
    i, j, d = neighbour_graph(points, s, threshold)
    pad = float(threshold)
    images = disc_images(discs, s, np.full(3, -pad), np.full(3, s + pad))
    a = points[i]
    cut = cut_edges(a, a + d, images)
    alive = ~cut
    center = np.ascontiguousarray(discs.center)
    normal = np.ascontiguousarray(discs.normal)
    radius = np.ascontiguousarray(discs.radius)
    rounds = 0
    # Only clusters that changed in the last round need a new visibility check.
    dirty = np.ones(n, dtype=bool)
    while True:
        labels = _labels(n, i, j, alive)
        n_labels = int(labels.max()) + 1
        u, wraps = _unwrap(points, i, j, d, alive, labels, n_labels, s)
        order = np.argsort(labels, kind="stable")
        cstart = np.concatenate([[0], np.cumsum(np.bincount(labels, minlength=n_labels))])
        # Splits first (the positions of a wrapping cluster are consistent along
        # its breadth-first tree, which is all a plane split needs) ...
        check = np.bincount(labels, dirty, n_labels) > 0
        found, shift = _find_splits(u, order, cstart, center, normal, radius, s, check)
        if rounds >= max_rounds:
            break
        if (found >= 0).any():
            _cut_by_planes(u, i, d, alive, labels, found, shift, center, normal)
            dirty = found[labels] >= 0
            rounds += 1
            continue
        # A cluster longer than the tile (an open helical strip winding around
        # the torus) is treated as wrapping: its hull would cover other blocks.
        lo_c = np.full((n_labels, 3), np.inf)
        hi_c = np.full((n_labels, 3), -np.inf)
        np.minimum.at(lo_c, labels, u)
        np.maximum.at(hi_c, labels, u)
        wraps |= (hi_c - lo_c) > s
        if not wraps.any():
            break
        # ... then a cluster that still wraps around the torus is cut on the tile
        # faces of the axes it wraps around.
        cw = wraps[labels[i]]
        end = points[i] + d
        crosses = (end < 0) | (end >= s)
        alive &= ~np.any(cw & crosses, axis=1)
        dirty = wraps.any(1)[labels]
        rounds += 1
    # Move each cluster so that its centroid lies in the tile.
    cnt = np.bincount(labels, minlength=n_labels)[:, None]
    cen = np.stack([np.bincount(labels, u[:, k], n_labels) for k in range(3)], 1) / np.maximum(cnt, 1)
    u = u - s * np.floor(cen / s)[labels]
    stats = dict(edges=len(i), cut_edges=int(cut.sum()), rounds=rounds)
    return labels, u, stats
