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

**Traversal** (Tevs et al. 2008, hierarchical ray stepping): the ray's interval is
clipped to the prism box; a lane holds a level ``l`` and a cell ``(i, j)`` of that
level and, at each iteration of one ``dr.while_loop``,

* computes the cell's exit distance ``t_exit`` (the nearer of its x and y walls);
* if the ray's lowest point over ``[t, t_exit]`` is above the cell's maximum, steps
  to the neighbour cell through that wall and, when the step leaves the parent
  cell, goes up one level;
* otherwise goes down one level, first advancing ``t`` to where the ray sinks below
  the maximum, into the child cell holding the ray's point;
* at level 0 intersects the bilinear patch exactly (below).

Cells advance by integer steps, never by re-locating a point, so rounding cannot
make a lane revisit a cell; every iteration steps or descends, so a lane ends
after at most ``levels + 2 (levels + cells crossed)`` iterations.

**Ray-patch intersection.** In cell ``(i, j)`` the field's height is
``lerp(lerp(h00, h10, u), lerp(h01, h11, u), v)`` with ``u = (x - x0) / dx - i`` (the
same samples, formula and float operations as
:meth:`~arches_render.field.Heightfield.height`). Along the segment
``s in [0, s_b]`` from the current point, ``g(s) = h - z`` is the quadratic
``C + B s + A s^2``, ``A = e du dv``, with ``C`` evaluated exactly as the field
evaluates ``h - z`` at that point. The first ``s`` with ``g >= 0`` lies in an
interval where ``g`` is monotone (``[0, s*]`` before a maximum, ``[s*, s_b]`` after a
minimum, else ``[0, s_b]``); it is the increasing root ``(-B + sqrt(D)) / (2A)``,
computed in the cancellation-free form ``-2C / (B + sqrt(D))`` when ``B >= 0``, and
clamped into that interval. Whether the patch is hit at all is decided from the
values of ``g`` at the segment's ends and at an interior maximum.

**Shadow rays** (``occluded``) stop at the first *certain* hit: a cell whose
minimum the ray sinks below holds matter, whatever the finer levels say.

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

import drjit as dr
import mitsuba as mi
import numpy as np

from ..field.heightfield_mipmap import MaxMipmap, heightfield_cast_plan
from ..field.node import cell_index
from .sphere_tracer import SECOND_PASS_FACTOR, SphereTracer, TraceResult, ray_box


#: Rounds of the hybrid loop (cast, probe, near) after which a ray is unresolved.
MAX_ROUNDS = 4096


def make_tracer(field, eps=2e-4, omega=1.6, max_steps=512, cast=True):
    """The fastest exact tracer for ``field``: a :class:`HeightfieldCaster` when the
    tree reduces to a heightfield cast, else a :class:`SphereTracer`.

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
        hf = plan.heightfield
        self.mipmap = MaxMipmap(hf.heights_np)
        self.top = self.mipmap.levels - 1
        self.ncx, self.ncy = hf.nx - 1, hf.ny - 1
        self._max = mi.Float(self.mipmap.max_flat)
        self._min = mi.Float(self.mipmap.min_flat)
        self._off = mi.UInt32(self.mipmap.offsets)
        self._corners = mi.Float(self.mipmap.corners.ravel())
        # The field's own arrays and parameters: the patch test repeats its arithmetic.
        self._x0, self._y0 = hf._x0, hf._y0
        self._inv_dx, self._inv_dy = hf._inv_dx, hf._inv_dy
        self._dx, self._dy = dr.opaque(mi.Float, hf.dx), dr.opaque(mi.Float, hf.dy)
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
    def query(self, o, d, tmax, active, cone=None, any_hit=False):
        """Ray queries with step counts and budgets (:meth:`SphereTracer.query`);
        ``any_hit``: stop at the first certain hit (shadow rays).

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
        the bilinear patch under ``p`` (the cell :meth:`Heightfield.height` uses), or
        the face normal where the clipping box is the nearer part of
        ``min(h - z, box)``.
        """
        if self.hybrid:
            return self.sphere.surface(p, t, d, cone)
        h00, h10, h01, h11, fu, fv = self.plan.heightfield.patch(p.x, p.y)
        top = dr.lerp(dr.lerp(h00, h10, fu), dr.lerp(h01, h11, fu), fv) - p.z
        hx = dr.lerp(h10 - h00, h11 - h01, fv) * self._inv_dx
        hy = dr.lerp(h01 - h00, h11 - h10, fu) * self._inv_dy
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
        """Ray queries; see the class docstring for the modes of a lane.

        CAST traverses the mipmap over ``[t, t_hi]``, a stretch where the root's
        surface is the heightfield's, clipped to its box. PROBE (hybrid trees) at
        ``t_seg`` certifies how far the 3-D operands stay below ``-T``: a long
        enough stretch becomes the next CAST, otherwise the lane turns to NEAR,
        over-relaxed sphere steps on the full field (the stop rule of
        :class:`SphereTracer`) until a step is long again. Each mode runs in a loop
        of its own inside one outer loop, so that one iteration of a SIMD packet
        pays for one mode's code, not for all three.
        """
        # Loop bodies rebind their state (``a = a & b``), never update it in place
        # (``a &= b``): an in-place update would also change the caller's array that
        # was passed in as loop state.
        Int, UInt, Float, Bool = mi.Int32, mi.UInt32, mi.Float, mi.Bool
        o, d = mi.Point3f(o), mi.Vector3f(d)
        tmax, active = Float(tmax), Bool(active)
        inf = Float(dr.inf)
        t_in, t_out = ray_box(o, d, *self._clip)
        ta, tb = dr.maximum(t_in, 0.0), dr.minimum(t_out, tmax)
        cast = self._cast_step(o, d, any_hit)
        top = self.top

        def start(t):
            """First cell: the top one for rays that enter the box from outside (a
            descent finds their first cells fastest), else the finest cell under
            the start point (secondary and shadow rays leave the surface)."""
            p = o + d * t
            low = t > t_in
            # Clamp before converting: far points must not overflow the integers.
            ci = cell_index((p.x - self._x0) * self._inv_dx, self.ncx, Int)
            cj = cell_index((p.y - self._y0) * self._inv_dy, self.ncy, Int)
            return dr.select(low, 0, Int(top)), dr.select(low, ci, 0), dr.select(low, cj, 0)

        if not self.hybrid:
            state = (Float(ta), Float(tb), *start(ta), Bool(False), Float(inf),
                     active & (ta <= tb), Bool(False), UInt(0))
            out = dr.while_loop(state, lambda *s: s[7], cast, label="heightfield_cast")
            return TraceResult.of(out[5], out[6], out[9], Bool(False), active, self.sphere.max_steps)

        CAST, PROBE, NEAR = UInt(0), UInt(1), UInt(2)
        f_in, f_out = ray_box(o, d, self.sphere.lo_op, self.sphere.hi_op)
        t_end = dr.minimum(f_out, tmax)
        z0, z1 = ray_box(o, d, *self._zone)
        misses_zone = (z0 > z1) | (z1 < 0.0) | (z0 > t_end)
        t0 = dr.maximum(f_in, 0.0)
        omega0, min_cast, max_steps = self.omega, self._min_cast, self.sphere.max_steps
        budget = max_steps * (1 + SECOND_PASS_FACTOR)

        # Exact entry/exit of the rays through the grown leaves that have one.
        spans = [_leaf_span(node, level, box, o, d) for node, level, box in self._leaves]
        bounded = [(node, level) for (node, level, _), sp in zip(self._leaves, spans) if sp is None]
        spans = [sp for sp in spans if sp is not None]

        def probe(t_seg, alive):
            """Where to go from ``t_seg``: ``(long, seg_end, lo, hi, near_end)``."""
            # Every 3-D operand is <= -T on the stretch (heightfield_mipmap's module
            # docstring): outside the zone, before the next grown leaf, or within
            # the other leaves' own distance bounds.
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
            return (cert >= min_cast, seg_end, dr.maximum(t_seg, ta), dr.minimum(seg_end, tb),
                    near_end)

        def near(t, t_prev, r_prev, step, omega, found, t_hit, alive, leave, near_end, steps):
            """One over-relaxed sphere step on the full field (as :class:`SphereTracer`;
            ``steps`` counts every sphere step of the ray, against its budgets); past
            ``near_end``, a long free step hands the lane back to probing at its
            verified end."""
            f, (r,) = self.field.eval_bounds(o + d * t, (0.0,), d, self.sphere.footprint(cone, t))
            failed = (omega > 1.0) & (r + r_prev < step)
            new_hit = ~failed & ((-f < self.sphere.tolerance(t, cone)) | (f >= 0.0))
            leave = alive & ~failed & ~new_hit & (r >= min_cast) & (t >= near_end)
            t_next = dr.select(failed, t_prev + r_prev, dr.minimum(t + omega * r, t_end))
            t_next = dr.select(leave, t + r, t_next)
            step = dr.select(failed, r_prev, t_next - t)
            t_prev, r_prev = dr.select(failed, t_prev, t), dr.select(failed, r_prev, r)
            omega = dr.select(failed, 1.0, omega0)  # relaxation resumes after a safe step
            done = ~failed & ~new_hit & ~leave & (t >= t_end)
            found = found | (alive & new_hit)
            t_hit = dr.select(alive & new_hit, t, t_hit)
            t = dr.select(new_hit, t, t_next)
            alive = alive & ~new_hit & ~done & ~leave
            return t, t_prev, r_prev, step, omega, found, t_hit, alive, leave, near_end, steps + 1

        def outer(t, t_hi, t_seg, mode, found, t_hit, alive, it, steps):
            # CAST: finish the current stretch.
            c = dr.while_loop((t, t_hi, *start(t), found, t_hit, alive & (mode == CAST),
                               Bool(False), UInt(0)), lambda *s: s[7], cast, label="hf_cast")
            casting = alive & (mode == CAST)
            found, t_hit = c[5], c[6]
            alive = alive & ~found
            mode = dr.select(casting & c[8], PROBE, mode)
            alive = alive & ~(casting & c[8] & (t_seg >= t_end))
            # PROBE.
            probing = alive & (mode == PROBE)
            long, seg_end, lo, hi, near_end = probe(t_seg, probing)
            go = probing & long & (lo <= hi)
            mode = dr.select(go, CAST, dr.select(probing & ~long, NEAR, mode))
            t, t_hi = dr.select(go, lo, t), dr.select(go, hi, t_hi)
            t_seg = dr.select(probing & long, seg_end, t_seg)
            # A certified stretch off the heightfield's box holds no surface.
            alive = alive & ~(probing & long & ~go & (seg_end >= t_end))
            # NEAR: sphere steps from t_seg until a step is long again.
            nearing = alive & (mode == NEAR)
            n = dr.while_loop((Float(t_seg), Float(t_seg), Float(0.0), Float(0.0), Float(omega0), found, t_hit,
                               nearing, Bool(False), near_end, UInt(steps)),
                              lambda *s: s[7] & (s[10] < budget), near, label="hf_near")
            found, t_hit = n[5], n[6]
            steps = dr.select(nearing, n[10], steps)
            t_seg = dr.select(nearing, n[0], t_seg)
            mode = dr.select(nearing & n[8], PROBE, mode)
            # A lane still stepping (n[7]) ran out of steps: it stays alive, and
            # the outer loop's condition ends it as unresolved.
            alive = alive & (~found & ~(nearing & ~n[8] & ~n[7]))
            return t, t_hi, t_seg, mode, found, t_hit, alive, it + 1, steps

        # Rays that miss the zone are one cast; the others start by probing.
        mode0 = dr.select(misses_zone, CAST, PROBE)
        state = (Float(dr.select(misses_zone, ta, t0)), Float(dr.select(misses_zone, tb, t0)),
                 Float(dr.select(misses_zone, t_end, t0)), UInt(mode0), Bool(False), Float(inf),
                 active & dr.select(misses_zone, ta <= tb, t0 <= t_end), UInt(0), UInt(0))
        out = dr.while_loop(state, lambda *s: s[6] & (s[8] < budget) & (s[7] < MAX_ROUNDS), outer,
                            label="heightfield_hybrid")
        # Lanes still alive used up their steps or rounds: unresolved, a hit at
        # their last point (TraceResult), never a miss.
        t_last = dr.select(out[3] == NEAR, out[2], out[0])
        return TraceResult.of(out[4], dr.select(out[4], out[5], t_last), out[8] + out[7], out[6], active,
                              max_steps)

    def _cast_step(self, o, d, any_hit):
        """The body of the traversal loop for rays ``o + t d`` (module docstring).

        Its state is ``(t, t_hi, lvl, ci, cj, found, t_hit, alive, ended, it)``: the ray
        is at ``t`` in cell ``(ci, cj)`` of level ``lvl`` and looks for a hit up to
        ``t_hi``; a lane stops with ``found`` (at ``t_hit``) or ``ended``.
        """
        Int, UInt, Float = mi.Int32, mi.UInt32, mi.Float
        inf = Float(dr.inf)
        inv = mi.Vector3f(dr.rcp(d.x), dr.rcp(d.y), dr.rcp(d.z))
        sx = dr.select(d.x >= 0.0, Int(1), Int(-1))
        sy = dr.select(d.y >= 0.0, Int(1), Int(-1))
        top, ncx, ncy = self.top, self.ncx, self.ncy
        x0, y0, dx, dy = self._x0, self._y0, self._dx, self._dy
        max_iter = self._max_iter
        offsets = [int(v) for v in self.mipmap.offsets]

        def cells(lvl):
            # Cells per row and column at level lvl: ceil(n / 2^lvl).
            one = Int(1) << lvl
            return (ncx + one - 1) >> lvl, (ncy + one - 1) >> lvl

        def step_fn(t, t_hi, lvl, ci, cj, found, t_hit, alive, ended, it):
            size = Float(Int(1) << lvl)
            csx, csy = dx * size, dy * size
            ex = x0 + Float(dr.select(d.x >= 0.0, ci + 1, ci)) * csx
            ey = y0 + Float(dr.select(d.y >= 0.0, cj + 1, cj)) * csy
            tx = dr.select(d.x != 0.0, (ex - o.x) * inv.x, inf)
            ty = dr.select(d.y != 0.0, (ey - o.y) * inv.y, inf)
            t_wall = dr.minimum(tx, ty)
            t_exit = dr.minimum(t_wall, t_hi)
            nxl, _ = cells(lvl)
            off = UInt(0)
            for l_, o_ in enumerate(offsets):
                off = dr.select(lvl == l_, UInt(o_), off) if l_ else off
            k = off + UInt(cj * nxl + ci)
            zmax = dr.gather(Float, self._max, k, alive)
            za, zb = o.z + d.z * t, o.z + d.z * t_exit
            zlow = dr.minimum(za, zb)
            empty = t > t_hi
            touch = alive & ~empty & (zlow <= zmax)
            leaf = touch & (lvl == 0)

            # Exact ray-patch test on [t, t_exit] (module docstring), skipped by
            # SIMD packets without a lane at level 0.
            def patch_test(t, t_exit, za, ci, cj, leaf):
                h00, h10, h01, h11 = dr.gather(mi.Vector4f, self._corners, UInt(cj * ncx + ci), leaf)
                ua = (o.x + d.x * t - x0) * self._inv_dx - Float(ci)
                va = (o.y + d.y * t - y0) * self._inv_dy - Float(cj)
                C = dr.lerp(dr.lerp(h00, h10, ua), dr.lerp(h01, h11, ua), va) - za
                du, dv = d.x * self._inv_dx, d.y * self._inv_dy
                bu, bv, e = h10 - h00, h01 - h00, (h11 - h01) - (h10 - h00)
                B = bu * du + bv * dv + e * (ua * dv + va * du) - d.z
                A = e * du * dv
                sb = dr.maximum(t_exit - t, 0.0)
                g1 = C + sb * (B + A * sb)
                s_star = -B / (2.0 * A)
                inner = (A != 0.0) & (s_star > 0.0) & (s_star < sb)
                cap = inner & (A < 0.0)
                gmax = dr.select(cap, C + s_star * (B + A * s_star), -inf)
                patch = leaf & ((C >= 0.0) | (g1 >= 0.0) | (gmax >= 0.0))
                # The monotone bracket [lo, hi] holding the first root.
                lo = dr.select(inner & (A > 0.0), s_star, 0.0)
                hi = dr.select(cap & (gmax >= 0.0), s_star, sb)
                sq = dr.sqrt(dr.maximum(dr.fma(B, B, -4.0 * A * C), 0.0))
                root = dr.select(B >= 0.0, -2.0 * C / (B + sq), (sq - B) / (2.0 * A))
                root = dr.select(dr.isfinite(root), dr.clip(root, lo, hi), hi)
                return patch, dr.select(C >= 0.0, 0.0, root)

            patch, s_hit = dr.if_stmt((t, t_exit, za, ci, cj, leaf), leaf, patch_test,
                                      lambda *a: (mi.Bool(False), Float(0.0)), label="hf_patch")

            # Certain hit for shadow rays: the ray sinks below the cell's minimum.
            hit_now = patch
            if any_hit:
                zmin = dr.gather(Float, self._min, k, touch)
                hit_now = patch | (touch & (zlow <= zmin))
            t_now = dr.select(patch, t + s_hit, t)

            # Descend: advance to where the ray sinks below the cell's maximum.
            down = touch & (lvl > 0) & ~hit_now
            t_d = dr.select(za > zmax, t + (zmax - za) * inv.z, t)
            t_d = dr.maximum(dr.minimum(t_d, t_exit), t)
            half_x, half_y = csx * 0.5, csy * 0.5
            right = o.x + d.x * t_d >= x0 + Float(2 * ci + 1) * half_x
            upper = o.y + d.y * t_d >= y0 + Float(2 * cj + 1) * half_y
            cnx, cny = cells(dr.maximum(lvl - 1, 0))
            ci_d = dr.minimum(2 * ci + dr.select(right, Int(1), Int(0)), cnx - 1)
            cj_d = dr.minimum(2 * cj + dr.select(upper, Int(1), Int(0)), cny - 1)

            # Step through the exit wall; go up when leaving the parent cell.
            step = alive & ~hit_now & ~down
            go_x = tx <= ty
            ci_s = ci + dr.select(go_x, sx, 0)
            cj_s = cj + dr.select(go_x, 0, sy)
            up = (lvl < top) & (((ci_s >> 1) != (ci >> 1)) | ((cj_s >> 1) != (cj >> 1)))
            ci_s, cj_s = dr.select(up, ci_s >> 1, ci_s), dr.select(up, cj_s >> 1, cj_s)
            lvl_s = dr.select(up, lvl + 1, lvl)
            unx, uny = cells(lvl_s)
            out = (ci_s < 0) | (ci_s >= unx) | (cj_s < 0) | (cj_s >= uny)
            # The stretch is done: its end lies in this cell, or the ray left the grid.
            ends = step & (empty | (t_wall >= t_hi) | out)
            step = step & ~ends

            t = dr.select(down, t_d, dr.select(step, dr.maximum(t, t_exit), t))
            lvl = dr.select(down, lvl - 1, dr.select(step, lvl_s, lvl))
            ci = dr.select(down, ci_d, dr.select(step, ci_s, ci))
            cj = dr.select(down, cj_d, dr.select(step, cj_s, cj))
            found = found | hit_now
            t_hit = dr.select(hit_now, t_now, t_hit)
            # Termination follows from the integer steps; a budget guards it anyway.
            alive = alive & (~hit_now & ~ends & (it + 1 < max_iter))
            return t, t_hi, lvl, ci, cj, found, t_hit, alive, ended | ends, it + 1

        return step_fn

    @property
    def _max_iter(self):
        # At most top descents per ascent, ascents <= cells crossed.
        return self.top + 2 * (self.top + 2 * (self.ncx + self.ncy)) + 16


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
