"""Local slope bounds: the part of the node protocol that bounds a field's slope in a ball.

A node's global Lipschitz bound ``L`` holds everywhere; a crowded cluster of
primitives makes it large for the whole tree. Nodes that know better bound their
slope in a ball around a point:

``local_lipschitz(p)``
    ``(L, value_max, r)``: a slope bound valid within the radius ``r`` of ``p``
    (a grid of primitives answers from the cells around ``p``'s).
``eval_local(p, levels, direction, footprint, radii)``
    ``(f, ds, slopes)``: ``eval_bounds`` and, for each radius of ``radii`` (floats
    or per-lane ``mi.Float``), a bound of the slope of the (footprint) field in
    the ball of that radius around ``p``, from one evaluation.

The functions below ask a node for them when it has them and fall back on what
every node has (its global bound) when it does not, so callers (operators that
sum slopes, a tracer, a structure that classifies cells) need not know which
node answers. Every bound is rigorous: a ball's slope bound is never measured.

References
----------
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
38(5), Sec. 6.
"""

from __future__ import annotations

import drjit as dr

__all__ = ["local_lipschitz", "eval_local", "local_hart"]


def local_lipschitz(node, p):
    """``(L, r)``: a slope bound of ``node`` valid in the ball of radius ``r`` around ``p``
    (``r = None``: everywhere). Nodes that know better define ``local_lipschitz``."""
    own = getattr(node, "local_lipschitz", None)
    local = None if own is None else own(p)
    if local is None:
        return node.lipschitz, None
    L, _, r = local
    return L, r


def eval_local(node, p, levels, direction=None, footprint=None, radii=()):
    """``(f, ds, slopes)``: ``node.eval_bounds`` and, for each radius of ``radii``, a
    bound of the slope of ``node``'s (footprint) field in the ball of that radius
    around ``p``. Nodes that know local slopes define ``eval_local`` (one pass for
    value, bounds and slopes); for the others the slope is their
    :func:`local_lipschitz` where its ball holds the radius, else their global one."""
    own = getattr(node, "eval_local", None)
    if own is not None:
        return own(p, levels, direction, footprint, radii)
    f, ds = node.eval_bounds(p, levels, direction, footprint)
    if not radii:
        return f, ds, ()
    L, r = local_lipschitz(node, p)
    L_glob = node.lipschitz
    if footprint is not None and node.lod_kappa:
        grow = 1.0 + node.lod_kappa * footprint.rate
        L, L_glob = L * grow, L_glob * grow
    slopes = tuple(L if r is None else dr.select(r >= rad, L, L_glob) for rad in radii)
    return f, ds, slopes


def local_hart(f, levels, L, r, L_global):
    """Distance bounds ``max(min(r, (-f - c)/L), (-f - c)/L_global)`` for each level."""
    out = []
    for c in levels:
        gap = dr.maximum(-f - c, 0.0)
        d = gap * (1.0 / L_global)
        if r is not None:
            d = dr.maximum(d, dr.minimum(gap * dr.rcp(dr.maximum(L, 1e-12)), r))
        out.append(d)
    return tuple(out)
