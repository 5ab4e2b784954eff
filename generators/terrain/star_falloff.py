"""The falloff of one skeletal primitive at a point: its anisotropic star distance.

For the primitive ``prim`` (a :class:`.skeletal_records.Primitive`) of the set ``node``
(:class:`.skeletal_set.SkeletalSet`, whose module docstring states the math): the
projection ``s`` of ``p`` on the skeleton, ``r = |p - s|``, ``rho = max(r - c, 0)``, the
star radius ``D(p) = R (1 + A n(v(p) / lambda))`` with the noise read on the boundary
point ``v(p) = s + (c + R) u(p)``, and ``g(rho / D)``. The noise is evaluated only where
``rho < R (1 + A N)`` (beyond, ``g = 0``).

References
----------
Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
38(5), Sec. 3.3 (falloff), 5.2 (anisotropic star noise).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from arches_render.field.noise import fbm

from .falloff import g_dr

__all__ = ["star_falloff"]


def star_falloff(node, p, prim, geometry=False, level=None, direction=None):
    """``g(d~)`` of the primitive ``prim`` of the set ``node`` at ``p`` (a value in
    [0, 1]); with ``geometry``, ``(g, rho, r, D)``: also
    ``rho = max(r - c, 0)``, the distance ``r`` to the skeleton and the star radius
    ``D(p)`` (``D_max`` where the noise is skipped), and with a ``direction`` ``u``
    the lean ``grad r . u`` (signed) after them. ``level``: the star noise's
    footprint level (``None``: every octave)."""
    a, ba, R, core = prim.a, prim.ba, prim.R, prim.core
    pa = p - a
    t = dr.clip(dr.dot(pa, ba) * prim.inv_len2, 0.0, 1.0)
    s = a + ba * t
    off = p - s
    r = dr.norm(off)
    rho = dr.maximum(r - core, 0.0)
    lean = () if direction is None else (dr.dot(off, direction) * dr.rcp(dr.maximum(r, 1e-30)),)
    if not node.noise:
        g = g_dr(dr.square(rho / R))
        return (g, rho, r, R, *lean) if geometry else g

    def noisy(rho, R, core, s, off, r, group, *lvl):
        u = off / dr.maximum(r, 1e-12)
        v = s + (core + R) * u
        seed = node._seed + group * 7919
        n = fbm(v * node._inv_wl, int(node.noise["octaves"]), node._lac, node._gain, seed, *lvl)
        D = R * (1.0 + node._amp * n)
        return g_dr(dr.square(rho / D)), D

    def far(rho, R, core, s, off, r, group, *lvl):
        return mi.Float(0.0), R * node._reach

    lvl = () if level is None else (level,)
    g, D = dr.if_stmt((rho, R, core, s, off, r, prim.group, *lvl), rho < R * node._reach, noisy, far,
                      label="star_noise")
    return (g, rho, r, D, *lean) if geometry else g
