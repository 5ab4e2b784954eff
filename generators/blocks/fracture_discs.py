"""Fracture discs of the six structure types and the segment-disc cut of the graph.

Paris et al. (2020, section 4.1) model a fracture as a disc ``D_i(c_i, r_i, n_i)``
(centre, radius, unit normal). The structure types of the rock-mass classification
(Palmstrom 2001) differ by how the discs are distributed in the cubic tile of edge
``s``: number of fractures, radius, centres and relative orientations. Fractures
occur as *sets*: families of parallel, evenly spaced discs. Here a set has a mean
normal, a count ``N = round(s / spacing)`` (so that consecutive discs of the set are
``spacing`` apart along its normal: the centres' offsets along the normal are
stratified, ``(j + 1/2 + U(-1/4, 1/4)) s / N``), a radius interval and an angular
jitter; the in-plane position of each centre is uniform in the tile. The paper
samples the centres with a Poisson distribution of radius ~2 m; stratifying them
along the set normal is the same idea (no clumps) expressed per set, and it gives
the *evenly spaced* sets of the classification.

With ``a`` the structure axis (``axis``, default ``z``; columns' axis, bedding
normal) and ``(e1, e2, a)`` an orthonormal frame:

=================  ==============================================================
structure          fracture sets (paper section 4.1, Table 1)
=================  ==============================================================
equidimensional    three orthogonal sets along ``e1, e2, a`` (``s / spacing`` discs
                   each), radius ``disc_radius`` (x[0.8, 1.2]), jitter 3 deg, plus
                   10 % more irregular discs (random normals)
prismatic          as equidimensional, more irregular: radius x[0.5, 1.5], jitter
                   12 deg, 20 % more irregular discs
rhombohedral       three mutually oblique sets: ``e1, e2, a`` tilted towards the
                   frame diagonal by ``obliquity`` degrees (default 25), jitter 3 deg
polyhedral         ``3 s / spacing`` discs with uniformly random normals, radius
                   x[0.6, 1.2]
tabular            one dominant set normal to ``a`` (bedding) of radius ``s``, plus
                   two sets normal to ``e1``, ``e2`` of radius ``s / 10``, twice as
                   many (the paper's "less frequent, small radii" joints)
columnar           ``column_sets`` (default 3) continuous sets (radius ``s``) whose
                   normals are perpendicular to ``a`` at equal angles (+- 6 deg),
                   plus cross joints normal to ``a`` every ``4 spacing``
                   (radius ``s / 3``)
=================  ==============================================================

Defaults (``s = 20`` m): ``spacing`` 4 m (equidimensional, prismatic: 15 + 2 discs,
Table 1 has 15), 2.5 m (rhombohedral: 24), 1.4 m (polyhedral: 43), 2 m (tabular beds:
30 discs), 1.6 m (columnar); ``disc_radius = s / 4`` (the paper's 5 m).

Periodicity: the tile is replicated (section 5), so the fracture pattern is
periodic: a disc acts through all its images ``D_i + s k`` (``k`` in ``Z^3``).

Segment-disc test (section 4.1, "an edge ``p_j p_k`` is kept if it does not intersect
any fracture"): with ``d_a = (a - c) . n`` and ``d_b = (b - c) . n`` of opposite
signs, the segment meets the plane at ``x = a + d_a / (d_a - d_b) (b - a)``, and the
edge is cut when ``|x - c| < r``.

References
----------
Paris et al. (2020), section 4.1 and Table 1.
Palmstrom, A. (2001). Measurement and characterization of rock mass jointing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["STRUCTURES", "Discs", "fracture_discs", "disc_images", "cut_edges", "structure_frame"]

STRUCTURES = ("equidimensional", "rhombohedral", "polyhedral", "tabular", "columnar", "prismatic")

#: Default fracture spacing as a fraction of the tile edge (s = 20 m: 4, 2.5, 1.4, 2, 1.6, 4 m).
DEFAULT_SPACING = {"equidimensional": 0.2, "rhombohedral": 0.125, "polyhedral": 0.07,
                   "tabular": 0.1, "columnar": 0.08, "prismatic": 0.2}
#: Default radius scale of the non-persistent discs, times s.
DEFAULT_RADIUS = 0.35


@dataclass
class Discs:
    """Fracture discs: ``(M, 3)`` centres and unit normals, ``(M,)`` radii."""

    center: np.ndarray
    normal: np.ndarray
    radius: np.ndarray

    def __len__(self):
        return len(self.radius)


def structure_frame(axis) -> np.ndarray:
    """Orthonormal rows ``(e1, e2, a)`` with ``a = axis / |axis|``."""
    a = np.asarray(axis, dtype=np.float64).reshape(3)
    n = np.linalg.norm(a)
    if not n > 0:
        raise ValueError("structure axis must be a non-zero vector")
    a = a / n
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(helper, a)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(a, e1), a])


def _jitter(rng, normals, degrees):
    """Tilt each unit normal by a random angle of standard deviation ``degrees``."""
    if degrees <= 0:
        return normals
    v = normals + rng.normal(0.0, np.radians(degrees), normals.shape)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _random_normals(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def lattice_direction(v, reach: int = 3) -> np.ndarray:
    """The integer vector (components in ``[-reach, reach]``) closest in angle to ``v``."""
    g = np.arange(-reach, reach + 1)
    cand = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    cand = cand[np.any(cand != 0, axis=1)]
    cos = (cand @ v) / np.linalg.norm(cand, axis=1)
    best = cand[np.argmax(cos)]
    return best / np.gcd.reduce(np.abs(best[best != 0]))


def _persistent_set(rng, size, normal, spacing):
    """A continuous set: infinite planes, periodic with the tile.

    The images of a plane ``n . x = o`` by the tile lattice ``s Z^3`` are the planes
    ``o + s k . n``; they form an evenly spaced family only if ``n`` is a lattice
    direction ``v / |v|`` (``v`` integer, primitive), of period ``s / |v|``. So the
    normal is snapped to the nearest small integer direction and ``m`` planes are
    placed per period, ``m = round(s / (|v| spacing))``.
    """
    v = lattice_direction(np.asarray(normal, float) / np.linalg.norm(normal))
    period = size / np.linalg.norm(v)
    n = v / np.linalg.norm(v)
    m = max(int(round(period / spacing)), 1)
    offsets = (np.arange(m) + 0.5 + rng.uniform(-0.2, 0.2, m)) * period / m
    return np.outer(offsets, n), np.tile(n, (m, 1)), np.full(m, np.inf)


def _set(rng, size, normal, count, radius_lo, radius_hi, jitter_deg):
    """One evenly spaced set: stratified offsets along ``normal``, random in-plane."""
    count = max(int(count), 1)
    normal = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    u = rng.uniform(0.0, size, (count, 3))
    offsets = (np.arange(count) + 0.5 + rng.uniform(-0.25, 0.25, count)) * size / count
    centers = u - np.outer(u @ normal - offsets, normal)
    normals = _jitter(rng, np.tile(normal, (count, 1)), jitter_deg)
    radii = rng.uniform(radius_lo, radius_hi, count)
    return centers, normals, radii


def fracture_discs(structure: str, size: float, seed: int = 0, spacing: float | None = None,
                   disc_radius: float | None = None, axis=(0.0, 0.0, 1.0), obliquity: float = 25.0,
                   column_sets: int = 3) -> Discs:
    """Fracture discs of one structure type in the tile ``[0, size)^3``.

    Parameters
    ----------
    structure : str
        One of :data:`STRUCTURES`.
    size : float
        Tile edge ``s`` (metres).
    seed : int
        Random seed.
    spacing : float, optional
        Mean spacing of the discs of a set along its normal (metres); default
        :data:`DEFAULT_SPACING` times ``s``.
    disc_radius : float, optional
        Radius scale ``r_i`` of the non-persistent discs; default ``s / 4``.
    axis : array_like
        Structure axis ``a`` (column axis, bedding normal, third set's normal).
    obliquity : float
        Rhombohedral tilt of the three set normals towards the diagonal (degrees).
    column_sets : int
        Number of continuous sets around the column axis (columnar).

    Returns
    -------
    Discs

    References
    ----------
    Paris et al. (2020), section 4.1 (fracture distributions), Figure 5, Table 1.
    """
    if structure not in STRUCTURES:
        raise ValueError(f"structure must be one of {', '.join(STRUCTURES)} (got {structure!r})")
    s = float(size)
    w = float(spacing) if spacing else DEFAULT_SPACING[structure] * s
    if not 0 < w <= s:
        raise ValueError(f"spacing must be in (0, {s:g}] (got {w:g})")
    rho = float(disc_radius) if disc_radius else DEFAULT_RADIUS * s
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xB10C]))
    frame = structure_frame(axis)
    e1, e2, a = frame
    n_per_set = max(int(round(s / w)), 1)
    parts = []
    if structure in ("equidimensional", "prismatic"):
        lo, hi, jit, irregular = ((0.8, 1.2, 3.0, 0.1) if structure == "equidimensional"
                                  else (0.5, 1.5, 12.0, 0.2))
        n_irr = int(round(irregular * 3 * n_per_set))
        # "normals n_i are determined using a random axis-aligned direction": the
        # same number of discs per axis (an unbalanced draw flattens the blocks).
        for k in range(3):
            parts.append(_set(rng, s, frame[k], n_per_set, lo * rho, hi * rho, jit))
        if n_irr:
            c = rng.uniform(0, s, (n_irr, 3))
            parts.append((c, _random_normals(rng, n_irr), rng.uniform(lo * rho, hi * rho, n_irr)))
    elif structure == "rhombohedral":
        diag = (e1 + e2 + a) / np.sqrt(3.0)
        t = np.radians(float(obliquity))
        for k in range(3):
            # Rotate the axis towards the diagonal in the plane they span.
            v = frame[k] - (frame[k] @ diag) * diag
            v /= np.linalg.norm(v)
            ang = np.arccos(np.clip(frame[k] @ diag, -1, 1)) - t
            nk = np.cos(ang) * diag + np.sin(ang) * v
            parts.append(_set(rng, s, nk, n_per_set, 0.8 * rho, 1.2 * rho, 3.0))
    elif structure == "polyhedral":
        n = 3 * n_per_set
        parts.append((rng.uniform(0, s, (n, 3)), _random_normals(rng, n),
                      rng.uniform(0.6 * rho, 1.2 * rho, n)))
    elif structure == "tabular":
        parts.append(_persistent_set(rng, s, a, w))
        for e in (e1, e2):
            parts.append(_set(rng, s, e, n_per_set, 0.1 * s, 0.1 * s, 4.0))
    elif structure == "columnar":
        m = max(int(column_sets), 2)
        phase = rng.uniform(0, np.pi)
        for k in range(m):
            ang = phase + np.pi * k / m + np.radians(rng.uniform(-6, 6))
            parts.append(_persistent_set(rng, s, np.cos(ang) * e1 + np.sin(ang) * e2, w))
        parts.append(_set(rng, s, a, max(int(round(s / (4 * w))), 1), s / 3, s / 3, 4.0))
    center = np.concatenate([p[0] for p in parts])
    normal = np.concatenate([p[1] for p in parts])
    radius = np.concatenate([p[2] for p in parts])
    return Discs(center, normal, radius)


def disc_images(discs: Discs, size: float, lo, hi) -> Discs:
    """Periodic images ``D_i + s k`` of the discs whose box meets ``[lo, hi]``.

    The half-extent of a disc along axis ``x_a`` is ``r sqrt(1 - n_a^2)``.
    """
    s = float(size)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    inf = ~np.isfinite(discs.radius)
    planes = _plane_images(Discs(discs.center[inf], discs.normal[inf], discs.radius[inf]), s, lo, hi)
    discs = Discs(discs.center[~inf], discs.normal[~inf], discs.radius[~inf])
    half = discs.radius[:, None] * np.sqrt(np.clip(1.0 - discs.normal ** 2, 0.0, 1.0))
    if len(discs) == 0:
        return planes
    k_lo = np.floor((lo - discs.center - half) / s).astype(int)
    k_hi = np.ceil((hi - discs.center + half) / s).astype(int)
    cs, ns, rs = [], [], []
    for i in range(len(discs)):
        ks = np.stack(np.meshgrid(*[np.arange(k_lo[i, a], k_hi[i, a] + 1) for a in range(3)],
                                  indexing="ij"), -1).reshape(-1, 3)
        c = discs.center[i] + s * ks
        keep = np.all((c + half[i] >= lo) & (c - half[i] <= hi), axis=1)
        cs.append(c[keep])
        ns.append(np.repeat(discs.normal[i][None], keep.sum(), 0))
        rs.append(np.full(keep.sum(), discs.radius[i]))
    return Discs(np.concatenate(cs + [planes.center]), np.concatenate(ns + [planes.normal]),
                 np.concatenate(rs + [planes.radius]))


def _plane_images(planes: Discs, s, lo, hi) -> Discs:
    """Distinct images of infinite planes (lattice normals) that cross ``[lo, hi]``."""
    cs, ns = [np.empty((0, 3))], [np.empty((0, 3))]
    corners = np.stack(np.meshgrid(*zip(lo, hi), indexing="ij"), -1).reshape(-1, 3)
    for c, n in zip(planes.center, planes.normal):
        o = c @ n
        # |v| of the primitive integer direction v = |v| n (|v|^2 is an integer).
        v_len = next(np.sqrt(q) for q in range(1, 28)
                     if np.allclose(n * np.sqrt(q), np.round(n * np.sqrt(q)), atol=1e-6))
        period = s / v_len
        proj = corners @ n
        ks = np.arange(np.floor((proj.min() - o) / period), np.ceil((proj.max() - o) / period) + 1)
        cs.append(np.outer(o + ks * period, n))
        ns.append(np.tile(n, (len(ks), 1)))
    c, n = np.concatenate(cs), np.concatenate(ns)
    return Discs(c, n, np.full(len(c), np.inf))


@numba.njit(cache=True, parallel=False)
def _cut(a, b, center, normal, radius):
    n_e, n_d = len(a), len(radius)
    out = np.zeros(n_e, dtype=np.bool_)
    for e in range(n_e):
        for d in range(n_d):
            da = 0.0
            db = 0.0
            for k in range(3):
                da += (a[e, k] - center[d, k]) * normal[d, k]
                db += (b[e, k] - center[d, k]) * normal[d, k]
            if (da > 0.0 and db > 0.0) or (da < 0.0 and db < 0.0) or da == db:
                continue
            t = da / (da - db)
            r2 = 0.0
            for k in range(3):
                x = a[e, k] + t * (b[e, k] - a[e, k]) - center[d, k]
                r2 += x * x
            if r2 < radius[d] * radius[d]:
                out[e] = True
                break
    return out


def cut_edges(a: np.ndarray, b: np.ndarray, discs: Discs) -> np.ndarray:
    """Which segments ``[a_e, b_e]`` cross a disc (``(E,)`` bool).

    Parameters
    ----------
    a, b : numpy.ndarray
        ``(E, 3)`` segment end points.
    discs : Discs
        The discs (already expanded to the periodic images that matter).

    References
    ----------
    Paris et al. (2020), section 4.1: ``D_i cap p_j p_k = empty`` keeps the edge.
    """
    if len(discs) == 0 or len(a) == 0:
        return np.zeros(len(a), dtype=bool)
    return _cut(np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64),
                np.ascontiguousarray(discs.center, np.float64),
                np.ascontiguousarray(discs.normal, np.float64),
                np.ascontiguousarray(discs.radius, np.float64))
