"""Landscape evolution: uplift, stream-power incision, thermal erosion and creep on a DEM.

Used to make synthetic DEMs that look eroded (valleys, ridges, escarpments, benches)
instead of smoothstep blocks: the amplification processes of Paris et al. (2019)
analyse drainage and slopes, which only read right on a surface shaped by water.

Governing equation (detachment-limited stream power law with hillslope terms)::

    dh/dt = U - K A^m S^n + D lap(h) + thermal(h)

``h`` elevation (m), ``U`` rock uplift relative to base level (m/yr), ``A`` upstream
drainage area (m^2), ``S`` slope towards the receiver, ``K`` erodibility
(m^(1-2m)/yr), ``m`` the area exponent (0.4-0.6 in nature; 0.5 here), ``n = 1``.

Flow routing (Barnes et al. 2014, priority-flood with receivers)
    Cells are flooded from the *outlets* (a mask: the base level, e.g. one tile
    edge for a coast or a river mouth) in order of increasing spill elevation. The
    order in which cells leave the queue is a topological order (every cell comes
    after its receiver), and a cell inside a depression gets as receiver the cell
    that flooded it, so water crosses pits and flats towards their spill point.
    Outside depressions the receiver is the steepest-descent neighbour (D8,
    O'Callaghan & Mark 1984). Edges that are not outlets are closed (no flow leaves
    there): :func:`hydrology.fill_depressions` drains through *every* border cell,
    which would pin all four edges at base level, hence this routing of our own
    (it reuses hydrology's deterministic heap).

Stream power, implicit (Braun & Willett 2013)
    With ``n = 1`` the implicit Euler step along each receiver link is linear::

        h_i' = (h_i + U dt + F h_r') / (1 + F),   F = K A_i^m dt / d_ir,

    solved in the flooding order (the receiver's new height ``h_r'`` is known).
    The step is unconditionally stable (no CFL limit on ``dt``) and exact at steady
    state: ``K A^m S = U``, i.e. ``S = (U / K) A^-m``, the slope-area law of real
    river profiles. A cell left below its receiver (in a depression) is filled to
    the receiver's height: sediment fills lakes to their spill level (flat floors).
    Below ``sea_level`` there is no fluvial incision.

Layered rock
    ``K`` and the talus angle depend on the rock at each cell: horizontal strata in
    the rock's own frame (``z - cumulative uplift``, so layers rise with the rock).
    Hard caprock erodes slowly and stands steep; soft layers erode fast and slope
    gently: differential erosion makes the benches, escarpments and mesas of the
    Colorado Plateau.

Thermal erosion (Musgrave et al. 1989)
    Where the drop to a lower 8-neighbour exceeds ``d tan(theta)`` (``d`` the
    centre distance, ``theta`` the talus angle of the rock), a fraction ``c`` of
    the largest excess moves down, shared in proportion to each neighbour's excess.
    Updated synchronously (fluxes from the old heights) so that it is symmetric and
    order-free; mass is conserved. A cell may receive from all 8 neighbours at once,
    so ``c <= 1/8`` is needed to never overshoot (larger ``c`` turns cliffs into a
    checkerboard of alternating cells).

Creep (linear diffusion)
    ``D lap(h)`` by explicit 5-point differences in sub-steps of at most
    ``dx^2 / (8 D)``: half the explicit scheme's stability bound ``dx^2 / (4 D)``, so
    that the grid-scale (checkerboard) mode is damped (amplification ``1 - 8 D dt /
    dx^2 >= 0``) instead of flipping sign undamped at the bound. Zero-flux closed
    edges, fixed outlets.

References
----------
Braun, J., Willett, S. D. (2013). A very efficient O(n), implicit and parallel method
to solve the stream power equation governing fluvial incision and landscape
evolution. Geomorphology 180-181, 170-179.
Barnes, R., Lehman, C., Mulla, D. (2014). Priority-flood. Computers & Geosciences 62.
Musgrave, F. K., Kolb, C. E., Mace, R. S. (1989). The synthesis and rendering of
eroded fractal terrains. SIGGRAPH '89 (thermal weathering).
Sunamura, T. (1992). Geomorphology of Rocky Coasts. Wiley.
Howard, A. D. (1994). A detachment-limited model of drainage basin evolution.
Water Resources Research 30(7), 2261-2285.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from .hydrology import NEIGHBOUR_DI, NEIGHBOUR_DJ, heap_pop, heap_push

__all__ = ["Strata", "edge_outlets", "route_flow", "stream_power_step", "thermal_erosion", "diffuse", "evolve"]


@dataclass(frozen=True)
class Strata:
    """Horizontal hard and soft layers, in the rock's frame.

    Attributes
    ----------
    bases : numpy.ndarray
        Increasing rock-frame elevations (m) where each layer starts; layer ``k``
        spans ``[bases[k], bases[k + 1])``. Below ``bases[0]`` the first layer
        continues, above the last base the last one.
    hard : numpy.ndarray
        ``bool`` per layer.
    hard_k_factor : float
        Erodibility of hard rock relative to soft rock (``< 1``).
    hard_talus_deg : float
        Talus angle of hard rock, degrees (soft rock uses ``evolve``'s ``talus_deg``).
    """

    bases: np.ndarray
    hard: np.ndarray
    hard_k_factor: float = 0.1
    hard_talus_deg: float = 70.0

    @classmethod
    def alternating(cls, bottom, top, period, hard_fraction=0.35, jitter=0.4, seed=0, **kw):
        """Soft/hard pairs from ``bottom`` up to ``top``, hard rock on top of each pair.

        Parameters
        ----------
        bottom, top : float
            Rock-frame elevations (m) of the first base and of the end of the stack.
        period : float
            Mean thickness of a pair (m).
        hard_fraction : float
            Mean share of a pair that is hard.
        jitter : float
            Relative spread of each pair's thickness and hard share (uniform, seeded),
            so that beds are not evenly spaced.
        seed : int
            Seed of the spread.
        **kw
            ``hard_k_factor``, ``hard_talus_deg``.

        Returns
        -------
        Strata
        """
        rng = np.random.default_rng(seed)
        bases, hard, z = [], [], float(bottom)
        while z < top:
            p = period * (1.0 + jitter * rng.uniform(-1.0, 1.0))
            f = float(np.clip(hard_fraction * (1.0 + jitter * rng.uniform(-1.0, 1.0)), 0.05, 0.95))
            bases += [z, z + (1.0 - f) * p]
            hard += [False, True]
            z += p
        return cls(np.asarray(bases), np.asarray(hard), **kw)

    def is_hard(self, z_rock):
        """Boolean mask of hard rock at rock-frame elevations ``z_rock`` (metres)."""
        k = np.clip(np.searchsorted(self.bases, np.asarray(z_rock), side="right") - 1, 0, len(self.hard) - 1)
        return self.hard[k]


def edge_outlets(shape, edges="nsew"):
    """Outlet mask made of whole tile edges.

    Parameters
    ----------
    shape : tuple
        ``(ny, nx)``.
    edges : str
        Any of ``"s"`` (row 0), ``"n"`` (last row), ``"w"`` (column 0), ``"e"`` (last column).

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` bool, ``True`` at base-level cells.
    """
    m = np.zeros(shape, dtype=bool)
    if "s" in edges:
        m[0, :] = True
    if "n" in edges:
        m[-1, :] = True
    if "w" in edges:
        m[:, 0] = True
    if "e" in edges:
        m[:, -1] = True
    return m


@numba.njit(cache=True)
def _route(Z, outlet, dx, dy, di, dj):
    ny, nx = Z.shape
    N = ny * nx
    key = np.empty(N, dtype=np.float64)  # spill (filled) elevation
    rec = np.full(N, -1, dtype=np.int64)
    order = np.empty(N, dtype=np.int64)
    seen = np.zeros(N, dtype=np.bool_)
    keys = np.empty(N, dtype=np.float64)
    vals = np.empty(N, dtype=np.int64)
    dist = np.empty(8)
    for k in range(8):
        dist[k] = math.sqrt((dj[k] * dx) ** 2 + (di[k] * dy) ** 2)
    n = 0
    for c in range(N):
        if outlet.flat[c]:
            key[c] = Z.flat[c]
            seen[c] = True
            n = heap_push(keys, vals, n, key[c], c)
    count = 0
    while n > 0:
        kc, c, n = heap_pop(keys, vals, n)
        order[count] = c
        count += 1
        cj, ci = c // nx, c % nx
        for k in range(8):
            j, i = cj + di[k], ci + dj[k]
            if j < 0 or i < 0 or j >= ny or i >= nx:
                continue
            q = j * nx + i
            if seen[q]:
                continue
            seen[q] = True
            rec[q] = c  # the flooding cell: the way out of a pit or across a flat
            key[q] = max(Z[j, i], kc)
            n = heap_push(keys, vals, n, key[q], q)
    # Steepest descent on the filled surface where a strictly lower neighbour exists:
    # such a neighbour left the queue earlier (keys leave in non-decreasing order), so
    # the order stays topological.
    rdist = np.zeros(N)
    for t in range(count):
        c = order[t]
        if rec[c] < 0:
            continue
        cj, ci = c // nx, c % nx
        best, bk = 0.0, -1
        for k in range(8):
            j, i = cj + di[k], ci + dj[k]
            if j < 0 or i < 0 or j >= ny or i >= nx:
                continue
            s = (key[c] - key[j * nx + i]) / dist[k]
            if s > best:
                best, bk = s, k
        if bk >= 0:
            rec[c] = (cj + di[bk]) * nx + ci + dj[bk]
            rdist[c] = dist[bk]
        else:
            r = rec[c]
            rdist[c] = math.sqrt((((r % nx) - ci) * dx) ** 2 + (((r // nx) - cj) * dy) ** 2)
    return rec, order[:count], rdist, key.reshape(ny, nx)


def route_flow(heights, cell_size, outlets, inflow=None):
    """Receivers, topological order and drainage area of a DEM (single flow direction).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations in metres.
    cell_size : float
        Metres between samples (square cells).
    outlets : array_like
        ``(ny, nx)`` bool base-level mask (at least one ``True``).
    inflow : array_like, optional
        ``(ny, nx)`` extra upstream area entering at each cell (m^2): a river that
        enters the tile from a catchment outside it.

    Returns
    -------
    dict
        ``receiver`` (flat indices, ``-1`` at outlets), ``order`` (outlets first,
        every cell after its receiver), ``distance`` (m to the receiver), ``area``
        (``(ny, nx)`` m^2, own cell included) and ``filled`` (spill elevations).
    """
    Z = np.ascontiguousarray(heights, dtype=np.float64)
    out = np.ascontiguousarray(outlets, dtype=np.bool_)
    if Z.ndim != 2 or Z.shape != out.shape:
        raise ValueError("route_flow needs 2-D heights and an outlet mask of the same shape")
    if not out.any():
        raise ValueError("route_flow needs at least one outlet cell")
    c = float(cell_size)
    rec, order, dist, filled = _route(Z, out, c, c, NEIGHBOUR_DI, NEIGHBOUR_DJ)
    a0 = np.full(Z.size, c * c)
    if inflow is not None:
        a0 = a0 + np.asarray(inflow, dtype=np.float64).ravel()
    area = _accumulate(rec, order, a0)
    return dict(receiver=rec, order=order, distance=dist, area=area.reshape(Z.shape), filled=filled)


@numba.njit(cache=True)
def _accumulate(rec, order, a0):
    A = a0.copy()
    for t in range(len(order) - 1, -1, -1):
        c = order[t]
        r = rec[c]
        if r >= 0:
            A[r] += A[c]
    return A


@numba.njit(cache=True)
def _implicit_sp(h, rec, order, dist, A, K, U, m, dt, sea_level, marine):
    out = h.copy()
    for t in range(len(order)):
        c = order[t]
        r = rec[c]
        if r < 0:
            continue  # base level: fixed
        raised = h[c] + U[c] * dt
        if marine and h[c] < sea_level:
            out[c] = raised  # no rivers under the sea
            continue
        F = K[c] * A[c] ** m * dt / dist[c]
        v = (raised + F * out[r]) / (1.0 + F)
        if raised <= out[r]:
            v = out[r]  # in a depression: filled to the spill level
        out[c] = v
    return out


def stream_power_step(heights, cell_size, dt, uplift, K, outlets, m=0.5, inflow=None, sea_level=None):
    """One implicit step of uplift and stream-power incision (Braun & Willett 2013, ``n = 1``).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations (m).
    cell_size : float
        Cell size (m).
    dt : float
        Time step (years); any size (the scheme is unconditionally stable).
    uplift, K : float or array_like
        Uplift rate (m/yr) and erodibility (m^(1-2m)/yr), scalars or ``(ny, nx)``.
    outlets : array_like
        Base-level mask (fixed heights).
    m : float
        Drainage-area exponent.
    inflow : array_like, optional
        Extra upstream area per cell (m^2), see :func:`route_flow`.
    sea_level : float, optional
        No incision below this level.

    Returns
    -------
    (numpy.ndarray, dict)
        New heights and the routing of the old ones (:func:`route_flow`).
    """
    H = np.ascontiguousarray(heights, dtype=np.float64)
    flow = route_flow(H, cell_size, outlets, inflow)
    U = np.broadcast_to(np.asarray(uplift, dtype=np.float64), H.shape).ravel().copy()
    Kc = np.broadcast_to(np.asarray(K, dtype=np.float64), H.shape).ravel().copy()
    new = _implicit_sp(H.ravel(), flow["receiver"], flow["order"], flow["distance"], flow["area"].ravel(),
                       Kc, U, float(m), float(dt), 0.0 if sea_level is None else float(sea_level),
                       sea_level is not None)
    return new.reshape(H.shape), flow


@numba.njit(cache=True)
def _thermal(h, tan_talus, fixed, dx, rate, iters, di, dj):
    ny, nx = h.shape
    dist = np.empty(8)
    for k in range(8):
        dist[k] = math.sqrt((dj[k] * dx) ** 2 + (di[k] * dx) ** 2)
    cur = h.copy()
    delta = np.zeros((ny, nx))
    ex = np.empty(8)
    for _ in range(iters):
        delta[:] = 0.0
        for cj in range(ny):
            for ci in range(nx):
                if fixed[cj, ci]:
                    continue
                z = cur[cj, ci]
                tot, mx = 0.0, 0.0
                for k in range(8):
                    ex[k] = 0.0
                    j, i = cj + di[k], ci + dj[k]
                    if j < 0 or i < 0 or j >= ny or i >= nx:
                        continue
                    e = z - cur[j, i] - dist[k] * tan_talus[cj, ci]
                    if e > 0:
                        ex[k] = e
                        tot += e
                        if e > mx:
                            mx = e
                if tot <= 0:
                    continue
                move = rate * 0.5 * mx  # half the excess would level the pair
                delta[cj, ci] -= move
                for k in range(8):
                    if ex[k] > 0 and not fixed[cj + di[k], ci + dj[k]]:
                        delta[cj + di[k], ci + dj[k]] += move * ex[k] / tot  # into an outlet: leaves
        cur += delta
    return cur


def thermal_erosion(heights, cell_size, talus_deg, rate=0.125, iterations=1, fixed=None):
    """Thermal erosion (talus creep) towards a critical angle (Musgrave et al. 1989).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations (m).
    cell_size : float
        Cell size (m).
    talus_deg : float or array_like
        Critical angle (degrees) of the rock at each cell.
    rate : float
        Share ``c`` of the largest excess moved per iteration, in ``(0, 1/8]`` (the
        range that never overshoots).
    iterations : int
        Number of synchronous sweeps.
    fixed : array_like, optional
        Base-level cells: held at their height; material moving into them leaves
        the tile.

    Returns
    -------
    numpy.ndarray
        New heights; ``sum`` is conserved when no cell is fixed.
    """
    H = np.ascontiguousarray(heights, dtype=np.float64)
    t = np.broadcast_to(np.tan(np.radians(np.asarray(talus_deg, dtype=np.float64))), H.shape).copy()
    f = np.zeros(H.shape, dtype=np.bool_) if fixed is None else np.ascontiguousarray(fixed, dtype=np.bool_)
    return _thermal(H, t, f, float(cell_size), float(rate), int(iterations), NEIGHBOUR_DI, NEIGHBOUR_DJ)


def diffuse(heights, cell_size, D, dt, fixed=None):
    """Linear hillslope diffusion ``dh/dt = D lap(h)``, explicit with CFL sub-steps.

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations (m).
    cell_size : float
        Cell size (m).
    D : float
        Diffusivity (m^2/yr).
    dt : float
        Duration (years), split into sub-steps of at most ``dx^2 / (8 D)``.
    fixed : array_like, optional
        Cells held at their height (outlets).

    Returns
    -------
    numpy.ndarray
        New heights (zero-flux edges).
    """
    H = np.array(heights, dtype=np.float64)
    if D <= 0 or dt <= 0:
        return H
    dx2 = float(cell_size) ** 2
    k = int(math.ceil(dt * D * 8.0 / dx2))
    h = dt / k
    keep = None if fixed is None else np.asarray(fixed, dtype=bool)
    for _ in range(k):
        P = np.pad(H, 1, mode="edge")  # mirror edge: no flux through closed edges
        lap = P[2:, 1:-1] + P[:-2, 1:-1] + P[1:-1, 2:] + P[1:-1, :-2] - 4.0 * H
        new = H + D * h / dx2 * lap
        if keep is not None:
            new[keep] = H[keep]
        H = new
    return H


def evolve(heights, cell_size, steps, dt, uplift, K, outlets, m=0.5, inflow=None, talus_deg=35.0,
           strata=None, thermal_rate=0.125, thermal_iterations=4, diffusivity=0.0, sea_level=None,
           wave_rate=0.0, progress=None):
    """Run uplift, stream power, thermal erosion and creep for ``steps`` steps.

    Each step: implicit stream power with uplift (:func:`stream_power_step`), then
    wave cut (with ``sea_level`` and ``wave_rate``), thermal erosion with the talus
    angle of the rock at each cell, then creep. With
    ``strata`` the erodibility and talus angle follow the layer at each cell's
    rock-frame elevation ``h - U t``.

    Parameters
    ----------
    heights : array_like
        Initial ``(ny, nx)`` elevations (m).
    cell_size : float
        Cell size (m).
    steps : int
        Number of steps.
    dt : float
        Step (years).
    uplift : float or array_like
        Uplift rate relative to base level (m/yr).
    K : float or array_like
        Erodibility of soft rock (m^(1-2m)/yr).
    outlets : array_like
        Base-level mask (see :func:`edge_outlets`).
    m : float
        Area exponent.
    inflow : array_like, optional
        Upstream area entering the tile per cell (m^2).
    talus_deg : float
        Talus angle of soft rock (degrees).
    strata : Strata, optional
        Hard layers.
    thermal_rate : float
        Thermal erosion share per sweep (see :func:`thermal_erosion`).
    thermal_iterations : int
        Sweeps per step.
    diffusivity : float
        Creep diffusivity (m^2/yr); 0 for none.
    sea_level : float, optional
        No fluvial incision below it.
    wave_rate : float
        Shore erosion (m/yr): land cells next to the sea are lowered at this rate
        down to 1 m below ``sea_level`` (a wave-cut notch; the debris goes offshore),
        and thermal erosion then makes the cliff above retreat. The simplest form of
        wave-driven cliff retreat (Sunamura 1992): rate independent of rock and fetch.
    progress : callable, optional
        ``progress(done, total)`` after each step.

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` float64 final elevations.
    """
    H = np.array(heights, dtype=np.float64)
    out = np.asarray(outlets, dtype=bool)
    U = np.broadcast_to(np.asarray(uplift, dtype=np.float64), H.shape)
    K0 = np.broadcast_to(np.asarray(K, dtype=np.float64), H.shape)
    lifted = np.zeros(H.shape)  # cumulative uplift: maps heights to the rock's frame
    for s in range(int(steps)):
        if strata is not None:
            hard = strata.is_hard(H - lifted)
            Kc = np.where(hard, K0 * strata.hard_k_factor, K0)
            talus = np.where(hard, strata.hard_talus_deg, talus_deg)
        else:
            Kc, talus = K0, talus_deg
        H, _ = stream_power_step(H, cell_size, dt, U, Kc, out, m, inflow, sea_level)
        lifted += U * dt
        if wave_rate > 0 and sea_level is not None:
            H = _wave_cut(H, float(sea_level), wave_rate * dt, out)
        if thermal_iterations > 0:
            H = thermal_erosion(H, cell_size, talus, thermal_rate, thermal_iterations, out)
        if diffusivity > 0:
            H = diffuse(H, cell_size, diffusivity, dt, out)
        if progress:
            progress(s + 1, int(steps))
    return H


def _wave_cut(H, sea_level, depth, fixed):
    """Lower land cells 8-adjacent to the sea by ``depth`` (not below ``sea_level - 1``)."""
    from scipy.ndimage import binary_dilation
    sea = H < sea_level
    shore = binary_dilation(sea, np.ones((3, 3), bool)) & ~sea & ~fixed
    out = H.copy()
    out[shore] = np.maximum(H[shore] - depth, np.minimum(H[shore], sea_level - 1.0))
    return out
