"""Blend weights of the triplanar material: projections, stacked layers, bands.

Plain Dr.Jit functions on arrays, shared by the BSDF (:mod:`.triplanar`) and its
tests.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Below this a soft width means a hard step; also keeps the ramps free of 0/0.
MIN_SOFT = 1e-6

__all__ = ["triplanar_weights", "composite_weights", "smoothstep01", "band"]


def triplanar_weights(n, sharpness):
    """Projection blend weights of the three axis projections.

    Parameters
    ----------
    n : mi.Vector3f
        Unit shading normal.
    sharpness : mi.Float or float
        Blend exponent ``s >= 1``.

    Returns
    -------
    mi.Vector3f
        ``(b_x, b_y, b_z)`` with ``b_k = |n_k|^s / sum_j |n_j|^s``.

    References
    ----------
    Peytavie et al. (2009), section 6, "Texturing terrains of arbitrary geometry".
    """
    a = dr.abs(mi.Vector3f(n))
    # Dividing by the largest component first keeps a^s away from underflow
    # for large exponents (the largest term becomes exactly 1).
    a = a / dr.maximum(dr.max(a), 1e-20)
    a = dr.power(a, sharpness)
    return a / (a.x + a.y + a.z)


def composite_weights(coverages):
    """Paint-style compositing weights of stacked layers.

    Parameters
    ----------
    coverages : list of mi.Float
        Coverage ``c_i`` of each layer, bottom first; ``c_0`` is taken as 1.

    Returns
    -------
    list of mi.Float
        ``w_i = c_i prod_{j>i} (1 - c_j)``; they sum to 1.
    """
    weights = [None] * len(coverages)
    uncovered = mi.Float(1.0)
    for i in range(len(coverages) - 1, 0, -1):
        weights[i] = coverages[i] * uncovered
        uncovered = uncovered * (1.0 - coverages[i])
    weights[0] = uncovered
    return weights


def smoothstep01(t):
    """``3t^2 - 2t^3`` of ``t`` clamped to ``[0, 1]``."""
    t = dr.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def band(x, lo, hi, soft):
    """1 on ``[lo, hi]``, smoothstep fall-off to 0 over ``soft`` outside."""
    inv = dr.rcp(dr.maximum(soft, MIN_SOFT))
    return smoothstep01((x - lo) * inv + 1.0) * smoothstep01((hi - x) * inv + 1.0)
