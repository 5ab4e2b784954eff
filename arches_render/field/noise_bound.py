"""Computer-assisted proof of the Lipschitz bound of :func:`~arches_render.field.noise.gradient_noise`.

Run offline (``python -m arches_render.field.noise_bound``); nothing imports this
module at package import time. It prints a number ``L`` with the guarantee
``|grad n(p)| <= L`` for every point, every seed and every assignment of gradients
to lattice corners; ``NOISE_LIPSCHITZ`` in :mod:`~arches_render.field.noise` is
that number rounded up.

The statement
-------------
In a cell, with local coordinates ``u in [0, 1]^3``, corners ``c in {0, 1}^3``,
``d_c = u - c``, the quintic fade ``s`` and ``W_c(u) = prod_k w_{c_k}(u_k)``
(``w_1 = s``, ``w_0 = 1 - s``),

    n(u) = sum_c W_c(u) g_c . d_c,    grad n(u) = sum_c A_c(u) g_c,
    A_c(u) = grad W_c(u) d_c^T + W_c(u) I.

The gradients ``g_c`` are taken from ``G``, the 12 vectors ``(+-1, +-1, 0)`` and
permutations (``grad_dot`` maps its 16 hash codes onto exactly these: codes
12..15 repeat ``(1,1,0), (-1,1,0), (0,-1,1), (0,-1,-1)``). We bound, for ALL
``12^8`` choices (a superset of what the hash produces),

    F(u) = max_config |grad n(u)|,     L = sup_u F(u).

``n`` is continuous across cell faces (the far corners' weights vanish there, and
a corner's gradient depends on the corner alone), so on any segment cut by the
lattice planes into pieces inside closed cells, ``|n(b) - n(a)| <= L |b - a|``.

Step 1: support function (exact). ``max_{g in G} w . g = M2(w)``, the sum of the
two largest ``|w_k|`` (pick those two coordinates with matching signs). For a
unit ``e``, ``Phi_u(e) = sum_c M2(A_c(u)^T e)`` is the largest ``grad n(u) . e``
over configurations, so every value ``Phi_u(e)`` is attained by some
configuration (a lower bound of ``F(u)``), and if ``k*`` is a configuration's
gradient of largest norm, ``Phi_u(e) >= k* . e``.

Step 2: directions (adaptive cube net, rigorous angle). Map a unit ``e`` to
``p = e / |e|_inf`` on the surface of ``[-1, 1]^3``. A face is cut into square
cells ``Q`` of half-side ``r <= 1/2``; take ``e = k* / |k*|`` and ``q`` the centre of
the cell holding its ``p``. Then ``|p - q| <= sqrt(2) r``, ``p . q >= 1 > 0``, and the distance
from ``p`` to the line ``R q`` is ``|p| sin(theta) <= |p - q|`` with ``|p| >= 1``,
so ``sin(theta) <= sqrt(2) r`` and

    |k*| cos(theta) = k* . q/|q| <= Phi_u(q/|q|)  =>  |k*| <= Phi_u(q/|q|) / cos_Q,
    cos_Q = sqrt(1 - 2 r^2).

Hence ``F(u) <= max_Q Phi_u(q_Q/|q_Q|) / cos_Q`` over any set of cells covering the
cube surface. The cells are refined (each into 4) only where that value could
matter (see Step 5); the leaves of this refinement still cover the surface.

Step 3: variation over a box (interval arithmetic, replaces a global Hessian bound).
For a cube ``B`` with centre ``u0`` and any ``u in B``, configuration by configuration

    |grad n(u)| <= |grad n(u0)| + sum_c |(A_c(u) - A_c(u0)) g_c| <= F(u0) + V(B),
    V(B) = sum_c max_{m in {(1,1,0),(1,0,1),(0,1,1)}} |Delta_c m|,

where ``Delta_c[i, j] >= |A_c(u)[i, j] - A_c(u0)[i, j]|`` on ``B`` (``|g|`` is one of
the three patterns ``m``, and ``|(D g)_i| <= (|D| |g|)_i``). Each entry of ``A_c``
is a product of three univariate polynomials, one per coordinate:
``A_c[i, i] = alpha(u_i) w(u_j) w(u_k)`` with ``alpha = w' (t - c_i) + w``, and
``A_c[i, j] = w'(u_i) beta(u_j) w(u_k)`` (``j != i``) with ``beta = w (t - c_j)``.
The range of a polynomial on an interval lies between the extreme coefficients
of its Bernstein form on that interval (convex-hull property), the range of a
product of functions of different variables lies in the interval product of
their ranges, and ``Delta`` is the largest distance from ``A_c(u0)`` to that
interval. ``V(B)`` is first order in the box size with a local constant: about
40 times the half-side near ``u = (1/2, 1/2, 1/2)``, where the sampled Hessian
norm is about 14 times the half-diagonal (24 times the half-side). A global
analytic Hessian bound (about 66, from ``|s''| <= 10/sqrt(3)``, ``s' <= 15/8``)
would need boxes ~3x smaller, i.e. ~25x more of them.

Step 4: symmetry. ``s(1 - t) = 1 - s(t)`` and ``G`` is closed under sign changes
and permutations of coordinates, so ``u_k -> 1 - u_k`` (with ``g_c -> g_c`` with
its ``k``-th sign flipped, moved to the mirrored corner) and permutations of the
axes map configurations onto configurations and keep ``F``. It suffices to
cover ``D = {0 <= u_1 <= u_2 <= u_3 <= 1/2}``.

Step 5: branch and bound. Cubes covering ``D`` (those of a ``grid^3`` partition of
``[0, 1/2]^3`` that meet ``D``) get ``UB(B) = max_Q Phi/cos_Q + V(B) >= sup_B F``.
With ``LB`` the largest ``Phi`` value seen (a lower bound of ``L``, Step 1) and a
target ``T = LB + tol``, direction cells are refined while
``Phi/cos_Q + V(B) > T``, and a cube is split into 8 while ``UB(B) > T``, up to
the depth limits. The certificate is the largest ``UB`` over the final cubes,
plus a margin for float64 rounding (every quantity is below 100 and takes under
a hundred operations: errors below 1e-11, margin ``1e-9``). The limits and
``T`` only steer the work; every final cube's ``UB`` is a bound whatever they are.

Result (defaults, ~15 s): ``L <= 3.7580``. The bound is tight: at ``u = (1/2, 1/2, 1/2)``
the configuration of :func:`center_lower_bound` has ``|grad n| = 15/4`` exactly.
Random configurations rarely come close (sampling finds about 3.08).
"""

from __future__ import annotations

import itertools
import math
import time
from math import comb
from typing import NamedTuple

import numpy as np

_P = np.polynomial.polynomial
_S = np.array([0.0, 0.0, 0.0, 10.0, -15.0, 6.0])  # s(t) = 10 t^3 - 15 t^4 + 6 t^5
_CORNERS = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)])
_PATTERNS = np.array([[1.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])  # |g| for g in G
FP_MARGIN = 1e-9


def _factor_polys(bit: int) -> dict[str, np.ndarray]:
    """Monomial coefficients of the univariate factors for corner bit ``bit``."""
    w = _S.copy() if bit else _P.polysub([1.0], _S)
    dw = _P.polyder(w)
    t_minus_b = np.array([-float(bit), 1.0])
    return {"w": w, "dw": dw, "alpha": _P.polyadd(_P.polymul(dw, t_minus_b), w),
            "beta": _P.polymul(w, t_minus_b)}


_FACTORS = (_factor_polys(0), _factor_polys(1))


def _entry_factors(i: int, j: int) -> tuple[str, str, str]:
    """Names of the factors of ``A_c[i, j]`` along axes 0, 1, 2."""
    if i == j:
        return tuple("alpha" if k == i else "w" for k in range(3))
    return tuple("dw" if k == i else "beta" if k == j else "w" for k in range(3))


def bernstein_range(coef, a, b):
    """Enclosure ``(lo, hi)`` of ``{p(t): a <= t <= b}`` for the polynomial ``coef`` (ascending).

    The Taylor coefficients of ``tau -> p(a + (b - a) tau)`` are converted to the
    Bernstein basis of ``[0, 1]``; the polynomial's values are convex combinations
    of those coefficients.
    """
    n = len(coef) - 1
    h = b - a
    c = [sum(coef[j] * comb(j, k) * a ** (j - k) for j in range(k, n + 1)) * h ** k for k in range(n + 1)]
    beta = np.stack([sum(comb(i, k) / comb(n, k) * c[k] for k in range(i + 1)) for i in range(n + 1)])
    return beta.min(0), beta.max(0)


def corner_matrices(u):
    """``A_c(u)`` for the 8 corners: array ``(N, 8, 3, 3)`` for ``u`` of shape ``(N, 3)``."""
    u = np.asarray(u, dtype=float)
    vals = [{k: _P.polyval(u, p) for k, p in _FACTORS[b].items()} for b in (0, 1)]
    A = np.empty(u.shape[:1] + (8, 3, 3))
    for ci, c in enumerate(_CORNERS):
        for i in range(3):
            for j in range(3):
                names = _entry_factors(i, j)
                A[:, ci, i, j] = np.prod([vals[c[k]][names[k]][:, k] for k in range(3)], axis=0)
    return A


def variation_bound(center, half):
    """``V(B)`` (Step 3) for cubes ``center (N, 3)`` of half-side ``half (N,)``."""
    lo, hi = center - half[:, None], center + half[:, None]
    rng = [{k: bernstein_range(p, lo, hi) for k, p in _FACTORS[b].items()} for b in (0, 1)]
    A0 = corner_matrices(center)
    V = np.zeros(len(center))
    for ci, c in enumerate(_CORNERS):
        delta = np.empty((len(center), 3, 3))
        for i in range(3):
            for j in range(3):
                names = _entry_factors(i, j)
                elo, ehi = rng[c[0]][names[0]][0][:, 0], rng[c[0]][names[0]][1][:, 0]
                for k in (1, 2):
                    flo, fhi = rng[c[k]][names[k]][0][:, k], rng[c[k]][names[k]][1][:, k]
                    prods = np.stack([elo * flo, elo * fhi, ehi * flo, ehi * fhi])
                    elo, ehi = prods.min(0), prods.max(0)
                a0 = A0[:, ci, i, j]
                delta[:, i, j] = np.maximum(ehi - a0, a0 - elo)
        V += np.linalg.norm(np.einsum("nij,pj->npi", delta, _PATTERNS), axis=-1).max(axis=1)
    return V, A0


def support(A, q):
    """``Phi_u(q/|q|) = sum_c M2(A_c^T q) / |q|`` for matrices ``A (P, 8, 3, 3)``, ``q (P, 3)``."""
    w = np.abs(np.einsum("pcij,pi->pcj", A, q))
    return (w.sum(-1) - w.min(-1)).sum(-1) / np.linalg.norm(q, axis=-1)


def _cube_cells(m: int):
    """Cell centres ``(face, a, b)`` and half-side of an ``m x m`` grid on each cube face."""
    t = (np.arange(m) + 0.5) * (2.0 / m) - 1.0
    a, b = np.meshgrid(t, t, indexing="ij")
    face = np.repeat(np.arange(6), m * m)
    return face, np.tile(a.ravel(), 6), np.tile(b.ravel(), 6), 1.0 / m


def _directions(face, a, b):
    axis, sign = face // 2, np.where(face % 2 == 0, 1.0, -1.0)
    q = np.empty(face.shape + (3,))
    q[np.arange(len(face)), axis] = sign
    q[np.arange(len(face)), (axis + 1) % 3] = a
    q[np.arange(len(face)), (axis + 2) % 3] = b
    return q


def _box_upper_bounds(A0, V, state, net, net_levels, can_split, chunk=40000):
    """Step 2 for each cube centre: ``max_Q Phi/cos_Q`` over the refined direction cells.

    Returns ``(fub, lbu, cosu)``: the upper bound of ``F(u0)``, the largest ``Phi``
    seen (a lower bound), and ``cos_Q`` of the cell giving ``fub``. Cells are refined
    while ``Phi/cos_Q + V > state['T']``; boxes that must be split anyway
    (``lbu + V > T``) stop refining (their ``fub`` is then still a valid bound).
    """
    nb = len(A0)
    f0, a0, b0, r0 = _cube_cells(net)
    bi = np.repeat(np.arange(nb), len(f0))
    face, a, b = np.tile(f0, nb), np.tile(a0, nb), np.tile(b0, nb)
    r = r0
    fub = np.full(nb, -np.inf)
    cosu = np.ones(nb)
    lbu = np.full(nb, -np.inf)
    for level in range(net_levels + 1):
        cos_q = math.sqrt(1.0 - 2.0 * r * r)
        phi = np.empty(len(bi))
        for s in range(0, len(bi), chunk):
            sl = slice(s, s + chunk)
            phi[sl] = support(A0[bi[sl]], _directions(face[sl], a[sl], b[sl]))
        np.maximum.at(lbu, bi, phi)
        state["evals"] += len(bi)
        state["LB"] = max(state["LB"], float(lbu.max()))
        state["T"] = max(state["T"], state["LB"] + state["tol"])
        ub = phi / cos_q
        doomed = (lbu + V > state["T"]) & can_split
        refine = (ub + V[bi] > state["T"]) & ~doomed[bi] & (level < net_levels)
        leaf = ~refine
        lf = np.full(nb, -np.inf)
        np.maximum.at(lf, bi[leaf], ub[leaf])
        better = lf > fub
        fub = np.where(better, lf, fub)
        cosu = np.where(better, cos_q, cosu)
        if not refine.any():
            break
        r = r / 2.0
        bi, face, a, b = bi[refine], face[refine], a[refine], b[refine]
        offs = np.array([[-r, -r], [-r, r], [r, -r], [r, r]])
        bi, face = np.repeat(bi, 4), np.repeat(face, 4)
        a = (a[:, None] + offs[:, 0]).ravel()
        b = (b[:, None] + offs[:, 1]).ravel()
    return fub, lbu, cosu


def configuration_ascent(A, e, iterations=8):
    """Lower bounds of ``F(u)``: norms of explicit configurations' gradients.

    From directions ``e (P, 3)``, repeatedly take the configuration that maximises
    ``grad n . e`` (``g_c = argmax_G (A_c^T e) . g``) and move ``e`` to its gradient.
    Returns ``(|k|, k)`` of the last configuration (``A`` is ``(P, 8, 3, 3)``).
    """
    G = np.array([v for v in itertools.product((-1, 0, 1), repeat=3) if sum(map(abs, v)) == 2], float)
    for _ in range(iterations):
        cfg = G[np.argmax(np.einsum("pcij,pi,gj->pcg", A, e, G), axis=-1)]
        k = np.einsum("pcij,pcj->pi", A, cfg)
        norm = np.linalg.norm(k, axis=-1)
        e = k / norm[:, None]
    return norm, k


def _meets_domain(lo, hi):
    """Whether the cube ``[lo, hi]`` meets ``{u_1 <= u_2 <= u_3}`` (greedy choice of the point)."""
    return (lo[:, 0] <= hi[:, 1]) & (np.maximum(lo[:, 0], lo[:, 1]) <= hi[:, 2])


class Certificate(NamedTuple):
    """A certified bound and where it comes from."""
    bound: float            #: certified sup |grad n| (``max UB + FP_MARGIN``)
    lower: float            #: largest |grad n| exhibited by a configuration (Step 1)
    net_max: float          #: worst cube: max over direction cells of Phi (before / cos)
    cos_delta: float        #: worst cube: cos_Q of the cell giving its bound
    variation: float        #: worst cube: V(B)
    half_diagonal: float    #: worst cube: half-diagonal sqrt(3) * half-side
    center: tuple           #: worst cube: centre
    critical: tuple         #: (UB, net max, cos_Q, V, half-diagonal) of the final cube holding (1/2, 1/2, 1/2)
    boxes: int              #: cubes evaluated
    evals: int              #: support-function evaluations
    seconds: float


def certify(grid: int = 8, net: int = 4, tol: float = 0.008, max_depth: int = 8, net_levels: int = 5,
            verbose: bool = False) -> Certificate:
    """Certify ``sup |grad n|`` over all gradient configurations (see the module docstring).

    Parameters
    ----------
    grid : int
        Initial cubes per axis over ``[0, 1/2]^3`` (only those meeting ``D`` are kept).
    net : int
        Initial direction cells per cube-face side (``6 net^2`` cells).
    tol : float
        Target slack above the best lower bound; it steers refinement only.
    max_depth, net_levels : int
        Cube splits and direction-cell refinements allowed.
    """
    if net < 2:
        raise ValueError("net >= 2 is needed (cos_Q = sqrt(1 - 2 r^2) with r = 1/net)")
    t0 = time.perf_counter()
    half0 = 0.25 / grid
    g = (np.arange(grid) + 0.5) * (2 * half0)
    center = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    half = np.full(len(center), half0)
    keep = _meets_domain(center - half[:, None], center + half[:, None])
    center, half = center[keep], half[keep]
    # Seed the lower bound (it only steers the work): explicit configurations at the
    # vertices of the initial cubes that lie in D, from a coarse set of directions.
    v = np.linspace(0.0, 0.5, grid + 1)
    verts = np.stack(np.meshgrid(v, v, v, indexing="ij"), -1).reshape(-1, 3)
    verts = verts[_meets_domain(verts, verts)]
    dirs = _directions(*_cube_cells(2)[:3])
    lb, _ = configuration_ascent(np.repeat(corner_matrices(verts), len(dirs), axis=0), np.tile(dirs, (len(verts), 1)))
    state = {"LB": float(lb.max()), "T": float(lb.max()) + tol, "tol": tol, "evals": 0}
    worst = critical = None
    boxes = 0
    for depth in range(max_depth + 1):
        if not len(center):
            break
        boxes += len(center)
        V, A0 = variation_bound(center, half)
        fub, lbu, cosu = _box_upper_bounds(A0, V, state, net, net_levels, depth < max_depth)
        ub = fub + V
        split = (ub > state["T"]) & (depth < max_depth)
        final = ~split
        if final.any():
            k = np.flatnonzero(final)[np.argmax(ub[final])]
            if worst is None or ub[k] > worst[0]:
                worst = (float(ub[k]), float(fub[k] * cosu[k]), float(cosu[k]), float(V[k]),
                         float(half[k]) * math.sqrt(3.0), tuple(float(x) for x in center[k]))
            at_mid = final & np.all(np.abs(center - 0.5) <= half[:, None], axis=1)
            if at_mid.any():
                k = np.flatnonzero(at_mid)[0]
                critical = (float(ub[k]), float(fub[k] * cosu[k]), float(cosu[k]), float(V[k]),
                            float(half[k]) * math.sqrt(3.0))
        if verbose:
            print(f"depth {depth}: {len(center)} cubes, {int(split.sum())} split, "
                  f"LB {state['LB']:.5f}, worst so far {worst[0] if worst else float('nan'):.5f}")
        c, h = center[split], half[split] / 2.0
        offs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        center = (c[:, None, :] + offs[None] * h[:, None, None]).reshape(-1, 3)
        half = np.repeat(h, 8)
        keep = _meets_domain(center - half[:, None], center + half[:, None])
        center, half = center[keep], half[keep]
    ub, net_max, cos_d, var, hd, ctr = worst
    return Certificate(ub + FP_MARGIN, state["LB"], net_max, cos_d, var, hd, ctr, critical, boxes,
                       state["evals"], time.perf_counter() - t0)


def center_lower_bound():
    """The configuration ``g_c = -sigma_x (0, sigma_y, sigma_z)``, ``sigma = 2c - 1``, at ``u = (1/2, 1/2, 1/2)``.

    There ``A_c = (15/64) sigma sigma^T + I/8`` and ``sigma . g_c = -2 sigma_x``, so
    ``grad n = -(15/32) sum_c sigma_x sigma + sum_c g_c / 8 = (-15/4, 0, 0)``: no bound
    valid for all configurations can be below ``15/4``. Returns ``(|grad n|, g (8, 3))``.
    """
    sigma = 2.0 * _CORNERS - 1.0
    g = -sigma[:, :1] * np.column_stack([np.zeros(8), sigma[:, 1], sigma[:, 2]])
    k = np.einsum("cij,cj->i", corner_matrices(np.full((1, 3), 0.5))[0], g)
    return float(np.linalg.norm(k)), g


def main():
    cert = certify(verbose=True)
    print(f"certified sup|grad n| <= {cert.bound:.6f}   (rounded up: {math.ceil(cert.bound * 100) / 100:.2f})")
    print(f"  lower bound (explicit configurations): {cert.lower:.6f}")
    print(f"  worst cube: centre {tuple(round(x, 5) for x in cert.center)}, half-diagonal {cert.half_diagonal:.3g}:")
    print(f"    net maximum {cert.net_max:.6f} / cos(delta) {cert.cos_delta:.6f} "
          f"+ variation V {cert.variation:.6f} (= {cert.variation / cert.half_diagonal:.1f} x half-diagonal)")
    ub, nm, cq, var, hd = cert.critical
    print(f"  cube at (1/2, 1/2, 1/2): {nm:.6f} / {cq:.6f} + V {var:.6f} = {ub:.6f}, half-diagonal {hd:.3g}")
    print(f"  {cert.boxes} cubes, {cert.evals} support evaluations, {cert.seconds:.1f} s")


if __name__ == "__main__":
    main()
