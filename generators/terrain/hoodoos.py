"""Hoodoos and goblins from an open, parameterised shape grammar (Paris et al. 2019, 6.3).

Placement. Hoodoos grow on talus and cliffs: medium slope, small drainage area.
The growth probability at a cell is

    P = mask * exp(-((s - s_mid) / s_width)^2) * exp(-A / A_ref),

(``s`` slope, ``A`` drainage area by Freeman's MFD, ``s_mid``, ``s_width``,
``A_ref`` parameters); Poisson-disc samples of the terrain are kept with
probability ``P`` and become the axioms ``A(p, s0)`` of the grammar.

Grammar (Fig. 20), with ``g(p)`` the geology: ``rho(p)`` of the resistance tree
at the symbol's position, ``z`` the (slightly tilted) growth axis and ``lambda``
the size ratio between stacked symbols::

    A(p, s) -> B(p, s)                                   1
    B(p, s) -> b(p, s) B(p + s z, lambda s)              p_B(rho)
    B(p, s) -> b(p, s) C(p + s z, lambda s)              1 - p_B(rho)
    C(p, s) -> c(p, s) B(p + s z, lambda s)              p_C(rho) / 2
    C(p, s) -> c(p, s)                                   p_C(rho) / 2
    C(p, s) -> d(p, s)                                   1 - p_C(rho)

Terminals: ``b`` a block (a rounded column segment of height ``s``), ``c`` a cone
(tapering column made of ``cone_steps`` stacked segments), ``d`` a box, the
flat cap rock (approximated by three crossed flat bars, since skeletal sets are
isotropic around their skeletons). The geology drives the probabilities and the
sizes: hard rock (high ``rho``) keeps stacking blocks (``p_B = 0.25 + 0.6 rho``)
and caps the column (``1 - p_C = rho``); widths scale with ``0.55 + 0.7 rho``, so
soft strata carve necks and hard ones bulge. Each symbol's axis is tilted by a
small random rotation (variety, as in the paper). Derivations stop at
``max_depth`` symbols with a cap. Everything is drawn from one seeded generator.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), section 6.3, Fig. 18-20.
Měch, R., Prusinkiewicz, P. (1996). Visual models of plants interacting with
their environment. SIGGRAPH '96 (open L-systems).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .hydrology import flow_accumulation, slope
from .shallow_erosion import sample_mask

__all__ = ["HoodooSymbols", "hoodoo_probability", "derive_hoodoos", "hoodoo_field"]

BLOCK, CONE, CAP = 0, 1, 2


@dataclass
class HoodooSymbols:
    """Terminal symbols as skeletal primitives (arrays of equal length).

    Attributes
    ----------
    a, b : numpy.ndarray
        ``(N, 3)`` segment ends.
    width : numpy.ndarray
        ``(N,)`` radius of the solid around the segment, metres.
    symbol : numpy.ndarray
        ``(N,)`` ``BLOCK`` (0), ``CONE`` (1) or ``CAP`` (2).
    hoodoo : numpy.ndarray
        ``(N,)`` index of the hoodoo (axiom) the symbol belongs to.
    """

    a: np.ndarray
    b: np.ndarray
    width: np.ndarray
    symbol: np.ndarray
    hoodoo: np.ndarray

    def __len__(self):
        return len(self.width)


def hoodoo_probability(heights, extent, s_mid=0.6, s_width=0.35, area_ref=None, mask=None):
    """Growth probability ``P`` of hoodoos per cell (see module docstring).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations over ``extent``.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)``.
    s_mid, s_width : float
        Preferred slope (rise over run) and its tolerance.
    area_ref : float, optional
        Drainage area scale ``A_ref`` (m^2); default 20 cells.
    mask : numpy.ndarray, optional
        User mask in ``[0, 1]``.

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` probabilities.
    """
    H = np.asarray(heights, dtype=np.float64)
    ny, nx = H.shape
    x0, y0, x1, y1 = extent
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    A = flow_accumulation(H, (dx, dy))
    s = slope(H, (dx, dy))
    ref = 20.0 * dx * dy if area_ref is None else float(area_ref)
    P = np.exp(-np.square((s - s_mid) / s_width)) * np.exp(-A / ref)
    return P if mask is None else P * np.clip(mask, 0.0, 1.0)


def _tilts(rng, n, max_angle):
    """``n`` unit axes within ``max_angle`` radians of +z."""
    t = rng.uniform(0.0, max_angle, n)
    phi = rng.uniform(0.0, 2 * np.pi, n)
    return np.stack([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.cos(t)], axis=1)


def _caps(rows, kd, p, s, w, axis, rng):
    """Emit the cap rock ``d(p, s)``: three crossed flat bars of thickness ``0.3 s``, length ``3 w``."""
    if len(kd) == 0:
        return
    t = 0.3 * s
    c = p + 0.5 * t[:, None] * axis
    ang0 = rng.uniform(0, np.pi / 3, len(kd))
    for k in range(3):
        ang = ang0 + k * np.pi / 3
        d = np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], 1) * (1.5 * w)[:, None]
        rows.append((c - d, c + d, 0.5 * t, np.full(len(kd), CAP), kd))


def derive_hoodoos(feet, s0, width0, resistance, rng, lam=0.85, max_depth=8, tilt_deg=6.0, cone_steps=3):
    """Derive hoodoos from the axioms ``A(p_k, s0)``, all columns one symbol at a time.

    The derivations are independent; advancing them together lets each level
    query the geology once for all columns (one batched evaluation).

    Parameters
    ----------
    feet : array_like
        ``(K, 3)`` feet of the hoodoos.
    s0 : float
        Height of the first symbol, metres.
    width0 : float
        Radius of a block of resistance 1 at size ``s0``, metres.
    resistance : callable
        ``rho(points (N, 3)) -> (N,)``.
    rng : numpy.random.Generator
        Choices among the rules, tilts.
    lam : float
        ``lambda``, size ratio of consecutive symbols.
    max_depth : int
        Largest number of symbols before a cap closes the column.
    tilt_deg : float
        Largest tilt of a symbol's axis, degrees.
    cone_steps : int
        Segments of a cone terminal.

    Returns
    -------
    HoodooSymbols
    """
    p = np.array(feet, dtype=np.float64).reshape(-1, 3)
    K = len(p)
    s = np.full(K, float(s0))
    state = np.zeros(K, dtype=np.int64)  # 0: B, 1: C, -1: done
    rows = []  # (a, b, width, symbol, hoodoo) arrays per emission
    tilt = np.radians(tilt_deg)
    for depth in range(max_depth):
        live = np.flatnonzero(state >= 0)
        if len(live) == 0:
            break
        rho = np.clip(np.asarray(resistance(p[live]), dtype=np.float64), 0.0, 1.0)
        w = width0 * (s[live] / s0) * (0.55 + 0.7 * rho)
        axis = _tilts(rng, len(live), tilt)
        top = p[live] + s[live, None] * axis
        u = rng.random(len(live))
        isB = state[live] == 0
        # B -> b B | b C
        kB = live[isB]
        rows.append((p[kB], top[isB], w[isB], np.full(len(kB), BLOCK), kB))
        state[kB] = np.where(u[isB] >= 0.25 + 0.6 * rho[isB], 1, 0)
        # C -> d (cap) | c B | c
        isC = ~isB
        p_c = 1.0 - rho
        cap = isC & (u >= p_c)
        cone = isC & ~cap
        kd = live[cap]
        _caps(rows, kd, p[kd], s[kd], w[cap], axis[cap], rng)
        state[kd] = -1
        kc = live[cone]
        for k in range(cone_steps):
            a = p[kc] + (s[kc] * k / cone_steps)[:, None] * axis[cone]
            b = p[kc] + (s[kc] * (k + 1) / cone_steps)[:, None] * axis[cone]
            rows.append((a, b, w[cone] * (1.0 - 0.6 * (k + 0.5) / cone_steps), np.full(len(kc), CONE), kc))
        state[kc] = np.where(u[cone] < 0.5 * p_c[cone], 0, -1)
        p[live] = top
        s[live] *= lam
    # Columns still growing at max_depth are closed by a cap (C -> d).
    kd = np.flatnonzero(state >= 0)
    if len(kd):
        rho = np.clip(np.asarray(resistance(p[kd]), dtype=np.float64), 0.0, 1.0)
        _caps(rows, kd, p[kd], s[kd], width0 * (s[kd] / s0) * (0.55 + 0.7 * rho), _tilts(rng, len(kd), tilt), rng)
    if not rows:
        z = np.zeros((0, 3))
        return HoodooSymbols(z, z.copy(), np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64))
    a, b, w, sym, hid = (np.concatenate(x) for x in zip(*rows))
    order = np.argsort(hid, kind="stable")  # symbols of one hoodoo together, in growth order
    return HoodooSymbols(a[order], b[order], w[order], sym[order].astype(np.int64), hid[order].astype(np.int64))


def hoodoo_field(heights, extent, height_at, resistance, spacing, s0, width0, probability=None,
                 seed=0, max_hoodoos=5000, min_hoodoos=3, **grammar):
    """Place and derive hoodoos over a heightfield.

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations over ``extent``.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)``.
    height_at : callable
        ``h(x, y)`` of the terrain surface (numpy).
    resistance : callable
        ``rho(points (N, 3)) -> (N,)``.
    spacing : float
        Poisson-disc distance between hoodoos, metres.
    s0, width0 : float
        Axiom size and block radius (see :func:`derive_hoodoos`).
    probability : numpy.ndarray, optional
        ``P`` per cell; default :func:`hoodoo_probability`.
    seed : int
        Seed of the placement and of the grammar.
    max_hoodoos : int
        Budget.
    min_hoodoos : int
        When fewer samples pass the probability test, the most probable ones grow.
    **grammar
        Passed to :func:`derive_hoodoos`.

    Returns
    -------
    HoodooSymbols
    """
    rng = np.random.default_rng(seed)
    P = hoodoo_probability(heights, extent) if probability is None else probability
    xy = sample_mask(np.ones_like(P), extent, spacing, rng)
    if len(xy):
        ny, nx = P.shape
        x0, y0, x1, y1 = extent
        i = np.clip(np.rint((xy[:, 0] - x0) / (x1 - x0) * (nx - 1)).astype(int), 0, nx - 1)
        j = np.clip(np.rint((xy[:, 1] - y0) / (y1 - y0) * (ny - 1)).astype(int), 0, ny - 1)
        p = P[j, i]
        accept = rng.random(len(xy)) < p
        if accept.sum() < min_hoodoos:  # a poor site still shows its best few places
            accept[np.argsort(-p, kind="stable")[:min_hoodoos]] = True
        xy = xy[accept][:max_hoodoos]
    feet = np.column_stack([xy, height_at(xy[:, 0], xy[:, 1]) - 0.25 * s0]) if len(xy) else np.zeros((0, 3))
    return derive_hoodoos(feet, s0, width0, resistance, rng, **grammar)
