"""Sphere tracing of a field with over-relaxed, Lipschitz-safe steps.

For a field ``f`` (positive inside) with Lipschitz bound ``L``, a point ``p`` in air
is at least ``r(p) = -f(p) / L`` away from the surface (Hart 1996), so a ray may
advance by ``r``. The tracer uses the tighter local bound ``r`` composed through the
operators by ``Node.eval_bounds`` (same guarantee, see :mod:`arches_render.field.node`)
and over-relaxed steps whose safety is checked after the fact: the step, its loop
state and its stop rule are :mod:`.march`'s, shared by every tracer.

Cones (footprint level of detail, :mod:`arches_render.field.lod`): a query may
give each lane its cone ``(r0, s)``, radius ``r0 + s t`` at distance ``t``. The field
is then evaluated as the footprint field of that cone (octaves finer than the cone
skipped, rigorous bounds), and the hit tolerance follows the cone as in cone
tracing: ``-f < max(eps t, min(CONE_TOLERANCE s t, eps diag))``, the cone's part
capped at ``eps`` times the field's diagonal, the largest tolerance the culled tree
was built for (see :mod:`arches_render.field.culling`). ``r0`` stays out of the tolerance: a secondary
ray starts on a surface, where a tolerance of its starting radius would stop it at
once.

References
----------
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
Amanatides, J. (1984). Ray tracing with cones. SIGGRAPH '84, 129-135.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..field import gradient
from ..field.culling import with_culling
from ..field.lod import Footprint
from ..field.node import finite_box, one_sided, shading_normals
from .march import (SECOND_PASS_FACTOR, March, ShadowProbe, march_result, position_ulps, ray_box, relaxed_step,
                    secant_probe)
from .ray_bundles import bundle_starts
from .ray_queue import queued_march
from .sun_columns import SUN_HALF_ANGLE, SunColumns

#: Fraction of the cone's radius that a hit may stay in front of the surface. At a
#: camera ray's cone it is about ``eps t``: silhouettes are not dilated (a hit within
#: the tolerance of an edge the ray would pass counts as a hit; 0.25 shifted the
#: mean of the boulders scene against its mesh by 0.75 %). Bounce rays, whose cones
#: are wide, stop much earlier.
CONE_TOLERANCE = 0.05


class SphereTracer:
    """Ray queries against one field.

    Parameters
    ----------
    field : Node
        The construction tree (bounded: its ``bounds()`` must be finite).
    eps : float
        Relative hit tolerance: stop when ``-f < eps t``.
    omega : float
        Over-relaxation factor in ``[1, 2)``.
    max_steps : int
        First step budget per ray; an *exhausted* ray gets ``SECOND_PASS_FACTOR``
        times more, and one that spends those too is resolved as a hit
        (:meth:`query`).
    """

    def __init__(self, field, eps=2e-4, omega=1.6, max_steps=512):
        box = finite_box(field)
        if box is None:
            raise ValueError("the field is unbounded: intersect it with a box")
        lo, hi = box
        pad = 1e-3 * float(np.max(hi - lo)) + 1e-4
        self.lo, self.hi = [float(v) - pad for v in lo], [float(v) + pad for v in hi]
        self.scale = float(np.linalg.norm(np.asarray(self.hi) - np.asarray(self.lo)))
        # Culling must keep values exact wherever the tracer looks closely: hits
        # (|f| < eps t) and gradient taps (h <= eps t / 2 away, so |f| grows by at
        # most L sqrt(3) h); t is bounded by the box's diagonal.
        self.field = with_culling(field, eps * self.scale * (1.0 + float(field.lipschitz)))
        # Opaque copies for the kernels: a field whose parameters move its box
        # (a lookdev edit) re-uses the compiled kernels.
        self.lo_op = [dr.opaque(mi.Float, v) for v in self.lo]
        self.hi_op = [dr.opaque(mi.Float, v) for v in self.hi]
        self.scale_op = dr.opaque(mi.Float, self.scale)
        self.eps = dr.opaque(mi.Float, eps)
        self.eps_np = float(eps)
        self.omega = float(omega)
        self.max_steps = int(max_steps)
        self.sun = None
        #: March by persistent lanes (:mod:`.ray_queue`): queries must then come with
        #: their rays evaluable (not from inside a symbolic loop).
        self.queued = False

    def aim_at_sun(self, direction, half_angle=SUN_HALF_ANGLE):
        """Build the :class:`~.sun_columns.SunColumns` of this field for a sun towards
        ``direction`` (within ``half_angle`` radians; 0 for a directional light):
        shadow rays towards it then stop where the map proves the rest free, or at
        once where it proves them in rock (:meth:`query`)."""
        self.sun = SunColumns(self.field, self.lo, self.hi, direction, self.eps_np * self.scale,
                              half_angle=half_angle)

    def tolerance(self, t, cone=None):
        """Hit tolerance at distance ``t``: ``eps t``, or with a cone ``(r0, s)`` the
        cone-tracing tolerance of the module docstring."""
        tol = self.eps * t
        if cone is None:
            return tol
        return dr.maximum(tol, dr.minimum(CONE_TOLERANCE * cone[1] * t, self.eps * self.scale_op))

    @staticmethod
    def footprint(cone, t):
        """The :class:`~arches_render.field.lod.Footprint` of ``cone`` at ``t`` (None: none)."""
        return None if cone is None else Footprint.on_ray(cone[0], cone[1], t)

    def query(self, o, d, tmax, active, cone=None, any_hit=False, coherent=False, t_min=None):
        """First hit of the rays ``o + t d`` (``|d| = 1``) with ``0 <= t <= tmax``, with
        the ray's step count and whether it used up its budgets.

        A ray that has neither found a hit nor proved ``[t_start, t_end]`` free after
        ``max_steps`` steps is *exhausted* and goes on for up to
        ``SECOND_PASS_FACTOR * max_steps`` more; one that spends those too is
        *unresolved* and reported as a hit at its last point (for a shadow ray:
        occluded), never as a miss; the ``exhausted`` and ``unresolved`` AOVs
        count them (:mod:`.aovs`). Both budgets run in one loop: inside Mitsuba's megakernel a loop ends per SIMD
        packet, so a packet whose lanes are all done stops whatever the budget, and
        a second loop would only emit the field's code twice.

        Parameters
        ----------
        o, d, tmax, active
            Ray origins, unit directions, far ends and lanes.
        cone : (mi.Float, mi.Float), optional
            ``(r0, s)``: each lane's cone (module docstring); None: full detail.
        any_hit : bool
            A shadow ray: it may probe ahead (:mod:`.march`, "Shadow probes"), and stops
            at the first point it finds within the tolerance of the solid or inside it,
            which need not be the first hit along it (``t`` is that point's); with a
            sun map (:meth:`aim_at_sun`) a ray towards the sun stops where the map proves
            the rest of it free, and one it proves in rock is a hit without a step (``t``
            its start). Every hit of the sphere tracer is certain.
        coherent : bool
            Rays that travel together, as camera rays (Mitsuba's ``ray_intersect`` hint):
            marched in plain packets even when :attr:`queued`. The queue hands a lane
            whose ray ended the next ray in line, so a packet soon holds rays from
            across the frame, while a plain packet of camera rays holds two pixels'
            samples, which march alike (wavefront renders, 160x90, 8 spp, every camera:
            floating islands 0.79 -> 0.52 s, every_generator 3.0 -> 2.4-2.6 s, the arch
            bridge 1.05-1.14 -> 0.92-1.03 s; goblins 1.55 -> 1.50 s).
        t_min : mi.Float, optional
            Where each ray may start: ``[0, t_min]`` is known to be free (camera rays
            marched in bundles: :meth:`bundle_starts`); a ray whose segment ends before it
            misses.

        Returns
        -------
        TraceResult
        """
        t_in, t_out = ray_box(o, d, self.lo_op, self.hi_op)
        t_start = dr.maximum(t_in, 0.0) if t_min is None else dr.maximum(dr.maximum(t_in, 0.0), t_min)
        t_end = dr.minimum(t_out, tmax)
        march = self._queued if self.queued and not coherent else self._march
        if not (any_hit and self.sun is not None):
            active = mi.Bool(active) & (t_start <= t_end)
            return march(mi.Point3f(o), mi.Vector3f(d), t_start, t_end, active, cone, any_hit)
        t_cap, rock = self.sun.limits(o, d, tmax)
        rock &= mi.Bool(active) & (t_start <= t_end)
        t_end = dr.minimum(t_end, t_cap)
        active = mi.Bool(active) & ~rock & (t_start <= t_end)
        res = march(mi.Point3f(o), mi.Vector3f(d), t_start, t_end, active, cone, any_hit)
        res.hit |= rock
        res.t = dr.select(rock, t_start, res.t)
        return res

    @dr.syntax
    def _march(self, o, d, t_start, t_end, active, cone, any_hit=False):
        """The loop of :meth:`query` over ``[t_start, t_end]``; see :mod:`.march`."""
        budget = self.max_steps * (1 + SECOND_PASS_FACTOR)
        march = March.start(t_start, self.omega)
        # A shadow ray's probe state (march, "Shadow probes"); None for other rays.
        shadow = ShadowProbe.start(dr.width(t_start)) if any_hit else None
        hit = mi.Bool(False)
        invalid = mi.Bool(False)
        alive = mi.Bool(active)
        steps = mi.UInt32(0)
        # The budget ends the loop (its condition), not ``alive``: a lane still alive
        # when it runs out is what march_result reports as unresolved.
        # Read-only values stay out of the loop's state: Dr.Jit records a loop's body
        # again to drop a variable it leaves unchanged (integrator.sample_megakernel).
        while dr.hint(alive & (steps < budget), label="sphere_trace", exclude=[self, o, d, t_end, cone]):
            if dr.hint(any_hit, mode="scalar"):
                march, out, _, shadow = self.step(o, d, march, t_end, cone, shadow)
            else:
                march, out, _ = self.step(o, d, march, t_end, cone)
            hit |= out.hit
            invalid |= out.invalid
            alive &= ~(out.hit | out.done | out.invalid)
            steps += 1
        return march_result(march, hit, alive, invalid, steps, active, self.max_steps)

    def _queued(self, o, d, t_start, t_end, active, cone, any_hit=False):
        """:meth:`_march` by persistent lanes (:func:`.ray_queue.queued_march`)."""
        return queued_march(self, o, d, t_start, t_end, active, cone, any_hit)

    def step(self, o, d, march, t_end, cone=None, shadow=None):
        """One over-relaxed sphere step of the rays ``o + t d`` from ``march.t``
        (:func:`~.march.relaxed_step`): ``(march, outcome, r)``, ``r`` the free radius
        the field granted there; with ``shadow`` (a :class:`~.march.ShadowProbe`), a
        shadow ray's step, which may probe (:mod:`.march`, "Shadow probes"), and its
        probe state after the step as a fourth item."""
        t = march.t
        # A point reached without a relaxed step (the ray's start, the frontier after a
        # failed step, a plain step) needs no free length behind it, only ahead: the
        # overlap test asks a point for what lies behind it only when a relaxed step
        # led there (field.node, "Ahead"). A ray leaving a surface then steps away at once.
        with one_sided((march.step <= 0.0) | (march.omega <= 1.0)):
            f, (r,) = self.field.eval_bounds(o + d * t, (0.0,), d, self.footprint(cone, t))
        probe = None if shadow is None else secant_probe(march, f, shadow, t_end)
        new, out = relaxed_step(march, f, r, t_end, self.tolerance(t, cone), self.omega, probe)
        if shadow is None:
            return new, out, r
        return new, out, r, shadow.after(out, f)

    def bundle_starts(self, o, d, tmax, active, cone=None):
        """Where camera rays ``o + t d`` may start (:func:`.ray_bundles.bundle_starts`):
        the ``t_min`` of :meth:`query`."""
        return bundle_starts(self, o, d, tmax, active, cone)

    def trace(self, o, d, tmax, active, cone=None):
        """``(hit, t)`` of :meth:`query` (unresolved rays count as hits)."""
        r = self.query(o, d, tmax, active, cone)
        return r.hit, r.t

    def occluded(self, o, d, tmax, active, cone=None):
        """Whether the segments ``o + t d``, ``0 <= t <= tmax``, meet the surface
        (unresolved rays count as occluded)."""
        return self.query(o, d, tmax, active, cone, any_hit=True).hit

    def surface(self, p, t, d=None, cone=None):
        """Surface point and outward normal for hits ``p`` found at distance ``t``
        along direction ``d`` (with ``cone``: of the footprint field that ray traced).

        A hit stops up to its tolerance in front of the surface; one Newton step along
        the gradient, ``p - f grad f / |grad f|^2``, puts it on the surface up to
        second order, so that rays spawned from it need only a tiny offset (an
        offset of the size of the tolerance lets light leak past contact shadows).

        Returns
        -------
        (mi.Point3f, mi.Vector3f)
            Projected point and unit normal ``-grad f / |grad f|``. Where the
            gradient vanishes (a ray that starts inside a saturated field, e.g.
            deep in an implicit heightfield whose value is constant there) the
            normal faces the ray, ``-d`` (or +Z without ``d``), instead of NaN.
        """
        # Gradient taps half the tolerance apart, never below the float32 resolution of p.
        h = dr.maximum(0.5 * self.eps * t, position_ulps(p, 64.0))
        fp = self.footprint(cone, t)
        # The normal of the C1 stand-ins (a heightfield's box-filtered elevation: shading_normals).
        with shading_normals():
            g = gradient(self.field, p, h, culled=True, footprint=fp)
        f = self.field.eval_bounds(p, (), footprint=fp)[0]
        g2 = dr.squared_norm(g)
        step = dr.select(g2 > 0.0, f / g2, 0.0)
        # Never move farther than the tolerance that stopped the ray.
        tol = self.tolerance(t, cone)
        step = dr.clip(step * dr.sqrt(g2), -tol, tol) * dr.rsqrt(dr.maximum(g2, 1e-30))
        fallback = -d if d is not None else mi.Vector3f(0.0, 0.0, 1.0)
        n = dr.select(g2 > 1e-30, -g * dr.rsqrt(dr.maximum(g2, 1e-30)), fallback)
        return p - g * step, n
