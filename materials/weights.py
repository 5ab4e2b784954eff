"""Blend weights of the triplanar material: projections, stacked layers, bands.

Plain Dr.Jit functions on arrays, shared by the BSDF (:mod:`.triplanar`) and its
tests.

Skipping negligible projections (biplanar where it is enough). With the blend
exponent ``s = 8`` of the paper most normals give one or two projections nearly
all the weight: ``b_k < 10^-4`` as soon as ``|n_k| < 0.32 max_j |n_j|``. Per
shading point the three projections are ranked by weight (slot 0 the largest,
slot 2 the smallest; :func:`projection_slots`) and a slot whose weight is below
:data:`MIN_PROJECTION` is dropped, the others renormalised:

    T' = sum_{k kept} b_k T_k / sum_{k kept} b_k,
    T - T' = sum_{k dropped} b_k (T_k - T'),   |T - T'| <= 2 MIN_PROJECTION max_k |T_k - T'|

(at most two slots dropped): under 2 10^-4 of the texture's range. A slot is a
symbolic branch (:func:`blend_projections`): a SIMD packet in which no lane needs
it skips its lookups, so flat ground and plain cliffs cost one or two projections
instead of three. Ranking by weight rather than by axis lets a packet of mixed
orientations (a cliff's foot) skip the third slot too.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Below this a soft width means a hard step; also keeps the ramps free of 0/0.
MIN_SOFT = 1e-6
#: Projections lighter than this are dropped (module docstring: error < 2e-4 of the range).
MIN_PROJECTION = 1e-4

__all__ = ["MIN_PROJECTION", "triplanar_weights", "projection_slots", "blend_projections", "composite_weights",
           "smoothstep01", "band"]


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


def _pick(k, v):
    """Component ``k`` (a per-lane index 0, 1, 2) of the 3-vector ``v``."""
    return dr.select(k == 0, v.x, dr.select(k == 1, v.y, v.z))


def projection_slots(p, b):
    """The three projections of ``p`` ranked by weight (module docstring).

    Parameters
    ----------
    p : mi.Point3f
        Shading position.
    b : mi.Vector3f
        Projection weights (:func:`triplanar_weights`).

    Returns
    -------
    list of (mi.Point2f, mi.Float)
        ``(uv_k, b_k)`` per slot, heaviest first, with ``uv_x = (p.y, p.z)``,
        ``uv_y = (p.x, p.z)``, ``uv_z = (p.x, p.y)``.
    """
    # First maximum and last minimum: distinct axes even where weights tie.
    top = dr.select(b.x >= b.y, dr.select(b.x >= b.z, 0, 2), dr.select(b.y >= b.z, 1, 2))
    low = dr.select(b.x < b.y, dr.select(b.x < b.z, 0, 2), dr.select(b.y < b.z, 1, 2))
    top, low = mi.UInt32(top), mi.UInt32(low)
    slots = []
    for k in (top, 3 - top - low, low):
        uv = mi.Point2f(dr.select(k == 0, p.y, p.x), dr.select(k == 2, p.y, p.z))
        slots.append((uv, _pick(k, b)))
    return slots


def blend_projections(lookup, slots, active=True):
    """``sum_k b_k T_k / sum_k b_k`` over the slots heavier than :data:`MIN_PROJECTION`.

    Parameters
    ----------
    lookup : callable
        ``lookup(uv, active) -> mi.Color3f``, the texture of one projection.
    slots : list of (mi.Point2f, mi.Float)
        :func:`projection_slots`.
    active : mi.Bool
        Lanes to compute (the branches' condition; the heaviest slot's lookup mask).

    Returns
    -------
    mi.Color3f
        The blend; slots 1 and 2 are symbolic branches, skipped by packets in which
        every lane's weight is below the threshold (slot 0, the heaviest, is
        always at least 1/3).
    """
    active = mi.Bool(active)
    uv0, b0 = slots[0]
    out, wsum = lookup(uv0, active) * b0, mi.Float(b0)
    for uv, w in slots[1:]:
        def add(out, wsum, uv, w):
            return out + lookup(uv, mi.Bool(True)) * w, wsum + w

        out, wsum = dr.if_stmt((out, wsum, uv, w), active & (w > MIN_PROJECTION), add,
                               lambda out, wsum, uv, w: (out, wsum), label="triplanar_slot")
    return out * dr.rcp(dr.maximum(wsum, 1e-20))


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
