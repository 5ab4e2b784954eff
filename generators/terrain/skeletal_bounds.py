"""Per-primitive bounds of a :class:`~.skeletal_set.SkeletalSet`: distances to level sets and local slopes.

The functions take the set (``node``), primitive ``k``'s constants ``prim`` (a
:class:`.skeletal_records.Primitive`: energy ``e``, radii, the bounds' factors) and its
``geometry`` at ``p`` (``(g, rho, r, D)`` from the set's falloff:
``rho = max(r - c, 0)``, ``r`` the distance to the skeleton, ``D`` the star radius,
exact where the noise was evaluated, ``D_max`` elsewhere). The set's loop over a
point's list combines them (minimum, maximum or sum); the notation is that of
:mod:`.skeletal_set`.

Distance bounds below the threshold (levels ``c`` with ``u = threshold - c > 0``, the
set ``{F >= u}``; the sum's caps ask for them, see :mod:`.operators`). Hart's bound
is poor there: ``|grad F|`` reaches ``e G_SLOPE / D`` (30 for the hoodoos preset), so
the bounds are geometric, per primitive. For ``"max"``, ``{F >= u}`` is the union of
``{F_i >= u} = {rho <= x D}``, ``x = sqrt(1 - (u / e_i)^(1/3))`` (none if ``e_i < u``);
for ``"sum"`` only ``F_i > 0`` is implied, ``x = 1``, over the positive energies. Then

    d_i >= rho(p) - x D_max                                   (D <= D_max), and
    d_i >= min(r / 2, (rho(p) - x D(p)) / (1 + x L_D))         (with the noise at p),

the second because within ``r/2`` of ``p``, ``rho`` is 1-Lipschitz and
``|grad D| <= L_D = R A L_n / lambda (sigma_s + 2 (c + R) / r)`` (the slope bound
above with ``r >= r(p) / 2``). It matters in the noise's margin, between the noisy
surface and its ``D_max`` envelope, where rays graze. The loop runs over *near* lists
(support boxes grown by ``m``, ``NEAR_REACH`` cell edges), so ``d >= min(G, min_i d_i)``, ``G >= m``
the cell's gap to the nearest support left out of its near list
(:func:`~arches_render.field.primitive_set.unlisted_gaps`, up to ``UNLISTED_REACH`` cell
edges), and at least the empty-cell distance; outside the grid, the distance to the box
of all supports; ``FAR`` above ``value_max``.

Local slopes (issue 21; :meth:`SkeletalSet.eval_local`). The cell bounds above sum
``|e| G_SLOPE L_i`` over every primitive near a cell, about ten times the true
gradient at a cave wall, where a primitive's falloff is far from its steepest point.
Within the ball ``B(p, rad)``, ``rad`` at most ``local_radius`` (``SLOPE_REACH`` cell
edges), only the primitives of ``p``'s slope list (supports grown by that much) act, and the star distance of each stays in
``[x - rad L_i, x + rad L_i]``, ``x = min(d~(p), 1)``: ``d~`` is ``L_i``-Lipschitz where it is
below 1, and a path from ``p`` into the support enters it at ``d~ = 1``. Hence

    |grad F| <= sum_i |e_i| L_i max { |g'(u)| : u in [x_i - rad L_i, x_i + rad L_i] }

in the ball (curves: their members' maximum; ``"max"`` sets: the maximum; 0 from a primitive
whose support the ball misses, ``rho(p) - rad > D_max``), where
``|g'(u)| = 6 u (1 - u^2)^2`` rises to ``G_SLOPE`` at ``u = 1/sqrt 5`` and falls to 0 at 1
(:func:`.falloff.falloff_slope_max`). Where the noise is skipped (``rho >= D_max``)
``x = 1`` is exact too. A footprint multiplies ``L_i`` by ``1 + kappa s``.

Along a line (noise-free sets, a ray's direction ``u`` given). ``d~ = rho / R`` and ``rho``
(the distance to the segment less the core) has gradient ``grad r``, a unit vector
whose change is bounded by the distance's curvature, ``|Hess r| <= 1 / r`` (the distance
to a convex set). On the line ``p + s u``, ``|s| <= rad < r(p)``, ``r >= r(p) - rad``, so
``|d/ds d~| <= (|grad r(p) . u| + rad / (r(p) - rad)) / R``, at most ``1 / R``; that factor
replaces ``L_i`` above. A ray that runs along a channel wall (a shadow ray leaving
a river bank) sees the carving change little, and steps by the terrain's slope.

The level bounds along a line (every set that adds matter, noisy or not). ``rho`` is
convex (the distance to a convex skeleton, less ``c``, clamped at 0), so on the line
it stays above its tangent: ``rho(p + s u) >= rho(p) + s lean``, ``lean = grad r . u``
(where ``r > c``; inside the core ``rho(p) = 0`` and every bound is 0). Both sides:
``rho`` falls at most at the rate ``|lean|``; ahead only (``s > 0``,
:func:`arches_render.field.node.one_sided`): ``max(-lean, 0)``, and a ray leaving a
primitive outward never comes closer to its skeleton. With that rate ``a`` in place
of 1 the two distance bounds above become

    d_i >= (rho(p) - x D_max) / a,    d_i >= min(r / 2, (rho(p) - x D(p)) / (a + x L_D)),

so a ray grazing a hoodoo (``a`` near 0) steps by how fast its noise can swell
(``L_D``), not by how fast it could walk into the wall. On the line within ``r / 2`` of
``p``, ``r`` too stays above its tangent, ``r(q) >= r (1 - |lean| / 2)``, so the noise's
swell ``L_D`` takes ``(c + R) / (r (1 - |lean| / 2))`` in place of the ball's ``2 (c + R) / r``
(goblins: camera 38.1 -> 37.5, shadow 36.1 -> 35.3, bounce 32.6 -> 31.7 steps).

Slanted levels (a set summed with a smooth operand, :class:`.operators.Sum`). Where
a terrain ``f_T`` has a small slope bound ``L_T`` and the set adds steep matter on it
(the goblins' hoodoos: ``e = 40`` over ``R`` of 0.6-8 m, ``|grad F|`` bounded by
90-190 near their walls, true 8-30), ``f_T + F >= -c`` at ``q`` with ``|q - p| <= delta``
needs ``F(q) >= u0 - L_T delta``, ``u0 = -c - f_T(p)``. So a radius ``delta`` in which
every primitive stays below ``u0 - L_T delta`` bounds the distance to the sum's level
set, with the *geometric* slope of the level bounds above (``1 + x L_D``, about 1.5)
instead of Hart's over the falloff's steepest part. The condition is
``delta <= d_k(u0 - L_T delta)`` for each ``k``, ``d_k(u)`` a level bound (decreasing
in ``delta``, since ``x`` grows as ``u`` falls). With ``a = min(d_k(u0), cap)`` and
``b = d_k(u0 - L_T a)``: ``b <= a`` (the lower level's bound is smaller) and, for
``delta <= min(b, cap)``, ``u0 - L_T delta >= u0 - L_T a`` so ``F_k < u0 - L_T a <=
u0 - L_T delta`` in the ball. The minimum over the listed primitives, at most ``m``
(a primitive left out of the near list is 0 within it) or the empty-cell
distance, and at most ``cap < u0 / L_T`` (so the level stays positive and every
unlisted primitive, 0 there, is below it) is the bound (:func:`slanted_bound`).

Cores (carving sets, every ``e_i <= 0``). Then ``F <= F_i`` for each ``i``, so
``F >= u`` (``u < 0``) needs ``e_i g(d~_i) >= u``, i.e. ``d~_i >= x = sqrt(1 - (u/e_i)^(1/3))``
(where ``|e_i| > |u|``), i.e. ``rho_i >= x D >= x D_min``; ``rho_i`` being 1-Lipschitz,
the distance from ``p`` to ``{F >= u}`` is at least ``max_i (x D_min,i - rho_i(p))``. The
sum asks a carving set for ``u = -(c + T)`` (the terrain is at most ``T``), and this
lets rays cross the carved air of a cave or an undercut in long steps.

References
----------
Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
38(5), Sec. 3.3, 5.2.
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render.field.brick_grid import half_up
from arches_render.field.node import box_distance, one_sided_lanes
from arches_render.field.noise import fbm_lipschitz
from arches_render.field.window_filters import window_max

from .falloff import G_SLOPE, falloff_slope_max

#: Distance bound of an empty level set (finite, so that ``0 * FAR`` stays 0).
FAR = 1e10

__all__ = ["level_shape", "level_bound", "slant_cap", "slanted_bound", "core_bound", "local_slope", "footprint_error", "quiet_within",
           "below_all", "stored_tables"]


def level_shape(node, e, u, skip=False):
    """``(x, acts)`` of a primitive of energy ``e`` at the level ``u > 0`` (module
    docstring, "Distance bounds"): ``{F_k >= u}`` is ``{rho <= x D}``, and empty
    where ``acts`` is false. ``None`` for ``e`` ``None`` (primitives of different
    energies: each its own, in :func:`level_bound`) or with ``skip``."""
    if e is None or skip:
        return None
    if node.combine == "max":
        x = dr.sqrt(dr.maximum(1.0 - dr.cbrt(dr.minimum(u / dr.maximum(e, 1e-30), 1.0)), 0.0))
        return x, e >= u
    return 1.0, e > 0.0


def level_bound(node, prim, geometry, u, rate=None, shape=None):
    """Lower bound of the distance from ``p`` to ``{F_k >= u}`` (``u > 0``), or
    ``None`` where primitive ``k`` cannot reach ``u`` (module docstring, "Distance
    bounds"): returns ``(acts, bound)``; along the ray's line where ``geometry``
    holds its lean ("Along a line"), else in a ball. ``shape``: the level's
    :func:`level_shape`, computed once outside the loop over the primitives where
    they share one energy."""
    _, rho, r, D, *lean = geometry
    x, acts = level_shape(node, prim.e, u) if shape is None else shape
    bound = rho - x * prim.reach_R  # with D_max
    rate_rho = 1.0
    if lean:
        # On the ray's line rho falls no faster than its tangent line ("Along a line").
        rate_rho = line_rate(lean[0])
        bound = dr.select(bound > 0.0, dr.minimum(bound * dr.rcp(dr.maximum(rate_rho, 1e-30)), FAR), bound)
    if node.noise:
        # With the noise at p: within r/2 of p, |grad D| <= K (sigma_s + 2 (c + R) / r)
        # (+ K kappa s for a footprint's fade, module docstring).
        # Along the line, r stays above r (1 - |lean| / 2) within r / 2 (convexity), so
        # 1 / (1 - |lean| / 2) replaces the ball's 2 ("Along a line").
        shrink = 2.0 if not lean else dr.rcp(1.0 - 0.5 * dr.minimum(dr.abs(lean[0]), 1.0))
        spin = prim.seg + shrink * (prim.core + prim.R) * dr.rcp(dr.maximum(r, 1e-12))
        if rate is not None:
            spin = spin + node._lod.kappa * rate
        lip_D = prim.noise_K * spin
        local = dr.minimum(0.5 * r, (rho - x * D) * dr.rcp(dr.maximum(rate_rho + x * lip_D, 1e-30)))
        bound = dr.maximum(bound, local)
    return acts, bound


def line_rate(lean):
    """How fast ``rho`` can fall per unit length along a ray's line, from its lean
    ``grad r . u`` at ``p`` (module docstring, "Along a line"): ``|lean|`` for both
    sides, ``max(-lean, 0)`` in the lanes a tracer traces ahead only
    (:func:`arches_render.field.node.one_sided`)."""
    both = dr.abs(lean)
    lanes = one_sided_lanes()
    return both if lanes is None else dr.select(lanes, dr.maximum(-lean, 0.0), both)


#: Where a slanted bound stops: this fraction of the radius ``u0 / slope`` at which the
#: slanted level reaches 0.
SLANT_CAP = 0.75


def slant_cap(u0, slope, reach):
    """Largest radius of a slanted bound: ``SLANT_CAP u0 / slope`` (the level stays
    positive), at most ``reach`` (``None``: no limit)."""
    cap = dr.maximum(u0, 0.0) * SLANT_CAP * dr.rcp(dr.maximum(slope, 1e-12))
    return cap if reach is None else dr.minimum(cap, reach)


def slanted_bound(node, prim, geometry, u0, slope, cap, rate=None, shape=None):
    """Lower bound of the radius ``delta`` of a ball around ``p`` in which
    ``F_k(q) < u0 - slope delta`` (module docstring, "Slanted levels"), or ``FAR``
    where primitive ``k`` reaches no level of the ball. ``u0 > 0``, ``slope > 0`` and
    ``cap`` (the largest radius the caller accepts, ``< u0 / slope``) per lane.

    Two passes of :func:`level_bound`: ``a = min(d_k(u0), cap)``, then ``d_k(u0 - slope a)``.
    Along a ray's line both passes are the line's: its longer ``a`` lowers the second
    pass's level, so the result may be shorter than a ball's (a quarter of the points
    by the goblins-like pillars of ``tests/test_slanted_levels.py``), yet over the
    goblins' rays the line's took 5-7 % fewer steps; keeping the better of both cost
    a third pass per primitive and more time than it saved."""
    acts, first = level_bound(node, prim, geometry, u0, rate, shape)
    a = dr.select(acts, dr.clip(first, 0.0, cap), cap)
    acts, second = level_bound(node, prim, geometry, u0 - slope * a, rate)
    return dr.select(acts, second, FAR)


def core_bound(node, prim, geometry, u):
    """Carving sets (every ``e <= 0``): a lower bound of the distance from ``p`` to
    ``{F >= u}`` (``u < 0``) from primitive ``k`` alone (module docstring, "Cores"):
    ``x D_min - rho`` with ``x = sqrt(1 - (u / e)^(1/3))``, 0 where ``|e| <= |u|``."""
    _, rho, *_ = geometry
    x = dr.sqrt(dr.maximum(1.0 - dr.cbrt(dr.minimum(u * dr.rcp(dr.minimum(prim.e, -1e-30)), 1.0)), 0.0))
    return dr.maximum(x * prim.Dmin - rho, 0.0)


def local_slope(node, prim, geometry, radius, rate=None):
    """Bound of ``|grad F_k|`` in the ball of radius ``radius`` around ``p``
    (module docstring, "Local slopes"): ``|e| max |g'| L_k`` over the star
    distances the ball can hold; with the line's ``along`` in ``geometry`` (noise-free
    sets), of the derivative along the line within ``radius`` ("Along a line")."""
    _, rho, r, D, *along = geometry
    Ld = prim.Ld
    if along and not node.noise:
        # |grad r . u| moves by at most |q - p| / (r(p) - |q - p|) along the line.
        turn = dr.select(r > 2.0 * radius, radius * dr.rcp(dr.maximum(r - radius, 1e-30)), 1.0)
        Ld = Ld * dr.minimum(dr.abs(along[0]) + turn, 1.0)
    if rate is not None:
        Ld = Ld * (1.0 + node.lod_kappa * rate)
    # d~ at p (D is exact where the noise was evaluated; D_max elsewhere, where
    # rho >= D_max and the clamp to 1 makes it exact too).
    x = dr.minimum(rho * dr.rcp(dr.maximum(D, 1e-30)), 1.0)
    slope = dr.abs(prim.e) * falloff_slope_max(x - radius * Ld, x + radius * Ld) * Ld
    # A ball that misses the support (rho 1-Lipschitz: rho > D_max in all of it) has
    # slope 0 from this primitive. Without this, every primitive of a cell's slope list
    # counted as if the ball touched its support: a Jacksboro channel wall summed
    # 14 against the one acting primitive's 4.75.
    D_max = prim.R * node._reach if node.noise else prim.R
    return dr.select(rho - radius > D_max, 0.0, slope)


def footprint_error(node, radius):
    """Bound of ``|F_fp - F|`` for footprints up to ``radius`` (a float): a truncated star
    noise moves ``D`` by at most ``R A dn`` (``dn`` the unit noise's truncation error), so
    ``d~ = rho / D`` by at most ``D_max R A dn / D_min^2`` inside the support, and each
    primitive's value by ``|e| G_SLOPE A dn (1 + span) / (1 - span)^2``; a point sums at
    most ``value_max - value_min`` of energy (``value_max`` for ``"max"``)."""
    if not node.noise:
        return 0.0
    nz = node.noise
    span = nz["span"]
    per_energy = G_SLOPE * nz["amplitude"] * node._lod.error_within(radius) * (1.0 + span) / (1.0 - span) ** 2
    return per_energy * (node.value_max if node.combine == "max" else node.value_max - node.value_min)


def quiet_within(node, p, reach):
    """Whether no primitive's support lies within ``reach`` of the points ``p``: the 3x3x3
    slope table of their cell is 0 (it covers one cell edge around it), or they are
    farther than ``reach`` from the grid that holds every support."""
    cell, stored, _, inside = node._cell(p)
    quiet = inside & (dr.gather(node._table, node._cell_L, cell, stored) == 0.0) & (reach <= node.cell)
    return quiet | (~inside & (box_distance(p, node._glo_box[0], node._glo_box[1]) > reach))


def below_all(threshold, c) -> bool:
    """Whether the level ``{f >= -c}`` of a set that adds matter holds every point, known
    before tracing: ``c`` a number with ``u = threshold - c < 0`` (a sum asks its sets at
    its other operands' maximum, far below). The set's final selects keep Hart's bound
    alone for such a level, so the loop over the primitives need not compute its
    geometric bounds (renders are bitwise the same)."""
    return isinstance(c, (int, float)) and threshold - c < -1e-6 * max(1.0, abs(c))


def distance_slopes(node):
    """``L_i`` (float64, per primitive): the slope bound of the star distance ``d~`` of each
    primitive of the set ``node`` inside its support (:mod:`.skeletal_set`, "Lipschitz bound")."""
    R, c = node.radius_np, node.core_np
    if not node.noise:
        return 1.0 / R
    nz = node.noise
    span = nz["span"]
    slope_n = fbm_lipschitz(int(nz["octaves"]), nz["lacunarity"], nz["gain"]) / nz["wavelength"]
    dmin, dmax = R * (1.0 - span), R * (1.0 + span)
    segment = (np.linalg.norm(node.b_np - node.a_np, axis=1) > 0).astype(np.float64)
    return 1.0 / dmin + R * nz["amplitude"] * slope_n * (segment * dmax + c + R) / dmin ** 2


def cell_tables(node, prim_slope, start, count, index):
    """The set's per-cell slope and value bounds (:mod:`.skeletal_set`, "Lipschitz bound"
    and "Local bounds").

    Parameters
    ----------
    node : SkeletalSet
        The set (its energies, groups, combination and grid).
    prim_slope : ndarray
        ``|e_i| G_SLOPE L_i`` per primitive.
    start, count, index : ndarray
        The dense CSR cell lists (support boxes).

    Returns
    -------
    (cell_L, cell_M, lipschitz, value_max, value_min)
        Per cell (dense, ``(z, y, x)`` order), the 3x3x3-neighbourhood maxima of the
        summed slope bounds and of the summed positive energies (per group maxima;
        ``"max"``: maxima); the largest sum of slopes, and the range of ``F``.
    """
    e = node.energy_np
    n_cells = len(count)
    cell_of = np.repeat(np.arange(n_cells), count)
    if node.combine == "max":
        cell_l = np.zeros(n_cells)
        cell_m = np.zeros(n_cells)
        np.maximum.at(cell_l, cell_of, prim_slope[index])
        np.maximum.at(cell_m, cell_of, np.maximum(e[index], 0.0))
        cell_lo = np.zeros(n_cells)
    else:
        grp = node.group_np[index]
        # Entries of one (cell, group) are contiguous: reduce each run.
        run = np.r_[True, (cell_of[1:] != cell_of[:-1]) | (grp[1:] != grp[:-1])]
        starts = np.flatnonzero(run)
        run_cell = cell_of[starts]
        run_e = e[index][starts]
        cell_l = np.bincount(run_cell, np.maximum.reduceat(prim_slope[index], starts), minlength=n_cells)
        cell_m = np.bincount(run_cell, np.maximum(run_e, 0.0), minlength=n_cells)
        cell_lo = np.bincount(run_cell, np.minimum(run_e, 0.0), minlength=n_cells)
    shape = tuple(int(v) for v in node.res[::-1])  # (z, y, x) as the cell index
    return (window_max(cell_l.reshape(shape), 3).ravel(), window_max(cell_m.reshape(shape), 3).ravel(),
            float(cell_l.max()), float(cell_m.max()), float(cell_lo.min()))


def stored_tables(cell_l, cell_m):
    """The cell tables of :func:`cell_tables` as a set stores them: ``(L, M, dtype)``.

    float32 grown by a part in 10^6 (the float32 rounding of their sums), then float16
    rounded up where both fit (:func:`~arches_render.field.brick_grid.half_up`: 2 bytes
    a cell each, and the bounds they give grow by at most a part in 1024), the Dr.Jit
    type ``mi.Float16``; else float32, ``mi.Float``.
    """
    L = cell_l.astype(np.float32) * np.float32(1.0 + 1e-6)
    M = cell_m.astype(np.float32) * np.float32(1.0 + 1e-6)
    halves = half_up(L), half_up(M)
    if any(h is None for h in halves):
        return L, M, mi.Float
    return halves[0], halves[1], mi.Float16
