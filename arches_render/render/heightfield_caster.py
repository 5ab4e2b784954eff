"""Exact ray casting of heightfields by maximum-mipmap traversal, in Dr.Jit.

A tracer with the interface of :class:`~.sphere_tracer.SphereTracer` (``trace``,
``occluded``, ``surface``, ``eps``, ``scale_op``) for the trees that
:func:`~arches_render.field.heightfield_mipmap.heightfield_cast_plan` accepts: a
heightfield (possibly clipped by boxes) is intersected exactly, without sphere
steps. In a union or blend with 3-D operands (the default scene: terrain blended
with an arch), each ray alternates between exact casts over the stretches where
every 3-D operand is certified below ``-(k + m)`` (there the root's surface *is*
the heightfield's; proof in that module's docstring) and over-relaxed sphere steps
on the full field elsewhere. The stretches come from the exact entry and exit of
the ray through each leaf of the 3-D operands grown by ``k + m`` plus the leaf's
offset (capsules and spheres: exact; other leaves: their grown box), so a ray that
passes an arch at a distance is cast exactly on both sides of it, and sphere steps
are taken only within a few blend radii of the 3-D primitives.

The cast itself, the maximum-mipmap traversal and its exact ray-patch test,
is :mod:`.mipmap_traversal`; the sphere steps are :mod:`.march`'s. Every lane
the traversal's iteration guard or the loops' budgets stop is resolved
conservatively (an unresolved hit at the point it proved free up to), never
as a miss. ``steps`` counts sphere steps (field evaluations), ``cells`` the
cast's cell visits.

Vertical rays, rays starting inside or below the terrain, grazing rays and rays
from far away are handled by the same code; ``tests/test_heightfield_caster.py``
compares hits with a dense brute-force sampling of the field.

References
----------
Tevs, A., Ihrke, I., Seidel, H.-P. (2008). Maximum mipmaps for fast, accurate, and
scalable dynamic height field rendering. Proc. I3D 2008, 183-190.
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..field.heightfield_mipmap import heightfield_cast_plan
from .march import SECOND_PASS_FACTOR, March, ShadowProbe, TraceResult, ray_box
from .mipmap_traversal import MipmapTraversal
from .sphere_tracer import SphereTracer


#: Rounds of the hybrid loop (cast, probe, near) after which a ray is unresolved.
MAX_ROUNDS = 4096


def make_tracer(field, eps=2e-4, omega=1.6, max_steps=512, cast=True, cells=False):
    """The fastest exact tracer for ``field``: a :class:`HeightfieldCaster` when the
    tree reduces to a heightfield cast, else a :class:`~.cell_tracer.CellTracer` (with
    ``cells``) or a :class:`SphereTracer`.

    Parameters
    ----------
    field : Node
        Root of the construction tree.
    eps, omega, max_steps
        As for :class:`SphereTracer` (used where sphere steps remain).
    cast : bool
        False: always a :class:`SphereTracer` (comparisons).

    Returns
    -------
    HeightfieldCaster or SphereTracer
    """
    plan = heightfield_cast_plan(field) if cast else None
    if plan is None and cells:
        from .cell_tracer import CellTracer
        return CellTracer(field, eps=eps, omega=omega, max_steps=max_steps)
    if plan is None:
        return SphereTracer(field, eps=eps, omega=omega, max_steps=max_steps)
    return HeightfieldCaster(field, plan, eps=eps, omega=omega, max_steps=max_steps)


class HeightfieldCaster:
    """Ray queries of a tree that reduces to a heightfield cast (see module doc).

    Exact casts answer plain heightfields; hybrid trees (``hybrid`` true) mix casts
    and sphere steps per ray (:meth:`_query`). Hits are exact where the heightfield
    answers and within the sphere tracer's tolerance ``eps t`` near 3-D operands.

    Parameters
    ----------
    field : Node
        The construction tree.
    plan : CastPlan
        Its reduction, from :func:`heightfield_cast_plan`.
    eps, omega, max_steps
        Sphere-tracer settings for the 3-D zone and the hit tolerance that the
        integrator's ray offsets use.
    """

    def __init__(self, field, plan, eps=2e-4, omega=1.6, max_steps=512):
        self.plan = plan
        self.sphere = SphereTracer(field, eps=eps, omega=omega, max_steps=max_steps)
        self.eps, self.scale_op, self.scale = self.sphere.eps, self.sphere.scale_op, self.sphere.scale
        self.field = self.sphere.field  # culled: what near steps evaluate
        self.omega = float(omega)
        self.traversal = MipmapTraversal(plan.heightfield)
        op = lambda v: [dr.opaque(mi.Float, float(x)) for x in v]  # noqa: E731
        self._clip = op(plan.clip_lo), op(plan.clip_hi)
        self.hybrid = bool(plan.others)
        if self.hybrid:
            # Any margin m > 0 makes the zone argument strict; one hit tolerance.
            margin = float(eps) * self.scale + 1e-4
            self.far_level = plan.radius + margin
            zone = plan.zone(margin)
            self._zone = op(zone[0]), op(zone[1])
            self._leaves = [(leaf, dr.opaque(mi.Float, self.far_level + g), _grown_box(leaf, self.far_level + g))
                            for leaf, g in plan.leaves]
            # Certified stretches shorter than this are not worth a cast: step instead.
            self._min_cast = dr.opaque(mi.Float, 0.125 * self.far_level)

    # -- public queries ------------------------------------------------------------
    def query(self, o, d, tmax, active, cone=None, any_hit=False, coherent=False, t_min=None):
        """Ray queries with step counts and budgets (:meth:`SphereTracer.query`);
        ``any_hit``: stop at the first certain hit (shadow rays); ``coherent`` and
        ``t_min`` change nothing (no queue; a cast does not start at a proven distance).

        Returns
        -------
        TraceResult
        """
        return self._query(o, d, tmax, active, any_hit=any_hit, cone=cone)

    def trace(self, o, d, tmax, active, cone=None):
        """First hit of the rays ``o + t d`` (``|d| = 1``) with ``0 <= t <= tmax``;
        ``cone``: each lane's ray cone (:meth:`SphereTracer.trace`), used by the sphere
        steps near 3-D operands (the heightfield itself has no octaves).

        Returns
        -------
        (mi.Bool, mi.Float)
            Hit mask and distance.
        """
        r = self._query(o, d, tmax, active, any_hit=False, cone=cone)
        return r.hit, r.t

    def occluded(self, o, d, tmax, active, cone=None):
        """Whether the segments ``o + t d``, ``0 <= t <= tmax``, meet matter (stops at
        the first certain hit)."""
        return self._query(o, d, tmax, active, any_hit=True, cone=cone).hit

    def tolerance(self, t, cone=None):
        """Hit tolerance of the sphere steps (:meth:`SphereTracer.tolerance`)."""
        return self.sphere.tolerance(t, cone)

    def surface(self, p, t, d=None, cone=None):
        """Surface point and outward normal of hits ``p`` found at distance ``t``.

        Hybrid trees: the sphere tracer's (gradient of the full field). Otherwise
        the hit is exact and the normal analytic: ``(-h_x, -h_y, 1)`` normalized from
        the slopes of the heightfield's C1 stand-in (:meth:`Heightfield.smooth_slopes`,
        its module docstring, "Shading normals"), or the face normal where the
        clipping box is the nearer part of ``min(h - z, box)``.
        """
        if self.hybrid:
            return self.sphere.surface(p, t, d, cone)
        hf = self.plan.heightfield
        top = hf.height(p.x, p.y) - p.z
        hx, hy = hf.smooth_slopes(p.x, p.y)
        n = dr.normalize(mi.Vector3f(-hx, -hy, 1.0))
        # Nearest face of the clipping box (largest signed outside distance).
        lo, hi = self._clip
        q = [dr.maximum(lo[a] - p[a], p[a] - hi[a]) for a in range(3)]
        side = [dr.select(p[a] - lo[a] > hi[a] - p[a], 1.0, -1.0) for a in range(3)]
        qx_big = (q[0] >= q[1]) & (q[0] >= q[2])
        qy_big = ~qx_big & (q[1] >= q[2])
        face = mi.Vector3f(dr.select(qx_big, side[0], 0.0), dr.select(qy_big, side[1], 0.0),
                           dr.select(~qx_big & ~qy_big, side[2], 0.0))
        box = -dr.maximum(dr.maximum(q[0], q[1]), q[2])
        return mi.Point3f(p), dr.select(box < top, face, n)

    # -- implementation --------------------------------------------------------------
    def _query(self, o, d, tmax, active, any_hit, cone=None):
        """Ray queries: one exact cast for plain heightfields, the hybrid loop
        (:meth:`_hybrid`) for trees with 3-D operands."""
        o, d = mi.Point3f(o), mi.Vector3f(d)
        tmax, active = mi.Float(tmax), mi.Bool(active)
        t_in, t_out = ray_box(o, d, *self._clip)
        ta, tb = dr.maximum(t_in, 0.0), dr.minimum(t_out, tmax)
        if not self.hybrid:
            cast = self.traversal.cast(o, d, ta, tb, active & (ta <= tb), ta > t_in, any_hit)
            # A lane the iteration guard stopped is unresolved: a hit at the point
            # the cast proved free up to, never a miss.
            t = dr.select(cast.found, cast.t_hit, dr.select(cast.capped, cast.t, dr.inf))
            return TraceResult.of(cast.found, t, 0, cast.capped, active, self.sphere.max_steps, cells=cast.iterations)
        return self._hybrid(o, d, tmax, active, any_hit, cone, t_in, ta, tb)

    @dr.syntax
    def _hybrid(self, o, d, tmax, active, any_hit, cone, t_in, ta, tb):
        """The hybrid loop (module docstring): each lane is in one of three modes.

        CAST traverses the mipmap over ``[t, t_hi]``, a stretch where the root's
        surface is the heightfield's, clipped to its box. PROBE at ``t_seg``
        certifies how far the 3-D operands stay below ``-T``: a long enough stretch
        becomes the next CAST, otherwise the lane turns to NEAR, over-relaxed sphere
        steps on the full field (:meth:`_near`) until a step is long again. Each
        mode runs in a loop of its own inside one outer loop, so that one iteration
        of a SIMD packet pays for one mode's code, not for all three.
        """
        CAST, PROBE, NEAR = mi.UInt32(0), mi.UInt32(1), mi.UInt32(2)
        f_in, f_out = ray_box(o, d, self.sphere.lo_op, self.sphere.hi_op)
        t_end = dr.minimum(f_out, tmax)
        z0, z1 = ray_box(o, d, *self._zone)
        misses_zone = (z0 > z1) | (z1 < 0.0) | (z0 > t_end)
        t0 = dr.maximum(f_in, 0.0)
        budget = self.sphere.max_steps * (1 + SECOND_PASS_FACTOR)
        spans = self._spans(o, d)
        # Rays that miss the zone are one cast; the others start by probing.
        mode = dr.select(misses_zone, CAST, PROBE)
        t = mi.Float(dr.select(misses_zone, ta, t0))           # the cast's stretch [t, t_hi]
        t_hi = mi.Float(dr.select(misses_zone, tb, t0))
        t_seg = mi.Float(dr.select(misses_zone, t_end, t0))     # where probing (or stepping) resumes
        found = mi.Bool(False)
        t_hit = mi.Float(dr.inf)
        unresolved = mi.Bool(False)
        alive = active & dr.select(misses_zone, ta <= tb, t0 <= t_end)
        rounds = mi.UInt32(0)
        steps = mi.UInt32(0)
        cells = mi.UInt32(0)
        # Read-only values stay out of the loop's state: Dr.Jit records a loop's body
        # again to drop a variable it leaves unchanged (integrator.sample_megakernel).
        while dr.hint(alive & (steps < budget) & (rounds < MAX_ROUNDS), label="heightfield_hybrid",
                      exclude=[self, CAST, PROBE, NEAR, o, d, cone, t_end, t_in, ta, tb, z0, z1, misses_zone,
                               spans]):
            # CAST: finish the current stretch.
            casting = alive & (mode == CAST)
            cast = self.traversal.cast(o, d, t, t_hi, casting, t > t_in, any_hit)
            found |= casting & cast.found
            t_hit = dr.select(casting & cast.found, cast.t_hit, t_hit)
            cells += dr.select(casting, cast.iterations, 0)
            capped = casting & cast.capped
            unresolved |= capped
            t = dr.select(capped, cast.t, t)
            stretch_done = casting & cast.ended
            mode = dr.select(stretch_done, PROBE, mode)
            alive &= ~found & ~capped & ~(stretch_done & (t_seg >= t_end))
            # PROBE: how far do the 3-D operands stay certified below -T?
            probing = alive & (mode == PROBE)
            long, seg_end, lo, hi, near_end = self._probe(o, d, t_seg, t_end, ta, tb, z0, z1, misses_zone,
                                                          spans, cone)
            go = probing & long & (lo <= hi)
            mode = dr.select(go, CAST, dr.select(probing & ~long, NEAR, mode))
            t, t_hi = dr.select(go, lo, t), dr.select(go, hi, t_hi)
            t_seg = dr.select(probing & long, seg_end, t_seg)
            # A certified stretch off the heightfield's box holds no surface.
            alive &= ~(probing & long & ~go & (seg_end >= t_end))
            # NEAR: sphere steps from t_seg until a step is long again.
            nearing = alive & (mode == NEAR)
            near = self._near(o, d, t_seg, t_end, near_end, nearing, steps, budget, cone, any_hit)
            found |= near.hit
            t_hit = dr.select(near.hit, near.t, t_hit)
            steps = dr.select(nearing, near.steps, steps)
            t_seg = dr.select(nearing, near.t, t_seg)
            mode = dr.select(near.leave, PROBE, mode)
            unresolved |= near.invalid
            # A lane still stepping ran out of steps: it stays alive, and this loop's
            # condition ends it as unresolved.
            alive &= ~found & ~near.invalid & ~(nearing & near.done)
            rounds += 1
        # Lanes still alive used up their steps or rounds: unresolved, a hit at the
        # point they proved free up to, never a miss.
        unresolved |= alive
        # (A CAST lane's t_seg already points past the stretch it has yet to cast.)
        t_last = dr.select(mode == CAST, t, t_seg)
        return TraceResult.of(found, dr.select(found, t_hit, t_last), steps, unresolved, active,
                              self.sphere.max_steps, cells=cells + rounds)

    def _spans(self, o, d):
        """``(spans, bounded)``: the exact entry and exit of the rays through each grown
        leaf that has them, and the leaves certified by their own bounds instead."""
        spans = [_leaf_span(node, level, box, o, d) for node, level, box in self._leaves]
        bounded = [(node, level) for (node, level, _), sp in zip(self._leaves, spans) if sp is None]
        return [sp for sp in spans if sp is not None], bounded

    def _probe(self, o, d, t_seg, t_end, ta, tb, z0, z1, misses_zone, spans, cone):
        """Where to go from ``t_seg``: ``(long, seg_end, lo, hi, near_end)``.

        Every 3-D operand is ``<= -T`` on the stretch (heightfield_mipmap's module
        docstring): outside the zone, before the next grown leaf, or within the
        other leaves' own distance bounds. ``long``: the stretch is worth a cast,
        over ``[lo, hi]`` (clipped to the heightfield's box); ``near_end``: where the
        leaves the ray is about to enter end (sphere steps go at least that far)."""
        spans, bounded = spans
        inf, min_cast = mi.Float(dr.inf), self._min_cast
        cert, near_end = inf, -inf
        for e0, e1 in spans:
            cert = dr.minimum(cert, dr.select(e1 >= t_seg, dr.maximum(e0 - t_seg, 0.0), inf))
            soon = (e0 <= t_seg + min_cast) & (e1 >= t_seg)
            near_end = dr.maximum(near_end, dr.select(soon, e1, -inf))
        if bounded:
            p = o + d * t_seg
            fp = self.sphere.footprint(cone, t_seg)
            for node, level in bounded:
                cert = dr.minimum(cert, node.eval_bounds(p, (level,), d, fp)[1][0])
        cert = dr.select(misses_zone | (t_seg >= z1), inf, dr.maximum(cert, z0 - t_seg))
        seg_end = dr.minimum(t_seg + cert, t_end)
        return cert >= min_cast, seg_end, dr.maximum(t_seg, ta), dr.minimum(seg_end, tb), near_end

    @dr.syntax
    def _near(self, o, d, t_start, t_end, near_end, active, steps, budget, cone, any_hit=False):
        """Over-relaxed sphere steps on the full field from ``t_start`` (:mod:`.march`;
        ``steps`` counts every sphere step of the ray, against its budgets; a shadow
        ray's may probe, :mod:`.march`, "Shadow probes"). Past ``near_end``, a long free
        step hands the lane back to probing at its verified end (``leave``).

        Returns
        -------
        _NearOutcome
        """
        march = March.start(t_start, self.omega)
        shadow = ShadowProbe.start(dr.width(t_start)) if any_hit else None
        hit = mi.Bool(False)
        invalid = mi.Bool(False)
        done = mi.Bool(False)
        leave = mi.Bool(False)
        alive = mi.Bool(active)
        steps = mi.UInt32(steps)
        # Read-only values stay out of the loop's state: Dr.Jit records a loop's body
        # again to drop a variable it leaves unchanged (integrator.sample_megakernel).
        while dr.hint(alive & (steps < budget), label="hf_near", exclude=[self, o, d, cone, t_end, near_end]):
            t_now = march.t
            if dr.hint(any_hit, mode="scalar"):
                march, out, r, shadow = self.sphere.step(o, d, march, t_end, cone, shadow)
            else:
                march, out, r = self.sphere.step(o, d, march, t_end, cone)
            going = alive & ~out.failed & ~out.hit & ~out.invalid & (r >= self._min_cast) & (t_now >= near_end)
            # Leave at the end of the verified free interval, not at a relaxed point.
            march.t = dr.select(going, t_now + r, march.t)
            leave |= going
            hit |= alive & out.hit
            invalid |= alive & out.invalid
            done |= alive & out.done & ~going
            alive &= ~(out.hit | out.invalid | out.done | going)
            steps += 1
        # A lane the budget stopped reports its verified frontier (unresolved).
        t = dr.select(alive, dr.minimum(march.t, march.frontier), march.t)
        return _NearOutcome(hit=hit, t=t, leave=leave, done=done, invalid=invalid, steps=steps)


@dataclass
class _NearOutcome:
    """What a lane's sphere steps near the 3-D operands ended with (:meth:`HeightfieldCaster._near`)."""

    hit: object
    t: object
    leave: object
    done: object
    invalid: object
    steps: object


def _grown_box(node, grow):
    """Opaque box containing ``{node >= -grow}`` for bounded, unit-falloff nodes."""
    lo, hi = node.bounds()
    if not (node.unit_falloff and np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return None
    pad = float(grow) + 1e-5 * float(np.max(np.abs(np.concatenate([lo, hi])))) + 1e-4
    return ([dr.opaque(mi.Float, float(v) - pad) for v in lo], [dr.opaque(mi.Float, float(v) + pad) for v in hi])


def _leaf_span(node, grow, box, o, d):
    """Entry and exit distances of the rays ``o + t d`` through a set containing
    ``{node >= -grow}``, or ``None``. Empty spans come back as ``(inf, -inf)``.

    Capsules and spheres grow into capsules and spheres (exact spans; a capsule is
    convex, the union of a finite cylinder and two end balls, so its span runs
    from the first entry to the last exit of those pieces). Other bounded leaves
    that fall off at unit rate lie within their box grown by ``grow`` (``box``, from
    :func:`_grown_box`).
    """
    from ..field.primitives import Capsule, Sphere
    inf = mi.Float(dr.inf)
    if type(node) not in (Capsule, Sphere):
        if box is None:
            return None
        t0, t1 = ray_box(o, d, *box)
        return dr.select(t0 <= t1, t0, inf), dr.select(t0 <= t1, t1, -inf)

    def ball(c, R):
        # Closest approach first (no cancellation of large |o - c|).
        w = o - c
        b = -dr.dot(w, d)
        disc = R * R - dr.squared_norm(w + d * b)
        sq = dr.sqrt(dr.maximum(disc, 0.0))
        ok = disc >= 0.0
        return dr.select(ok, b - sq, inf), dr.select(ok, b + sq, -inf)

    if type(node) is Sphere:
        lo, hi = ball(node.c, node.r + grow)
        R = node.r + grow
    else:
        R = node.r + grow
        axis = node.b - node.a
        length = dr.norm(axis)
        u = axis / dr.maximum(length, 1e-20)
        w = o - node.a
        du, wu = dr.dot(d, u), dr.dot(w, u)
        dp, wp = d - u * du, w - u * wu  # components across the axis
        A = dr.squared_norm(dp)
        parallel = A < 1e-12
        s_c = -dr.dot(wp, dp) / dr.maximum(A, 1e-30)  # closest approach to the axis line
        disc = R * R - dr.squared_norm(wp + dp * s_c)
        half = dr.sqrt(dr.maximum(disc, 0.0) / dr.maximum(A, 1e-30))
        near_axis = dr.squared_norm(wp) <= R * R
        c0 = dr.select(parallel, dr.select(near_axis, -inf, inf), dr.select(disc >= 0.0, s_c - half, inf))
        c1 = dr.select(parallel, dr.select(near_axis, inf, -inf), dr.select(disc >= 0.0, s_c + half, -inf))
        # Slab 0 <= (p - a).u <= length.
        inv = dr.rcp(du)
        s0, s1 = -wu * inv, (length - wu) * inv
        flat = dr.abs(du) < 1e-12
        inside_slab = (wu >= 0.0) & (wu <= length)
        s_lo = dr.select(flat, dr.select(inside_slab, -inf, inf), dr.minimum(s0, s1))
        s_hi = dr.select(flat, dr.select(inside_slab, inf, -inf), dr.maximum(s0, s1))
        k0, k1 = dr.maximum(c0, s_lo), dr.minimum(c1, s_hi)
        a0, a1 = ball(node.a, R)
        b0, b1 = ball(node.b, R)
        lo = dr.minimum(dr.select(k0 <= k1, k0, inf), dr.minimum(a0, b0))
        hi = dr.maximum(dr.select(k0 <= k1, k1, -inf), dr.maximum(a1, b1))
    # Rounding: widen by a relative margin (certifies a hair less).
    pad = 1e-5 * (dr.select(dr.isfinite(lo), dr.abs(lo), 0.0) + R) + 1e-4
    return lo - pad, hi + pad
