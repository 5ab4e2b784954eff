"""The paper's blend (sum) and localized warp operators.

Union, intersection, difference, smooth blends and unbounded domain warps are in
:mod:`arches_render.field.operators` and :mod:`arches_render.field.warps`; this module
adds the two operators of Paris et al. (2019, Sec. 5.3) that those do not cover.

``Sum`` (the paper's blend, after Wyvill et al. 1999): ``f = sum_i f_i``. It is how a
terrain receives sculpting primitives: positive energies add matter (arches,
hoodoo parts), negative energies carve (caves, sea erosion). ``L = sum_i L_i``. The
sum is positive only where some operand is, so the box is the union of the
operands' boxes. Distance bounds: with ``M_j`` an upper bound of ``f_j``,
``sum f >= -c`` implies ``f_i >= -c - sum_{j != i} M_j``, so each operand's own bound at
that shifted level holds; the largest of them (and Hart's, with the operands'
local slope bounds where they have them: see :func:`local_lipschitz`) is used. A
carving set has ``M = 0`` and the terrain keeps its own tight bounds.

Local slopes (issue 21): Hart's bound uses the sum of the operands' slope bounds
in a ball of radius ``rad`` around ``p`` (:func:`eval_local`), for two radii (the finest
primitive set's ``local_radius``, an eighth of its cell edge, and 1/8 of that), so a ray near a steep
cave wall takes the step of the small ball, ``min(rad, (-f - c) / S(rad))``, and a
ray in open space that of the large one.

That global shift is vacuous for sculpting that *adds* matter in the air: there a
set must reach above the terrain's air value ``-T``, so ``M_j > T`` and
``{f_T >= -c - M_j}`` is all of space (the terrain's bound is 0 everywhere), and
rays fall back to Hart's bound with the set's large slope bound (``f = -T`` in the
air over ``L ~ 30``: steps of 6 cm, thousands per ray over the hoodoos scene, where
the tracer ran out of steps and reported misses). Hence *caps*: with ``m_j`` the
operand's minimum, ``v_j = m_j + 2^-20 (M_j - m_j)`` and ``rho_j`` the operand's own
distance bound to ``{f_j >= v_j}`` (level ``-v_j``; for a compact primitive set it
is nearly the distance to its supports, see :mod:`.skeletal_set`), ``f_j < v_j`` in the ball
``B(p, rho)``, ``rho = min_j rho_j``. In that ball ``sum f >= -c`` implies
``f_i >= -c - sum_{j != i} v_j``, so

    d >= max(d_i(c + sum_{j != i} M_j), min(rho, d_i(c + sum_{j != i} v_j))),

which is the distance bound to ``{f_i >= -c - sum v}`` ∪ (``{f_j >= v_j}`` ∩
``{f_i >= -c - sum M}``), a set holding ``{sum f >= -c}``. The same holds along a line
(two-sided line bounds). Any ``v_j`` is rigorous (``m_j`` need not even bound
``f_j``); a ``v_j`` just above the minimum makes the ball nearly the operand's support
while moving the others' level by only ``2^-20`` of its range. (It was 1/256: over
the goblins' hoodoos, whose energies span 40, that moved the terrain's level by
0.16, 0.31 m of vertical clearance through its sigmoid, and every ray leaving the
ground inside that band fell back to Hart's bound: 297 shadow steps a ray against
97 now. ``2^-20`` of a range is still many float32 ulps of the operands' values.) Caps are asked only
between operands that add matter (``M > 0``): next to a carving set (``M <= 0``) the
global shift is already small, and the extra levels would only cost time.

Slanted levels: caps help only where the terrain sits at its air value; over the
goblins' hoodoos the terrain's falloff band holds the whole of every hoodoo, and there
rays near a wall fell back to Hart's bound with the set's slope (90-190, against true
gradients of 8-30; bounce rays 90 steps on average). One set that adds matter and
answers slanted levels (:mod:`.skeletal_bounds`, "Slanted levels") is evaluated after
the other operands; with ``S`` their summed slope bound in the ball of the first
slope radius ``rad`` (their global one without local slopes) and ``f_o(p)`` their
summed value, ``f_o(q) <= f_o(p) + S |q - p|`` there, so the set's radius (at most
``rad``) in which ``F(q) < -c - f_o(p) - S |q - p|`` is free of ``{sum f >= -c}``:
the set's geometric level bounds with the terrain's small slope (goblins, 320x180:
camera steps 61 -> 43, shadow 92 -> 61, bounce 90 -> 41).

``LocalWarp``: ``f~(p) = f(w(p))``, ``w(p) = p + delta(p) m(p)``, with
``delta = a W(p / lambda)`` three decorrelated fBm (as in
:class:`arches_render.field.DomainWarp`) and ``m = clamp(f_D, 0, 1)`` the control field
that localises the warp (the paper's ``omega^{-1}(p) = p + delta(p) f_D(p)``).
``|J_w| <= 1 + m |J_delta| + |delta| |grad m| <= 1 + sqrt(3) a L_fbm / lambda
+ sqrt(3) a N L_D`` (``N`` the fBm range), so ``L = L_f (1 + sqrt(3) a (L_fbm / lambda + N L_D))``.
``f~ > 0`` needs ``w(p)`` in the child's box, and ``|w(p) - p| <= sqrt(3) a N``: the box
grows by that much.

References
----------
Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
38(5), Sec. 5.3.
Wyvill, B., Guy, A., Galin, E. (1999). Extending the CSG tree. CGF 18(2).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render.field.local_slopes import eval_local, local_hart, local_lipschitz
from arches_render.field.node import Node, box_union
from arches_render.field.warps import FbmParams


#: Where a cap sits in an operand's value range (see the module docstring).
CAP_FRACTION = 2.0 ** -20


def value_max(node: Node):
    """An upper bound of ``node``'s field, or ``None`` when the node does not know one."""
    v = getattr(node, "value_max", None)
    return None if v is None else float(v)


def value_min(node: Node):
    """The node's ``value_min`` (a lower bound of its field), or ``None``. The sum
    uses it only to place caps, which are rigorous for any value."""
    v = getattr(node, "value_min", None)
    return None if v is None else float(v)


def _listed(radius, radii) -> bool:
    """Whether ``radius`` is a plain number among ``radii`` (per-lane radii never are)."""
    return isinstance(radius, float) and radius in radii


class Sum(Node):
    """The paper's blend ``f = sum_i f_i`` (see module docstring)."""

    kind = "sum"
    unit_falloff = False

    def __init__(self, *children):
        if len(children) < 1:
            raise ValueError("sum needs at least one operand")
        self.children = tuple(children)

    def eval(self, p):
        v = self.children[0].eval(p)
        for c in self.children[1:]:
            v = v + c.eval(p)
        return v

    def box_range(self, lo, hi):
        a, b = self.children[0].box_range(lo, hi)
        for c in self.children[1:]:
            ca, cb = c.box_range(lo, hi)
            a, b = a + ca, b + cb
        return a, b

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        return self.eval_local(p, levels, direction, footprint)[:2]

    def eval_local(self, p, levels, direction=None, footprint=None, radii=()):
        """``(f, ds, slopes)``: :meth:`eval_bounds` and, for each of ``radii``, the sum
        of the operands' slope bounds in that ball (:func:`eval_local`)."""
        asked = tuple(radii)
        kids = self.children
        sups = [value_max(c) for c in kids]
        # Caps (module docstring): f_j < v_j within rho_j = d_j(-v_j), v_j just above
        # the operand's minimum. Only with levels: gradient taps ask for none.
        caps = [None] * len(kids)
        if levels:
            for j, (c, M) in enumerate(zip(kids, sups)):
                m = value_min(c)
                if M is not None and m is not None and m < M:
                    caps[j] = m + CAP_FRACTION * (M - m)
        n = len(levels)
        asks, plans = [], []
        for i in range(len(kids)):
            others = [j for j in range(len(kids)) if j != i]
            ask, plan = None, None
            if all(sups[j] is not None for j in others):
                ask = [c + sum(sups[j] for j in others) for c in levels]
                # Caps pay only where operands add matter (M > 0): with carving sets
                # (M <= 0) the global shift is already small.
                plan = [j for j in others if caps[j] is not None and sups[j] > 0] if sups[i] is not None and sups[i] > 0 else []
                if plan:
                    shift = sum(caps[j] if j in plan else sups[j] for j in others)
                    ask += [c + shift for c in levels]
            asks.append(ask)
            plans.append(plan)
        for j in {j for plan in plans if plan for j in plan}:
            asks[j] = (asks[j] or []) + [-caps[j]]
        # A radius asked that the sum uses itself is computed once (a blend over the sum
        # asks for the sum's own radii).
        own_radii = self.slope_radii if levels else ()
        radii = own_radii + tuple(r for r in asked if not _listed(r, own_radii))
        asked_at = [own_radii.index(r) if _listed(r, own_radii) else None for r in asked]
        extra = iter(range(len(own_radii), len(radii)))
        asked_at = [next(extra) if j is None else j for j in asked_at]
        steep = self._steep_child() if levels else None
        order = [i for i in range(len(kids)) if i != steep] + ([] if steep is None else [steep])
        values, answers, parts, slanted = [None] * len(kids), [None] * len(kids), [None] * len(kids), ()
        for i in order:
            child, ask = kids[i], asks[i]
            if i == steep:
                slants = self._slanted_asks(i, values, parts, levels, radii, footprint)
                ask = tuple(ask or ())
                fc, dc, sc = child.eval_local(p, ask, direction, footprint, radii, slants=slants)
                dc, slanted = dc[:len(ask)], dc[len(ask):]
            elif ask is not None or radii:  # (no levels: a culled child still skips far work)
                fc, dc, sc = eval_local(child, p, tuple(ask or ()), direction, footprint, radii)
            else:
                fc, dc, sc = child.eval(p), (), ()
            values[i], answers[i], parts[i] = fc, dc, sc
        f, slopes = None, None
        for fc, sc in zip(values, parts):  # in the children's order: the same float sum
            f = fc if f is None else f + fc
            slopes = sc if slopes is None else tuple(a + b for a, b in zip(slopes, sc))
        ds = [None] * n
        for i, plan in enumerate(plans):
            if plan is None:
                continue
            own = answers[i][:n]
            if plan:
                # Within rho of p every capped operand is below its cap.
                rho = None
                for j in plan:
                    rj = answers[j][-1]
                    rho = rj if rho is None else dr.minimum(rho, rj)
                own = [dr.maximum(g, dr.minimum(rho, d)) for g, d in zip(own, answers[i][n:2 * n])]
            ds = [d if old is None else dr.maximum(old, d) for old, d in zip(ds, own)]
        ds = [d if g is None else (g if d is None else dr.maximum(d, g))
              for d, g in zip(ds, slanted or (None,) * n)]
        L, r = 0.0, None
        for child in kids:
            Lc, rc = local_lipschitz(child, p)
            L = L + Lc
            r = rc if r is None else (r if rc is None else dr.minimum(r, rc))
        L_glob = self.lipschitz
        if footprint is not None and self.lod_kappa:
            # Footprint fields (arches_render.field.lod): every slope grows by 1 + kappa s.
            grow = 1.0 + self.lod_kappa * footprint.rate
            L, L_glob = L * grow, L_glob * grow
        hart = local_hart(f, levels, L, r, L_glob)
        own = len(own_radii)
        for S, rad in zip((slopes or ())[:own], radii[:own]):
            # Hart's bound in the ball of radius rad, where the slope is at most S.
            hart = tuple(dr.maximum(h, dr.minimum(dr.maximum(-f - c, 0.0) * dr.rcp(dr.maximum(S, 1e-12)), rad))
                         for h, c in zip(hart, levels))
        out = tuple(h if d is None else dr.maximum(d, h) for d, h in zip(ds, hart))
        return f, out, tuple(slopes[j] for j in asked_at) if asked else ()

    def _slanted_asks(self, steep, values, parts, levels, radii, footprint):
        """``(c + f_o(p), S, reach)`` for each level ``c``: what the steep operand is asked
        (module docstring, "Slanted levels"). ``f_o(p)``: the other operands' summed
        ``values``; ``S``: their slope bound in the ball of the first of ``radii``
        (``parts``: their slopes for ``radii``), else their global one (``reach`` None)."""
        others = [k for k in range(len(self.children)) if k != steep]
        rest = sum((values[k] for k in others), 0.0)
        if radii:
            slope, reach = sum((parts[k][0] for k in others), 0.0), radii[0]
        else:
            slope, reach = 0.0, None
            for k in others:
                other = self.children[k]
                grow = 1.0 + other.lod_kappa * footprint.rate if footprint is not None else 1.0
                slope = slope + other.lipschitz * grow
        return tuple((c + rest, slope, reach) for c in levels)

    def _steep_child(self):
        """The operand bounded by slanted levels (module docstring): the one set that
        adds matter and answers them, or ``None`` (none, or more than one)."""
        steep = [i for i, c in enumerate(self.children)
                 if getattr(c, "slanted_levels", False) and (value_max(c) or 0.0) > 0.0]
        return steep[0] if len(steep) == 1 and len(self.children) > 1 else None

    @property
    def slope_radii(self):
        """Radii of the balls in which the operands bound their slopes (``eval_local``):
        the smallest operand's ``local_radius`` and one eight times shorter (a ray
        near a steep wall needs a small ball, one in open space a large one); ``()`` when no
        operand has local slopes."""
        rs = [float(c.local_radius) for c in self.children if getattr(c, "local_radius", None)]
        if not rs:
            return ()
        m = min(rs)
        return (m, m / 8.0)

    def bounds(self):
        boxes = [c.bounds() for c in self.children]
        boxes = [b for b in boxes if np.all(b[1] >= b[0])] or boxes[:1]
        return box_union(boxes)

    @property
    def lipschitz(self):
        return sum(c.lipschitz for c in self.children)

    @property
    def value_max(self):
        sups = [value_max(c) for c in self.children]
        return None if any(m is None for m in sups) else sum(sups)


class LocalWarp(FbmParams, Node):
    """Child warped by ``p + delta(p) clamp(f_D(p), 0, 1)`` (see module docstring).

    Parameters
    ----------
    child : Node
        The warped sub-tree.
    control : Node
        ``f_D``: where it is >= 1 the warp is full, where <= 0 there is none (e.g. a
        :class:`~.skeletal_set.SkeletalSet` of energy 1).
    amplitude, wavelength, octaves, lacunarity, gain, seed
        The turbulence ``delta = a W(p / lambda)``.
    """

    kind = "local_warp"
    noise_fields = 3

    def __init__(self, child, control, amplitude=1.0, wavelength=1.0, octaves=3, lacunarity=2.0,
                 gain=0.5, seed=0):
        self.children = (child, control)
        self._init_fbm(amplitude, wavelength, octaves, lacunarity, gain, seed)

    def eval(self, p):
        m = dr.clip(self.children[1].eval(p), 0.0, 1.0)
        w = mi.Vector3f(self._fbm(p, 0), self._fbm(p, 1), self._fbm(p, 2))
        return self.children[0].eval(p + (self.amplitude * m) * w)

    def bounds(self):
        lo, hi = self.children[0].bounds()
        r = self.max_offset * math.sqrt(3.0)
        return lo - r, hi + r

    unit_falloff = False

    @property
    def lipschitz(self):
        grow = math.sqrt(3.0) * (self.fbm_slope + self.max_offset * self.children[1].lipschitz)
        return self.children[0].lipschitz * (1.0 + grow)

    @property
    def value_max(self):
        return value_max(self.children[0])
