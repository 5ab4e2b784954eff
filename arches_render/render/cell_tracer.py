"""Ray queries through surface cells: empty space skipped, the field stepped where the surface may be.

A :class:`~arches_render.field.surface_cells.SurfaceCells` structure over the
field's box says, for each leaf cell (or uniform brick), whether it is *air* for a
footprint class and how far around it everything is air too (a cube of cells). A
ray at a verified point ``t`` (one its march has proven free up to) whose cell is air
for the class of its footprint, and whose cube holds ``p(t)``, jumps to where it
leaves that cube, without evaluating the field: the cube is free for every
footprint field of that class. Elsewhere it takes the over-relaxed sphere steps of
:mod:`.march` on the full tree (whose bounds hold everywhere, so a step may leave
its cell). A relaxed point is never skipped from: the step that led there is
checked first.

The footprint class of a ray at ``t`` is the first whose radius ``rho_k`` holds the
ray's cone there (``r0 + s t``); a jump stops where the cone outgrows it. Without a
cone (full detail) every class holds.

Every hit is one the sphere tracer would find: an air cell holds no point within
the tracer's largest hit tolerance of the surface (the structure is built with that
slack). Cube exits are computed in float32 from the cell's box, so a jump may end
an ulp inside the next cell: far below the hit tolerance.

References
----------
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
Amanatides, J., Woo, A. (1987). A fast voxel traversal algorithm for ray tracing.
Eurographics '87 (cells stepped to their exit).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..field.surface_cells import SurfaceCells
from .march import SECOND_PASS_FACTOR, March, TraceResult, march_result, ray_box
from .sphere_tracer import SphereTracer

#: Default leaf edge: the longest side of the field's box over this many leaves.
LEAVES_ALONG = 256
#: Where a point's cell is looked up, ahead of it along the ray, in leaf edges (a
#: point on a cell's exit face reads the next cell).
NUDGE = 1e-3
#: Where a shadow ray probes for rock before it steps: fractions of its segment
#: (below 1), and ``1 + n`` for ``n`` leaf edges from its origin.
PROBES = (0.0625, 0.1875, 0.3125, 0.4375, 0.5625, 0.6875, 0.8125, 0.9375, 2.0, 4.0, 10.0, 28.0)


class CellTracer:
    """Sphere tracing through surface cells (module docstring); the interface of
    :class:`~.sphere_tracer.SphereTracer` (``query``, ``trace``, ``occluded``,
    ``surface``, ``tolerance``, ``eps``, ``scale_op``).

    Parameters
    ----------
    field : Node
        The construction tree (bounded).
    eps, omega, max_steps
        As for :class:`~.sphere_tracer.SphereTracer`.
    leaf : float, optional
        Leaf edge of the cells (default: the box's longest side / ``LEAVES_ALONG``).
    """

    def __init__(self, field, eps=2e-4, omega=1.6, max_steps=512, leaf=None):
        self.sphere = SphereTracer(field, eps=eps, omega=omega, max_steps=max_steps)
        self.field, self.eps, self.scale_op, self.scale = (self.sphere.field, self.sphere.eps, self.sphere.scale_op,
                                                           self.sphere.scale)
        self.omega, self.max_steps = float(omega), int(max_steps)
        lo, hi = np.asarray(self.sphere.lo), np.asarray(self.sphere.hi)
        leaf = float(np.max(hi - lo)) / LEAVES_ALONG if leaf is None else float(leaf)
        # The largest hit tolerance (a cone's part is capped at eps times the diagonal).
        self.cells = SurfaceCells(self.field, lo, hi, leaf, slack=float(eps) * self.scale)
        self._nudge = dr.opaque(mi.Float, NUDGE * leaf)
        self._leaf = dr.opaque(mi.Float, leaf)

    # -- public queries ------------------------------------------------------------
    def query(self, o, d, tmax, active, cone=None, any_hit=False, coherent=False, t_min=None):
        """First hits (:meth:`SphereTracer.query`; ``cells``: the cells jumped over;
        ``coherent`` changes nothing: no queue)."""
        t_in, t_out = ray_box(o, d, self.sphere.lo_op, self.sphere.hi_op)
        t_start = dr.maximum(t_in, 0.0) if t_min is None else dr.maximum(dr.maximum(t_in, 0.0), t_min)
        t_end = dr.minimum(t_out, tmax)
        active = mi.Bool(active) & (t_start <= t_end)
        o, d = mi.Point3f(o), mi.Vector3f(d)
        blocked = mi.Bool(False)
        if any_hit:
            # Shadow rays: a point of the segment in rock is an occlusion, whatever
            # lies before it. Probes near the origin and along the whole segment.
            for u in PROBES:
                t = t_start + u * (t_end - t_start) if u < 1.0 else t_start + (u - 1.0) * self._leaf
                blocked |= (t <= t_end) & self._rock(o, d, t, cone)
        res = self._march(o, d, t_start, t_end, active & ~blocked, cone, any_hit)
        return TraceResult(hit=res.hit | (active & blocked), t=res.t, steps=res.steps, exhausted=res.exhausted,
                           unresolved=res.unresolved, cells=res.cells)

    def trace(self, o, d, tmax, active, cone=None):
        """``(hit, t)`` of :meth:`query` (unresolved rays count as hits)."""
        r = self.query(o, d, tmax, active, cone)
        return r.hit, r.t

    def occluded(self, o, d, tmax, active, cone=None):
        """Whether the segments ``o + t d``, ``0 <= t <= tmax``, meet the surface."""
        return self.query(o, d, tmax, active, cone, any_hit=True).hit

    def tolerance(self, t, cone=None):
        """Hit tolerance (:meth:`SphereTracer.tolerance`)."""
        return self.sphere.tolerance(t, cone)

    def surface(self, p, t, d=None, cone=None):
        """Surface point and normal of a hit (:meth:`SphereTracer.surface`)."""
        return self.sphere.surface(p, t, d, cone)

    # -- implementation ----------------------------------------------------------------
    @dr.syntax
    def _march(self, o, d, t_start, t_end, active, cone, any_hit=False):
        """The loop of :meth:`query` over ``[t_start, t_end]``."""
        budget = self.max_steps * (1 + SECOND_PASS_FACTOR)
        march = March.start(t_start, self.omega)
        hit = mi.Bool(False)
        invalid = mi.Bool(False)
        alive = mi.Bool(active)
        steps = mi.UInt32(0)
        cells = mi.UInt32(0)
        # Read-only values stay out of the loop's state: Dr.Jit records a loop's body
        # again to drop a variable it leaves unchanged (integrator.sample_megakernel).
        while dr.hint(alive & (steps < budget), label="cell_trace", exclude=[self, o, d, t_end, cone]):
            # A jump over empty cells where the ray's point allows one, then a sphere
            # step from where it lands: each iteration evaluates the field once, so a
            # packet whose lanes disagree runs one body, and the jumps ride along.
            t_jump = self._jump(o, d, march.t, march.frontier, t_end, cone)
            jumped = t_jump > march.t
            march = dr.select(jumped, March.start(t_jump, self.omega), march)
            cells += dr.select(jumped, 1, 0)
            t = march.t
            march, out, _ = self.sphere.step(o, d, march, t_end, cone)
            if dr.hint(any_hit, mode="scalar"):
                # Look ahead, one scale an iteration (1 to 128 leaves): a grazing ray
                # crawling towards rock it will meet stops as soon as it sees it.
                ahead = t + self._leaf * mi.Float(mi.UInt32(1) << (steps & 7))
                rock = alive & ~out.hit & (ahead <= t_end) & self._rock(o, d, ahead, cone)
                hit |= rock
                alive &= ~rock
            hit |= out.hit
            invalid |= out.invalid
            alive &= ~(out.hit | out.done | out.invalid)
            steps += 1
        return march_result(march, hit, alive, invalid, steps, active, self.max_steps, cells)

    def _class(self, t, cone):
        """``(k, t_limit)``: the footprint class of the rays at ``t`` (0: none holds their
        cone) and how far along the ray it keeps holding."""
        radii = self.cells._radii
        k, t_limit = mi.UInt32(0), mi.Float(dr.inf)
        for i in reversed(range(len(radii))):
            if cone is None:
                fits, limit = mi.Bool(True), mi.Float(dr.inf)
            else:
                r0, s = cone
                fits = r0 + s * t <= radii[i]
                limit = dr.select(s > 0.0, (radii[i] - r0) * dr.rcp(s), dr.inf)
            k = dr.select(fits, i + 1, k)
            t_limit = dr.select(fits, limit, t_limit)
        return k, t_limit

    def _rock(self, o, d, t, cone):
        """Whether the rays' points at ``t`` are in rock for their footprint's class."""
        _, solid, _, _, _ = self.cells.lookup(o + d * t)
        k, _ = self._class(t, cone)
        return (k >= 1) & (solid >= k)

    def _jump(self, o, d, t, frontier, t_end, cone):
        """Where a ray at ``t`` may jump to through empty cells (``t`` itself where it may
        not: a relaxed point, a cell that is not air for the ray's footprint class, or
        a point outside the cell's empty cube)."""
        air, _, reach, lo, hi = self.cells.lookup(o + d * (t + self._nudge))
        k, t_limit = self._class(t, cone)
        D = mi.UInt32(0)
        for i, r in enumerate(reach):
            D = dr.select(k == i + 1, r, D)
        ok = (t <= frontier) & (k >= 1) & (air >= k)
        grow = mi.Float(dr.maximum(D, 1) - 1) * (hi.x - lo.x)
        t0, t1 = ray_box(o, d, lo - grow, hi + grow)
        ok &= t0 <= t
        t_jump = dr.minimum(dr.minimum(t1, t_limit), t_end)
        return dr.select(ok & (t_jump > t), t_jump, t)
