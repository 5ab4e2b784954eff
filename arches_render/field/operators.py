"""Boolean and smooth operators.

With ``f > 0`` inside, union is ``max``, intersection is ``min`` and difference is
``min(a, -b)``; each is Lipschitz with the largest bound of its operands.

The smooth blend uses the polynomial smooth maximum of radius ``k`` (metres):

    smax_k(a, b) = max(a, b) + k h^2 / 4,    h = max(k - |a - b|, 0) / k,

whose partial derivatives are non-negative and sum to one, so it keeps the
Lipschitz bound ``max(L_a, L_b)``; it moves the surface outward by at most ``k/4``
where the operands meet. The smooth intersection is ``-smax_k(-a, -b)``.

Local distance bounds (``eval_bounds`` at level ``c``, the set ``{f >= -c}``): for a
union it is the union of the operands' sets, so ``d = min_i d_i(c)``; for an
intersection it lies inside every operand's, so ``d = max_i d_i(c)``; for ``a - b``
it lies inside ``{a >= -c}`` and ``{b <= c}``, so ``d = max(d_a(c), (f_b - c) / L_b)``.

Smooth blend of ``n`` operands (folded ``g_j = smax_k(g_{j-1}, f_j)``). Suppose
``g_n >= -c`` while every ``f_i < -c``. Take the last fold step ``j`` whose seam was
active (``|g_{j-1} - f_j| < k``; there is one, or ``g_n = max f_i``). Later steps are
plain maxima, so ``g_j >= -c``; since ``g_j <= max(g_{j-1}, f_j) + k/4``, both
``f_j`` and ``g_{j-1}`` are ``>= -c - 5k/4``, and ``g_{j-1} <= max_{i<j} f_i + (n-2)k/4``.
So two distinct operands reach ``-c'`` with ``c' = c + (n + 3) k / 4``, and

    d >= min( min_i d_i(c),  second-smallest_i d_i(c') ),

which near one operand, far from the others, is that operand's own bound.

Caps of a two-operand blend. ``smax_k`` is non-decreasing in each operand, so where
``b < v`` (a *cap*, ``v < -c``), ``smax_k(a, b) >= -c`` needs ``smax_k(a, v) >= -c``, i.e.
``a >= -c - (sqrt k - sqrt delta)^2`` with ``delta = -c - v`` (for ``delta < k``; solving
``max(a, v) + (k - |a - v|)^2 / (4k) = -c`` on either side of ``a = v`` gives the same root;
for ``delta >= k`` the seam cannot reach the level and ``a >= -c``). With ``v = -c - k
CAP_BELOW``, ``b < v`` holds within ``d_b(c + k CAP_BELOW)`` of ``p``, so

    d >= min(d_b(c + k CAP_BELOW), d_a(c + k CAP_SHIFT)),   CAP_SHIFT = (1 - sqrt CAP_BELOW)^2,

and the same with the roles exchanged. It matters where one operand saturates a
little below the level: an implicit terrain is ``-T`` in all of its air, within a
blend radius ``k = T`` of an arch's surface values, so the ``(n + 3) k / 4`` shift above
reaches below ``-T`` and left rays at the arch only Hart's bound with the terrain's
large ``L`` (the arch bridge: 160 shadow steps a ray). The caps are asked at each
``CAP_BELOW`` of :data:`CAP_LEVELS`: a low one applies where the other operand is only
partly saturated, one close to 1 shifts this operand's level by almost nothing where
the other is saturated at ``-k`` (a ray leaving the arch within ``CAP_SHIFT k`` of its
surface, i.e. every shadow and bounce ray, gets no cap from the low one). Blends of operands with unit
falloff (distance-like values that keep falling away from them) do without: their
caps cost 7 % of the default scene's field render and bought nothing there.

Local slopes of a blend. ``smax_k``'s partial derivatives are non-negative and sum to
one, so at every point ``|grad smax_k(a, b) . e| <= max(|grad a . e|, |grad b . e|)``:
in a ball where the operands' slopes (along a ray's line, where they give those) are at
most ``S_a`` and ``S_b`` the blend's is at most ``max(S_a, S_b)``, and Hart's bound in
the ball of radius ``rho`` is ``min((-v - c) / max(S_a, S_b), rho)``. The blend asks
its operands for their slopes in the balls they bound themselves
(:attr:`Blend.slope_radii`): in a seam, where the free lengths of the fold above
are short, the global ``L`` was a sum's over a whole scene (the arch bridge's rays
leaving the arch stepped with 27.9, the river set's 20.5 with the terrain's 7.4, where
no primitive acts and the operands' slopes are below 2.5 and 7.4).

References
----------
Quilez, I. (2013). Smooth minimum. https://iquilezles.org/articles/smin/
Ricci, A. (1973). A constructive geometry for computer graphics. The Computer
Journal, 16(2), 157-160.
"""

from __future__ import annotations

import drjit as dr

from .local_slopes import eval_local
from .lod import lod_lipschitz
from .node import Node, box_intersection, box_union, hart_bounds, opaque_float


#: Caps of a two-operand blend (module docstring), as ``(CAP_BELOW, CAP_SHIFT)`` pairs:
#: where the other operand is below ``-c - CAP_BELOW k``, this one's level moves by
#: ``CAP_SHIFT k = (1 - sqrt(CAP_BELOW))^2 k``. 0.875 (shift 0.0042 k) serves operands a
#: little above their saturation; 0.99 (shift 2.5e-5 k) serves rays that leave a surface
#: next to a saturated operand: arch bridge shadow steps 83 -> 42 a ray (p99 871 -> 229;
#: 0.99 alone: 44, 253, and camera p99 117 -> 129, which the pair keeps at 114).
CAP_LEVELS = tuple((below, (1.0 - below ** 0.5) ** 2) for below in (0.875, 0.99))


def smooth_max(a, b, k):
    """Polynomial smooth maximum of radius ``k`` (see module docstring)."""
    h = dr.maximum(k - dr.abs(a - b), 0.0) / k
    return dr.maximum(a, b) + h * h * k * 0.25


class _NAry(Node):
    def __init__(self, *children):
        if len(children) < 1:
            raise ValueError(f"{self.kind} needs at least one operand")
        self.children = tuple(children)

    @property
    def lipschitz(self):
        return max(c.lipschitz for c in self.children)


class _Lattice(_NAry):
    """Union or intersection: one combinator for values, its dual for distances."""

    def box_range(self, lo, hi):
        # max and min are monotone in every operand: apply them to the ends.
        a, b = self.children[0].box_range(lo, hi)
        for c in self.children[1:]:
            ca, cb = c.box_range(lo, hi)
            a, b = self._value(a, ca), self._value(b, cb)
        return a, b

    def eval(self, p):
        v = self.children[0].eval(p)
        for c in self.children[1:]:
            v = self._value(v, c.eval(p))
        return v

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        f, ds = self.children[0].eval_bounds(p, levels, direction, footprint)
        for c in self.children[1:]:
            fc, dc = c.eval_bounds(p, levels, direction, footprint)
            f, ds = self._value(f, fc), tuple(self._distance(a, b) for a, b in zip(ds, dc))
        return f, ds


class Union(_Lattice):
    """``max`` of the operands; as far as the nearest operand."""

    kind = "union"

    @staticmethod
    def _value(a, b):
        return dr.maximum(a, b)

    @staticmethod
    def _distance(a, b):
        return dr.minimum(a, b)

    def bounds(self):
        return box_union([c.bounds() for c in self.children])


class Intersection(_Lattice):
    """``min`` of the operands; as far as the farthest operand."""

    kind = "intersection"
    # Outside the intersected box the field falls only as fast as the nearest
    # operand's own box: no unit falloff from this (smaller) box.
    unit_falloff = False

    _value = staticmethod(Union._distance)
    _distance = staticmethod(Union._value)

    def bounds(self):
        return box_intersection([c.bounds() for c in self.children])


class Difference(_NAry):
    """First operand minus the union of the others: ``min(a, -b, -c, ...)``."""

    kind = "difference"

    def __init__(self, *children):
        if len(children) < 2:
            raise ValueError("difference needs at least two operands")
        super().__init__(*children)

    def eval(self, p):
        v = self.children[0].eval(p)
        for c in self.children[1:]:
            v = dr.minimum(v, -c.eval(p))
        return v

    def box_range(self, lo, hi):
        a, b = self.children[0].box_range(lo, hi)
        for c in self.children[1:]:
            ca, cb = c.box_range(lo, hi)
            a, b = dr.minimum(a, -cb), dr.minimum(b, -ca)
        return a, b

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        # The subtracted operands keep full detail (``eval``): their bound needs
        # their true value, which a culled subtree's far answer is not.
        f, ds = self.children[0].eval_bounds(p, levels, direction, footprint)
        for c in self.children[1:]:
            rad = getattr(c, "local_radius", None) if levels else None
            if rad is None:
                fc = c.eval(p)
            else:
                # Hart's bound in the ball (or on the line) where the operand's slope is
                # at most S: its complement {c <= lv} is that far, or the ball's radius.
                fc, _, (S,) = eval_local(c, p, (), direction, None, (rad,))
            f = dr.minimum(f, -fc)
            inv = 1.0 / c.lipschitz
            ds = tuple(dr.maximum(d, dr.maximum(fc - lv, 0.0) * inv) for d, lv in zip(ds, levels))
            if rad is not None:
                local = dr.rcp(dr.maximum(S, 1e-12))
                ds = tuple(dr.maximum(d, dr.minimum(dr.maximum(fc - lv, 0.0) * local, rad))
                           for d, lv in zip(ds, levels))
        return f, ds

    def bounds(self):
        return self.children[0].bounds()


class Blend(_NAry):
    """Smooth union with blend radius ``radius`` (metres), folded left to right."""

    kind = "blend"

    def __init__(self, *children, radius=1.0):
        super().__init__(*children)
        if not radius > 0:
            raise ValueError("blend radius must be > 0")
        self.radius_np = float(radius)
        self.radius = opaque_float(radius)

    def eval(self, p):
        v = self.children[0].eval(p)
        for c in self.children[1:]:
            v = smooth_max(v, c.eval(p), self.radius)
        return v

    def box_range(self, lo, hi):
        # smax_k is non-decreasing in both arguments (module docstring).
        a, b = self.children[0].box_range(lo, hi)
        for c in self.children[1:]:
            ca, cb = c.box_range(lo, hi)
            a, b = smooth_max(a, ca, self.radius), smooth_max(b, cb, self.radius)
        return a, b

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        m = len(levels)
        seam = self.radius * ((len(self.children) + 3) * 0.25)
        asked = tuple(levels) + tuple(c + seam for c in levels)
        # Caps cost two more levels in every operand; they pay only next to an operand
        # that saturates (no unit falloff: an implicit terrain, a sum with primitives).
        capped = len(self.children) == 2 and not all(c.unit_falloff for c in self.children)
        if capped:
            # Caps (module docstring): each operand's own level c + sigma, and the
            # level below which it leaves the other operand's seam nearly idle.
            for below, shift in CAP_LEVELS:
                asked += tuple(c + shift * self.radius for c in levels)
                asked += tuple(c + below * self.radius for c in levels)
        radii = self.slope_radii if levels else ()
        v, answers, slopes = None, [], None
        for child in self.children:
            if radii:
                fc, dc, sc = eval_local(child, p, asked, direction, footprint, radii)
                # smax_k keeps the larger of its operands' slopes (local slopes above).
                slopes = sc if slopes is None else tuple(dr.maximum(a, b) for a, b in zip(slopes, sc))
            else:
                fc, dc = child.eval_bounds(p, asked, direction, footprint)
            answers.append(dc)
            if v is None:
                v, own, first, second = fc, list(dc[:m]), list(dc[m:2 * m]), [dr.inf] * m
                continue
            v = smooth_max(v, fc, self.radius)
            for i in range(m):
                own[i] = dr.minimum(own[i], dc[i])
                second[i] = dr.minimum(second[i], dr.maximum(first[i], dc[m + i]))
                first[i] = dr.minimum(first[i], dc[m + i])
        hart = hart_bounds(v, levels, lod_lipschitz(self, footprint))
        for S, rad in zip(slopes or (), radii):
            # Hart's bound in the ball of radius rad, where the blend's slope is at most S.
            inv = dr.rcp(dr.maximum(S, 1e-12))
            hart = tuple(dr.maximum(h, dr.minimum(dr.maximum(-v - c, 0.0) * inv, rad)) for h, c in zip(hart, levels))
        ds = [dr.maximum(dr.minimum(o, s2), h) for o, s2, h in zip(own, second, hart)]
        if capped:
            a, b = answers
            for j in range(len(CAP_LEVELS)):
                shifted, below = (2 + 2 * j) * m, (3 + 2 * j) * m
                for i in range(m):
                    # Within d_other(c + CAP_BELOW k) the other operand is below its cap.
                    ds[i] = dr.maximum(ds[i], dr.maximum(dr.minimum(b[below + i], a[shifted + i]),
                                                         dr.minimum(a[below + i], b[shifted + i])))
        return v, tuple(ds)

    @property
    def slope_radii(self):
        """Radii of the balls in which the blend bounds its slope by its operands' local
        slopes (module docstring, "Local slopes"): those its operands use themselves
        (a sum's or an erosion's ``slope_radii``, a primitive set's ``local_radius``
        and an eighth of it), the first operand's that has any; ``()`` when none has."""
        for c in self.children:
            rs = tuple(getattr(c, "slope_radii", ()) or ())
            if not rs and getattr(c, "local_radius", None):
                rs = (float(c.local_radius), float(c.local_radius) / 8.0)
            if rs:
                return rs
        return ()

    def bounds(self):
        lo, hi = box_union([c.bounds() for c in self.children])
        # The blend fills concave seams; it never reaches further than its radius.
        return lo - self.radius_np, hi + self.radius_np


class SmoothIntersection(_NAry):
    """Smooth intersection ``-smax_k(-a, -b)`` with radius ``radius`` (metres)."""

    kind = "smooth_intersection"
    unit_falloff = False

    def __init__(self, *children, radius=1.0):
        super().__init__(*children)
        if not radius > 0:
            raise ValueError("smooth_intersection radius must be > 0")
        self.radius_np = float(radius)
        self.radius = opaque_float(radius)

    def eval(self, p):
        v = self.children[0].eval(p)
        for c in self.children[1:]:
            v = -smooth_max(-v, -c.eval(p), self.radius)
        return v

    def box_range(self, lo, hi):
        a, b = self.children[0].box_range(lo, hi)
        for c in self.children[1:]:
            ca, cb = c.box_range(lo, hi)
            a, b = -smooth_max(-a, -ca, self.radius), -smooth_max(-b, -cb, self.radius)
        return a, b

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        # -smax(-a, -b) >= -c implies min(a, b) >= -c: inside both operands' sets.
        v, ds = self.children[0].eval_bounds(p, levels, direction, footprint)
        for c in self.children[1:]:
            fc, dc = c.eval_bounds(p, levels, direction, footprint)
            v, ds = -smooth_max(-v, -fc, self.radius), tuple(dr.maximum(a, b) for a, b in zip(ds, dc))
        return v, ds

    def bounds(self):
        return box_intersection([c.bounds() for c in self.children])
