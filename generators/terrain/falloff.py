"""Compact falloff ``g`` and the vertical sigmoid ``sigma`` of terrain amplification.

Falloff (Paris et al. 2019, Sec. 3.3): a compactly supported, C2 function of the
distance ``r`` to a skeleton, with radius of influence ``R``:

    g(r) = (1 - (r/R)^2)^3   if r < R,   0 otherwise.

With ``u = r/R``, ``g'(u) = -6 u (1 - u^2)^2``, largest in magnitude at ``u = 1/sqrt(5)``:

    max |dg/dr| = G_SLOPE / R,    G_SLOPE = 96 / (25 sqrt 5) ~= 1.7173.

Sigmoid (Sec. 5.1): the odd cubic ``s`` with ``s(0) = 0``, ``s'(0) = 1``, ``s(R) = T``,
``s'(R) = 0``, constant ``T`` beyond ``R`` (the paper's ``sigma = T + s``, range
``[0, 2T]``, surface at ``T``; we subtract ``T`` so the surface is ``f = 0``):

    s(x) = x + a x^2 + b x^3   (0 <= x <= R),   a = (3T - 2R)/R^2,  b = (R - 2T)/R^3.

With ``tau = T/R`` and ``u = x/R``: ``s'(x) = (1 - u)(1 + c u)``, ``c = 6 tau - 3``. So
``s`` is monotone iff ``tau >= 1/3``, and its slope is at most

    S_SIGMA = max(1, (c + 1)^2 / (4c))   (the second term when c >= 1).

``s(x) / x`` on ``(0, R]`` is a quadratic in ``u`` equal to 1 at 0 and ``tau`` at 1 that is
either concave (``tau >= 1/2``) or convex and decreasing at ``u = 1``; in both cases
``s(x) >= k x`` with ``k = min(1, tau)``, which gives the inverse bound
``s^{-1}(c) <= c / k`` used for distance bounds.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), Sec. 3.3 and 5.1.
Wyvill, B., Guy, A., Galin, E. (1999). Extending the CSG tree. Computer Graphics
Forum 18(2) (compact falloff functions).
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np

#: ``max |g'(u)|`` over ``u in [0, 1]`` for ``g(u) = (1 - u^2)^3``.
G_SLOPE = 96.0 / (25.0 * math.sqrt(5.0))


def g(r, R):
    """Compact falloff ``(1 - (r/R)^2)^3`` (0 beyond ``R``) on numpy values.

    Parameters
    ----------
    r : array_like
        Distances (>= 0).
    R : array_like
        Radius of influence (> 0).

    Returns
    -------
    numpy.ndarray
    """
    u2 = np.square(np.asarray(r, dtype=np.float64) / np.asarray(R, dtype=np.float64))
    return np.where(u2 < 1.0, np.power(np.clip(1.0 - u2, 0.0, 1.0), 3), 0.0)


def falloff_slope_max(lo, hi):
    """``max |g'(u)|`` over ``u`` in ``[lo, hi]`` (Dr.Jit), ``g(u) = (1 - u^2)^3`` on ``[0, 1]``.

    ``|g'(u)| = 6 u (1 - u^2)^2`` rises on ``[0, 1/sqrt 5]`` and falls on ``[1/sqrt 5, 1]``
    (0 at both ends and beyond 1), so its maximum over an interval is ``G_SLOPE``
    where the interval holds ``1/sqrt 5``, else its value at the end nearer to it.

    Parameters
    ----------
    lo, hi : mi.Float
        Interval ends (``lo <= hi``; any values: clamped to ``[0, 1]``).

    Returns
    -------
    mi.Float
    """
    peak = 1.0 / math.sqrt(5.0)
    a = dr.clip(lo, 0.0, 1.0)
    b = dr.clip(hi, 0.0, 1.0)
    u = dr.select(b < peak, b, a)
    w = 1.0 - u * u
    edge = 6.0 * u * w * w
    return dr.select((a <= peak) & (b >= peak), G_SLOPE, edge)


def g_dr(u2):
    """``g`` as a function of ``u^2 = (r/R)^2`` in Dr.Jit (0 for ``u^2 >= 1``)."""
    w = dr.maximum(1.0 - u2, 0.0)
    return w * w * w


def energy_for_radius(radius, R, level):
    """Energy ``e`` with ``e g(radius, R) = level``.

    A carving primitive of falloff ``R`` and energy ``-e`` summed with material whose
    field value is ``level`` (``T`` deep inside an
    :class:`~.implicit_heightfield.ImplicitHeightfield`) removes the ball of radius
    ``radius`` (without noise).

    Parameters
    ----------
    radius : array_like
        Cavity radius, ``0 <= radius < R``.
    R : array_like
        Falloff radius of influence.
    level : float
        Field value of the material.

    Returns
    -------
    numpy.ndarray
    """
    radius = np.asarray(radius, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    if np.any(radius >= R) or np.any(radius < 0):
        raise ValueError("energy_for_radius needs 0 <= radius < R")
    return level / g(radius, R)


def sigmoid_coefficients(R: float, T: float) -> tuple[float, float]:
    """``(a, b)`` of ``s(x) = x + a x^2 + b x^3`` (see module docstring)."""
    if not (R > 0 and T > 0):
        raise ValueError("sigmoid needs R > 0 and T > 0")
    tau = T / R
    if not (1.0 / 3.0 <= tau <= 2.0):
        raise ValueError(f"threshold T must be in [R/3, 2R] for a monotone sigmoid (got T/R = {tau:.3g})")
    return (3.0 * T - 2.0 * R) / R ** 2, (R - 2.0 * T) / R ** 3


def sigmoid_slope(R: float, T: float) -> float:
    """``S_SIGMA``: the largest slope of ``s`` (see module docstring)."""
    c = 6.0 * T / R - 3.0
    return max(1.0, (c + 1.0) ** 2 / (4.0 * c)) if c >= 1.0 else 1.0


def sigmoid_np(x, R: float, T: float):
    """``s(x)`` on numpy values: odd, ``+-T`` beyond ``+-R``."""
    a, b = sigmoid_coefficients(R, T)
    x = np.asarray(x, dtype=np.float64)
    m = np.minimum(np.abs(x), R)
    return np.sign(x) * (m + a * m * m + b * m * m * m)


def sigmoid_dr(x, R, a, b):
    """``s(x)`` in Dr.Jit; ``R``, ``a``, ``b`` are opaque ``mi.Float``."""
    m = dr.minimum(dr.abs(x), R)
    return dr.copysign(m + m * m * (a + b * m), x)
