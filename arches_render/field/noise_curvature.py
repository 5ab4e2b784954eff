"""Computer-assisted proof of the gradient noise's curvature bound along horizontal lines.

Run offline (``python -m arches_render.field.noise_curvature``); nothing imports this
module at package import time. It prints a number ``C`` with the guarantee
``|d^2/ds^2 n(u0 + s e)| <= C`` for every point, every seed, every assignment of
gradients to lattice corners and every unit direction ``e`` in the ``xy`` plane;
``NOISE_PLANAR_CURVATURE`` in :mod:`~arches_render.field.noise` is that number
rounded up. (The implicit heightfield's fBm is evaluated at ``(x, y, const)``, so its
rays see the noise along such lines: :mod:`arches_render.generators.terrain.elevation_line`.)

The statement
-------------
In a cell, with local coordinates ``u in [0, 1]^3``, corners ``c``, the fade's corner
weights ``W_c`` and ``phi_c = g_c . (u - c)`` (see :mod:`~arches_render.field.noise`), along
the line ``u0 + s e``

    n'' = sum_c W_c'' phi_c + 2 W_c' (g_c . e) = sum_c g_c . v_c,
    v_c = W_c'' (u - c) + 2 W_c' e,   W_c' = grad W_c . e,   W_c'' = e^T (hess W_c) e,

since ``phi_c`` is linear (``phi_c' = g_c . e``, ``phi_c'' = 0``). Each term is linear in its
own corner's gradient ``g_c``, chosen from the 12 vectors ``(+-1, +-1, 0)`` and
permutations, a symmetric set whose support function is ``M2`` (the sum of the two
largest ``|.|``, as in :mod:`~arches_render.field.noise_bound`), so over all ``12^8``
configurations (a superset of what the hash produces)

    max_config |n''| = Q(u, e) = sum_c M2(v_c(u, e)).

``n`` and its derivatives along a line are continuous across cell faces only up to
the first derivative (the quintic fade is C2: ``s''(0) = s''(1) = 0``, so ``n`` is C2 and
the bound holds along whole lines).

The proof
---------
``e = (cos t, sin t, 0)`` and ``Q(u, -e) = Q(u, e)``, so ``t in [0, pi)``. The box
``[0, 1]^3 x [0, pi)`` is cut into boxes; on each, every univariate factor (``w``, ``w'``,
``w''`` of each corner bit per axis, ``u_k - c_k``) is enclosed by its Bernstein
coefficients (:func:`~arches_render.field.noise_bound.bernstein_range`), ``cos`` and
``sin`` by their monotone pieces, and ``v_c`` by interval arithmetic; ``M2`` of an
interval vector is at most the sum of its two largest magnitudes. A box whose upper
bound exceeds the target is split in all four coordinates, up to ``max_depth``;
the certificate is the largest upper bound over the leaves (every point of the
domain lies in some leaf). The largest sampled ``Q`` is reported beside it.
"""

from __future__ import annotations

import argparse
import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polynomial as _P

from .noise_bound import bernstein_range

#: The quintic fade ``s(t) = 6 t^5 - 15 t^4 + 10 t^3`` (ascending coefficients).
_S = np.array([0.0, 0.0, 0.0, 10.0, -15.0, 6.0])
_CORNERS = list(itertools.product((0, 1), repeat=3))


def _factors(bit):
    w = _S.copy() if bit else _P.polysub([1.0], _S)
    return w, _P.polyder(w), _P.polyder(w, 2)


_POLYS = (_factors(0), _factors(1))


def _imul(a, b):
    """Interval product of ``a = (lo, hi)`` and ``b``."""
    p = np.stack([a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1]])
    return p.min(0), p.max(0)


def _iadd(a, b):
    return a[0] + b[0], a[1] + b[1]


def _cos_sin(t0, t1):
    """Enclosures of ``cos`` and ``sin`` on ``[t0, t1]`` within ``[0, pi]``."""
    c = (np.cos(t1), np.cos(t0))  # decreasing on [0, pi]
    s_end = np.minimum(np.sin(t0), np.sin(t1))
    s_top = np.where((t0 <= math.pi / 2) & (t1 >= math.pi / 2), 1.0, np.maximum(np.sin(t0), np.sin(t1)))
    # Rounding: widen by a few ulps of the unit range.
    eps = 1e-12
    return (c[0] - eps, c[1] + eps), (s_end - eps, s_top + eps)


def upper_bounds(lo, hi, t0, t1):
    """Upper bounds of ``Q`` on the boxes ``[lo, hi] x [t0, t1]`` (``lo, hi``: ``(N, 3)``)."""
    rng = [[[bernstein_range(p, lo[:, k], hi[:, k]) for p in _POLYS[b]] for k in range(3)] for b in (0, 1)]
    cos, sin = _cos_sin(t0, t1)
    e = (cos, sin)
    total = np.zeros(len(lo))
    for c in _CORNERS:
        w = [rng[c[k]][k][0] for k in range(3)]
        d1 = [rng[c[k]][k][1] for k in range(3)]
        d2 = [rng[c[k]][k][2] for k in range(3)]
        # W' = sum_k e_k dW/du_k, W'' = sum_{k,m} e_k e_m d2W/du_k du_m over k, m in {x, y}.
        wp = _imul(e[0], _imul(d1[0], _imul(w[1], w[2])))
        wp = _iadd(wp, _imul(e[1], _imul(w[0], _imul(d1[1], w[2]))))
        wpp = _imul(_imul(e[0], e[0]), _imul(d2[0], _imul(w[1], w[2])))
        wpp = _iadd(wpp, _imul(_imul(e[1], e[1]), _imul(w[0], _imul(d2[1], w[2]))))
        cross = _imul(_imul(e[0], e[1]), _imul(d1[0], _imul(d1[1], w[2])))
        wpp = _iadd(wpp, (2.0 * cross[0], 2.0 * cross[1]))
        mags = []
        for k in range(3):
            comp = _imul(wpp, (lo[:, k] - c[k], hi[:, k] - c[k]))
            if k < 2:
                tw = _imul(wp, e[k])
                comp = _iadd(comp, (2.0 * tw[0], 2.0 * tw[1]))
            mags.append(np.maximum(np.abs(comp[0]), np.abs(comp[1])))
        mags = np.sort(np.stack(mags), axis=0)
        total += mags[-1] + mags[-2]
    return total


def sampled_max(n=400_000, seed=0):
    """``max Q`` over random points and directions (a lower bound of the supremum)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(0, 1, (n, 3))
    t = rng.uniform(0, math.pi, n)
    return float(upper_bounds(u, u, t, t).max())


@dataclass
class Certificate:
    bound: float
    sampled: float
    leaves: int
    depth: int


def certify(target: float, grid: int = 4, angles: int = 8, max_depth: int = 8, chunk: int = 200_000):
    """Certify ``sup Q <= bound`` by branch and bound (module docstring).

    Parameters
    ----------
    target : float
        Boxes whose upper bound is at most this are accepted.
    grid, angles : int
        Initial cells per axis of ``u`` and of ``t``.
    max_depth : int
        Splits before giving up (then the bound is that of the unsplit leaves).

    Returns
    -------
    Certificate
        ``bound``: the largest upper bound over the accepted leaves and those left at
        ``max_depth`` (rigorous either way).
    """
    g = (np.arange(grid) + 0.5) / grid
    U = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    T = (np.arange(angles) + 0.5) / angles * math.pi
    centre = np.repeat(U, angles, axis=0)
    tc = np.tile(T, len(U))
    half = np.full(len(centre), 0.5 / grid)
    thalf = np.full(len(centre), 0.5 * math.pi / angles)
    bound, leaves, depth = 0.0, 0, 0
    while len(centre):
        ub = np.concatenate([upper_bounds(centre[i:i + chunk] - half[i:i + chunk, None],
                                          centre[i:i + chunk] + half[i:i + chunk, None],
                                          tc[i:i + chunk] - thalf[i:i + chunk], tc[i:i + chunk] + thalf[i:i + chunk])
                             for i in range(0, len(centre), chunk)])
        done = ub <= target
        if depth == max_depth:
            done[:] = True
        bound = max(bound, float(ub[done].max(initial=0.0)))
        leaves += int(done.sum())
        centre, tc, half, thalf = centre[~done], tc[~done], half[~done], thalf[~done]
        if not len(centre):
            break
        depth += 1
        signs = np.array(list(itertools.product((-0.5, 0.5), repeat=4)))
        centre = (centre[:, None, :] + signs[None, :, :3] * half[:, None, None]).reshape(-1, 3)
        tc = (tc[:, None] + signs[None, :, 3] * thalf[:, None]).reshape(-1)
        half = np.repeat(half * 0.5, 16)
        thalf = np.repeat(thalf * 0.5, 16)
    return Certificate(bound=bound, sampled=sampled_max(), leaves=leaves, depth=depth)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--target", type=float, default=15.0)
    ap.add_argument("--max-depth", type=int, default=8)
    args = ap.parse_args()
    cert = certify(args.target, max_depth=args.max_depth)
    print(f"sup |n''| along horizontal lines <= {cert.bound:.4f} (sampled max {cert.sampled:.4f}; "
          f"{cert.leaves} leaves, depth {cert.depth})")


if __name__ == "__main__":
    main()
