"""Contact points between rock volumes in contact.

Aperiodic tiles (Peytavie et al. 2009, section 5, "Contact points"): for every
two volumes ``V_i`` and ``V_j`` that touch, the contact point ``c_ij`` is the
point of the segment ``[p_i, p_j]`` where ``d_i(c_ij) = d_j(c_ij)``, found by
bisection. All contact points are kept (the paper does so to avoid floating
rocks).

Periodic tile (Peytavie et al. 2009, Arches, section 5): a contact point is a
random point of the face shared by the two cells; on the voxel grid, the
midpoint of a random pair of face-adjacent voxels of the two cells.

Two volumes touch when two of their voxels share a face.
"""

from __future__ import annotations

import numba
import numpy as np

from .seed_points import Seeds, anisotropic_distance, hash_uniform

__all__ = ["adjacent_label_pairs", "bisect_contacts", "random_face_contacts"]


def _face_pairs(labels: np.ndarray, periodic: bool):
    """All face-adjacent voxel pairs with different labels: (label_a, label_b, index_a, axis)."""
    out = []
    for axis in range(3):
        if periodic:
            a, b = labels, np.roll(labels, -1, axis=axis)
            ia = np.arange(labels.size).reshape(labels.shape)
        else:
            sl_a = [slice(None)] * 3
            sl_b = [slice(None)] * 3
            sl_a[axis], sl_b[axis] = slice(0, -1), slice(1, None)
            a, b = labels[tuple(sl_a)], labels[tuple(sl_b)]
            ia = np.arange(labels.size).reshape(labels.shape)[tuple(sl_a)]
        diff = (a != b) & (a >= 0) & (b >= 0)
        out.append((a[diff], b[diff], ia[diff], np.full(int(diff.sum()), axis)))
    return [np.concatenate(x) for x in zip(*out)]


@numba.njit(cache=True, nogil=True)
def _adjacent_keys(labels, periodic, m):
    """Keys ``min * m + max`` of face-adjacent voxels with different labels (both >= 0).

    Repeats of the last key are skipped (runs along a shared face give the same
    pair again and again); the caller takes the unique keys.
    """
    nx, ny, nz = labels.shape
    out = np.empty(3 * labels.size, dtype=np.int64)
    n = 0
    last = -1
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                a = labels[i, j, k]
                if a < 0:
                    continue
                for axis in range(3):
                    p, q, r = i, j, k
                    if axis == 0:
                        p += 1
                    elif axis == 1:
                        q += 1
                    else:
                        r += 1
                    if periodic:
                        p, q, r = p % nx, q % ny, r % nz
                    elif p == nx or q == ny or r == nz:
                        continue
                    b = labels[p, q, r]
                    if b >= 0 and b != a:
                        key = np.int64(min(a, b)) * m + max(a, b)
                        if key != last:
                            out[n] = key
                            n += 1
                            last = key
    return out[:n]


def adjacent_label_pairs(labels: np.ndarray, periodic: bool = False) -> np.ndarray:
    """Unordered pairs of labels with face-adjacent voxels.

    Parameters
    ----------
    labels : (nx, ny, nz) int array
        Voronoi labels (``-1``: unknown, ignored).
    periodic : bool
        The grid wraps around (periodic tile).

    Returns
    -------
    (P, 2) int64
        Unique pairs ``(i, j)`` with ``i < j``.
    """
    m = int(labels.max()) + 1
    key = np.unique(_adjacent_keys(np.ascontiguousarray(labels), bool(periodic), m))
    return np.stack([key // m, key % m], axis=1)


def bisect_contacts(seeds: Seeds, pairs, iterations: int = 48) -> np.ndarray:
    """Contact points ``c_ij`` on ``[p_i, p_j]`` with ``d_i(c_ij) = d_j(c_ij)``, by bisection.

    Parameters
    ----------
    seeds : Seeds
    pairs : (P, 2) int array
        Seed indices.
    iterations : int
        Bisection steps (48 halvings reach double precision on a unit segment).

    Returns
    -------
    (P, 3) float64
        Contact points in cell units.

    Notes
    -----
    ``h(t) = d_i(x(t)) - d_j(x(t))`` is continuous with ``h(0) = -d_j(p_i) < 0`` and
    ``h(1) = d_i(p_j) > 0``, so bisection always brackets a root.

    References
    ----------
    Peytavie et al. 2009, section 5, "Contact points".
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    i, j = pairs[:, 0], pairs[:, 1]
    pi, pj = seeds.position[i], seeds.position[j]
    # Along x(t) = p_i + t (p_j - p_i) the quadratic distances are d_i = t^2 q_i and
    # d_j = (1 - t)^2 q_j: the bisection runs on these scalars, with no 3-D work per step.
    q_i = anisotropic_distance(seeds, i, pj)
    q_j = anisotropic_distance(seeds, j, pi)
    lo = np.zeros(len(pairs))
    hi = np.ones(len(pairs))
    for _ in range(iterations):
        t = 0.5 * (lo + hi)
        neg = t * t * q_i - (1.0 - t) ** 2 * q_j < 0
        lo = np.where(neg, t, lo)
        hi = np.where(neg, hi, t)
    t = 0.5 * (lo + hi)
    return pi + t[:, None] * (pj - pi)


def random_face_contacts(labels: np.ndarray, seed: int):
    """One random contact point per pair of touching cells of a periodic grid (Arches).

    Parameters
    ----------
    labels : (N, N, N) int array
        Periodic Voronoi labels.
    seed : int

    Returns
    -------
    pairs : (P, 2) int64
    points : (P, 3) float64
        Midpoints of a random face-adjacent voxel pair of each cell pair, in tile
        units ``[0, 1)``.
    """
    N = labels.shape[0]
    a, b, ia, axis = _face_pairs(labels, True)
    lo, hi = np.minimum(a, b).astype(np.int64), np.maximum(a, b).astype(np.int64)
    key = lo * (int(labels.max()) + 1) + hi
    u = hash_uniform(np.asarray([seed], np.uint64) ^ (ia.astype(np.uint64) * np.uint64(3) + axis.astype(np.uint64)), 7)
    order = np.lexsort((u, key))
    first = order[np.r_[True, key[order][1:] != key[order][:-1]]] if len(order) else order
    idx = np.stack(np.unravel_index(ia[first], labels.shape), axis=1).astype(np.float64)
    step = np.zeros((len(first), 3))
    step[np.arange(len(first)), axis[first]] = 0.5
    points = np.mod((idx + 0.5 + step) / N, 1.0)
    return np.stack([lo[first], hi[first]], axis=1), points
