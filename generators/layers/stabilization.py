"""Stabilization of granular layers by their angle of repose (Peytavie et al. 2009, 3.4).

Bedrock (and the other stable materials: sandstone, water) never moves. Between two
stable layers of a stack (a *section*), the granular layers are first merged by
kind and sorted sand, rocks, air (figure 6): material hanging in a section falls to
its floor. Then granular material flows from a stack to its eight neighbours until
every slope is at most the material's angle of repose ``alpha`` (sand 30-35 degrees,
rocks 40-45; defaults 33 and 42).

Flow rule. For the top layer of every granular run of a stack (material ``M``;
the run may be capped by a stable layer: debris under a roof spills out sideways,
leaving a void), let ``h`` be that top and, for a neighbour at horizontal distance ``d`` (``s`` or
``s sqrt 2``; the paper uses ``s`` for all eight, which makes diagonals 41 % steeper),
``h_i`` the floor on which material would land there: the top of the solid under
the air that the neighbour has at height ``h`` (no flow when the neighbour is solid
there: a wall). With ``dh_i = h - h_i`` and ``dh~_i = dh_i - d tan(alpha)`` when
positive, the paper moves ``dz_i = a dh~_i / sum dh~`` with a small constant ``a``
to avoid oscillations. Heights here are integer quanta ``dz`` of the stacks, the
threshold is ``T = floor(d tan(alpha) / dz)`` quanta, and the excess ``e = dh - T``.
A stack sends at most ``a`` per visit, split in proportion to the excesses, each
share also capped at ``ceil(e / 2)`` of the *current* excess. That cap is what
makes the iteration terminate: moving ``m <= ceil(e/2) < dh`` quanta from levels
``[h - m, h)`` down to ``[h_i, h_i + m)`` changes the potential energy (sum of the
levels of all granular quanta) by ``m (h_i - h + m) < 0``, an integer, so the
Gauss-Seidel sweeps (alternating scan order) stop after finitely many moves, with
``dh <= T`` everywhere, i.e. every slope ``<= tan(alpha)`` *exactly* on the
quantized heights. Quanta are moved, never created: mass is conserved exactly.
Grid edges are walls.

References
----------
Peytavie, A., Galin, E., Grosjean, J., Merillou, S. (2009). Arches: a framework for
modeling complex terrains. Computer Graphics Forum 28(2), 457-467 (section 3.4).
Musgrave, F. K., Kolb, C. E., Mace, R. S. (1989). The synthesis and rendering of
eroded fractal terrains. SIGGRAPH '89 (thermal weathering).
Benes, B., Forsbach, R. (2001). Layered data representation for visual simulation
of terrain erosion. SCCG 2001.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .material_stacks import ROCK, SAND, MaterialStacks

#: Default angles of repose in degrees (paper: sand 30-35, rocks 40-45).
REPOSE = {SAND: 33.0, ROCK: 42.0}


def _tables(stacks: MaterialStacks, angles):
    """Per-material granular flags and thresholds (quanta) for straight and diagonal steps."""
    granular = np.zeros(256, dtype=np.bool_)
    t_side = np.zeros(256, dtype=np.int64)
    t_diag = np.zeros(256, dtype=np.int64)
    for m, a in angles.items():
        if not 0.0 < a < 90.0:
            raise ValueError(f"angle of repose must be in (0, 90) degrees (got {a})")
        granular[m] = True
        tan = math.tan(math.radians(a))
        t_side[m] = int(math.floor(stacks.cell * tan / stacks.dz))
        t_diag[m] = int(math.floor(stacks.cell * math.sqrt(2.0) * tan / stacks.dz))
    if np.any(t_side[granular] < 1):
        raise ValueError("dz is larger than one cell's rise at the angle of repose: refine dz")
    return granular, t_side, t_diag


def stabilize(stacks: MaterialStacks, angles=None, amount=None, max_sweeps=100000, progress=None):
    """Let granular material flow until every slope is below its angle of repose.

    Parameters
    ----------
    stacks : MaterialStacks
    angles : dict, optional
        ``{material id: angle of repose in degrees}`` of the granular materials
        (default :data:`REPOSE`: sand 33, rock 42).
    amount : float, optional
        The paper's ``a``: most material a stack sends per visit, in metres
        (default one cell size ``s``).
    max_sweeps : int
        Safety cap on the sweeps (termination is guaranteed, see module docstring).
    progress : callable, optional
        ``progress(sweep, max_sweeps)``.

    Returns
    -------
    (MaterialStacks, dict)
        Stable stacks and statistics ``{'sweeps', 'moved_levels'}``.
    """
    angles = dict(REPOSE if angles is None else angles)
    granular, t_side, t_diag = _tables(stacks, angles)
    a = stacks.cell if amount is None else float(amount)
    if not a > 0:
        raise ValueError(f"amount must be > 0 (got {a})")
    a_q = max(1, int(round(a / stacks.dz)))
    lens = np.diff(stacks.offsets.astype(np.int64))
    cap = int(lens.max(initial=0)) + 16
    while True:
        M, N, L = _to_padded(stacks.offsets, stacks.material, stacks.count, cap)
        ok = _canonicalize(M, N, L, granular)
        total_sweeps, moved = 0, 0
        while ok:
            sweeps, mv, ok, done = _sweeps(M, N, L, stacks.nx, stacks.ny, granular, t_side, t_diag,
                                           a_q, min(64, max_sweeps - total_sweeps), total_sweeps % 2)
            total_sweeps += sweeps
            moved += mv
            if progress is not None:
                progress(total_sweeps, max_sweeps)
            if done or total_sweeps >= max_sweeps:
                break
        if ok:
            ok = _canonicalize(M, N, L, granular)
        if ok:
            break
        cap *= 2            # a stack ran out of layer slots: start over with more
    off, m, n = _from_padded(M, N, L)
    return stacks.with_arrays(off, m, n), {"sweeps": total_sweeps, "moved_levels": moved}


def slope_excess(stacks: MaterialStacks, angles=None):
    """Largest ``(h - h_i) / d - tan(alpha)`` over the tops of granular runs and their neighbours.

    ``<= 0`` means every slope is at most its angle of repose (the test of
    stability, with the same landing rule as :func:`stabilize`, in metres).
    Returns ``-inf`` when nothing can flow.
    """
    angles = dict(REPOSE if angles is None else angles)
    tan = np.zeros(256)
    granular = np.zeros(256, dtype=np.bool_)
    for m, a in angles.items():
        granular[m] = True
        tan[m] = math.tan(math.radians(a))
    M, N, L = _to_padded(stacks.offsets, stacks.material, stacks.count,
                         int(np.diff(stacks.offsets.astype(np.int64)).max(initial=0)) + 1)
    return _excess(M, N, L, stacks.nx, stacks.ny, granular, tan, stacks.cell, stacks.dz)


# ------------------------------------------------------------------ kernels
_DI = np.array([1, -1, 0, 0, 1, 1, -1, -1], dtype=np.int64)
_DJ = np.array([0, 0, 1, -1, 1, -1, 1, -1], dtype=np.int64)


@njit(cache=True)
def _to_padded(offsets, material, count, cap):
    ncol = len(offsets) - 1
    M = np.zeros((ncol, cap), dtype=np.uint8)
    N = np.zeros((ncol, cap), dtype=np.int64)
    L = np.zeros(ncol, dtype=np.int64)
    for c in range(ncol):
        a, b = offsets[c], offsets[c + 1]
        L[c] = b - a
        for k in range(a, b):
            M[c, k - a] = material[k]
            N[c, k - a] = count[k]
    return M, N, L


@njit(cache=True)
def _from_padded(M, N, L):
    ncol = len(L)
    off = np.zeros(ncol + 1, dtype=np.uint32)
    for c in range(ncol):
        off[c + 1] = off[c] + L[c]
    m = np.empty(off[ncol], dtype=np.uint8)
    n = np.empty(off[ncol], dtype=np.uint16)
    for c in range(ncol):
        for k in range(L[c]):
            m[off[c] + k] = M[c, k]
            n[off[c] + k] = N[c, k]
    return off, m, n


@njit(cache=True)
def _canonicalize(M, N, L, granular):
    """Merge and sort every section (sand, rock, air), merge equal neighbours, drop top air."""
    ncol, cap = M.shape
    tm = np.zeros(cap + 4, dtype=np.uint8)
    tn = np.zeros(cap + 4, dtype=np.int64)
    for c in range(ncol):
        t = 0
        k = 0
        while k < L[c]:
            if granular[M[c, k]] or M[c, k] == 0:
                sand = 0
                rock = 0
                air = 0
                other = 0
                while k < L[c] and (granular[M[c, k]] or M[c, k] == 0):
                    if M[c, k] == 0:
                        air += N[c, k]
                    elif M[c, k] == 2:
                        sand += N[c, k]
                    elif M[c, k] == 3:
                        rock += N[c, k]
                    else:
                        other += N[c, k]
                    k += 1
                if sand > 0:
                    tm[t] = 2
                    tn[t] = sand
                    t += 1
                if rock > 0:
                    tm[t] = 3
                    tn[t] = rock
                    t += 1
                if other > 0:
                    return False    # a granular id without a sorting rank
                if air > 0:
                    tm[t] = 0
                    tn[t] = air
                    t += 1
            else:
                if t > 0 and tm[t - 1] == M[c, k]:
                    tn[t - 1] += N[c, k]
                else:
                    tm[t] = M[c, k]
                    tn[t] = N[c, k]
                    t += 1
                k += 1
            if t > cap:
                return False
        while t > 0 and tm[t - 1] == 0:
            t -= 1
        for q in range(t):
            M[c, q] = tm[q]
            N[c, q] = tn[q]
        L[c] = t
    return True


@njit(cache=True)
def _landing(M, N, L, c, h):
    """Air layer of stack ``c`` holding level ``h - 1``: ``(index, bottom level)``; -1 if solid."""
    z = 0
    for k in range(L[c]):
        if z <= h - 1 < z + N[c, k]:
            if M[c, k] == 0:
                return k, z
            return -1, 0
        z += N[c, k]
    return L[c], z


@njit(cache=True)
def _deposit(M, N, L, c, q, g, m):
    """Put ``m`` quanta of ``g`` at the floor of air layer ``q`` of stack ``c``."""
    cap = M.shape[1]
    if q > 0 and M[c, q - 1] == g:
        N[c, q - 1] += m
    else:
        if L[c] + 1 > cap:
            return False
        for k in range(L[c], q, -1):
            M[c, k] = M[c, k - 1]
            N[c, k] = N[c, k - 1]
        M[c, q] = g
        N[c, q] = m
        L[c] += 1
        q += 1
    if q < L[c]:
        N[c, q] -= m          # the air above shrinks (it was thicker than m)
    return True


@njit(cache=True)
def _sweeps(M, N, L, nx, ny, granular, t_side, t_diag, a_q, n_sweeps, parity):
    moved = 0
    ncol = nx * ny
    # Only stacks that changed, or whose neighbours changed, can have become unstable:
    # a sweep visits those (all of them at first).
    dirty = np.ones(ncol, dtype=np.bool_)
    nxt = np.zeros(ncol, dtype=np.bool_)
    nb = np.zeros(8, dtype=np.int64)
    exc = np.zeros(8, dtype=np.int64)
    for sweep in range(n_sweeps):
        changed = False
        forward = (sweep + parity) % 2 == 0
        for step in range(ncol):
            c = step if forward else ncol - 1 - step
            if not dirty[c]:
                continue
            ci = c % nx
            cj = c // nx
            k = 0
            z = 0
            while k < L[c]:
                top = z + N[c, k]
                g = M[c, k]
                # The top of every granular run may flow, also under a ceiling (debris
                # of a collapse spills out sideways, leaving a void under the roof).
                run_top = granular[g] and (k == L[c] - 1 or not granular[M[c, k + 1]])
                if not run_top:
                    z = top
                    k += 1
                    continue
                total = 0
                for d in range(8):
                    exc[d] = 0
                    i = ci + _DI[d]
                    j = cj + _DJ[d]
                    if i < 0 or i >= nx or j < 0 or j >= ny:
                        continue
                    n = j * nx + i
                    q, b = _landing(M, N, L, n, top)
                    if q < 0:
                        continue
                    thr = t_side[g] if d < 4 else t_diag[g]
                    e = top - b - thr
                    if e > 0:
                        exc[d] = e
                        nb[d] = n
                        total += e
                if total == 0:
                    z = top
                    k += 1
                    continue
                budget = min(a_q, N[c, k])
                sent = 0
                for d in range(8):
                    if exc[d] == 0 or N[c, k] == 0 or sent >= budget:
                        continue
                    share = max(1, (budget * exc[d]) // total)
                    h = z + N[c, k]
                    q, b = _landing(M, N, L, nb[d], h)
                    if q < 0:
                        continue
                    thr = t_side[g] if d < 4 else t_diag[g]
                    e = h - b - thr
                    if e <= 0:
                        continue
                    m = min(share, (e + 1) // 2, N[c, k], budget - sent)
                    if not _deposit(M, N, L, nb[d], q, g, m):
                        return sweep, moved, False, False
                    if k + 1 < L[c] and M[c, k + 1] != 0:
                        # Capped by a stable layer: open a void under it.
                        if L[c] + 1 > M.shape[1]:
                            return sweep, moved, False, False
                        for q2 in range(L[c], k + 1, -1):
                            M[c, q2] = M[c, q2 - 1]
                            N[c, q2] = N[c, q2 - 1]
                        M[c, k + 1] = 0
                        N[c, k + 1] = 0
                        L[c] += 1
                    N[c, k] -= m
                    if k + 1 < L[c]:
                        N[c, k + 1] += m
                    sent += m
                    moved += m
                    changed = True
                    _mark(nxt, c, nx, ny)
                    _mark(nxt, nb[d], nx, ny)
                    # Stacks later in this sweep see the change too, so skipping the
                    # clean ones changes nothing but the time.
                    _mark(dirty, c, nx, ny)
                    _mark(dirty, nb[d], nx, ny)
                if N[c, k] == 0:
                    # The layer is gone: the air above joins the space below.
                    for q2 in range(k, L[c] - 1):
                        M[c, q2] = M[c, q2 + 1]
                        N[c, q2] = N[c, q2 + 1]
                    L[c] -= 1
                    if k < L[c] and k > 0 and M[c, k - 1] == 0 and M[c, k] == 0:
                        N[c, k - 1] += N[c, k]
                        for q2 in range(k, L[c] - 1):
                            M[c, q2] = M[c, q2 + 1]
                            N[c, q2] = N[c, q2 + 1]
                        L[c] -= 1
                    while L[c] > 0 and M[c, L[c] - 1] == 0:
                        L[c] -= 1
                    # Re-examine from this index (a layer below may now be exposed).
                    if k > 0:
                        k -= 1
                        z -= N[c, k]
                    continue
                z = z + N[c, k]
                k += 1
        if not changed:
            return sweep + 1, moved, True, True
        for c in range(ncol):
            dirty[c] = nxt[c]
            nxt[c] = False
    return n_sweeps, moved, True, False


@njit(cache=True)
def _mark(flags, c, nx, ny):
    ci = c % nx
    cj = c // nx
    for j in range(max(0, cj - 1), min(ny, cj + 2)):
        for i in range(max(0, ci - 1), min(nx, ci + 2)):
            flags[j * nx + i] = True


@njit(cache=True)
def _excess(M, N, L, nx, ny, granular, tan, s, dz):
    worst = -np.inf
    for c in range(nx * ny):
        ci = c % nx
        cj = c // nx
        z = 0
        for k in range(L[c]):
            top = z + N[c, k]
            g = M[c, k]
            if granular[g] and (k == L[c] - 1 or not granular[M[c, k + 1]]):
                for d in range(8):
                    i = ci + _DI[d]
                    j = cj + _DJ[d]
                    if i < 0 or i >= nx or j < 0 or j >= ny:
                        continue
                    q, b = _landing(M, N, L, j * nx + i, top)
                    if q < 0:
                        continue
                    dist = s if d < 4 else s * np.sqrt(2.0)
                    v = (top - b) * dz / dist - tan[g]
                    if v > worst:
                        worst = v
            z = top
    return worst
