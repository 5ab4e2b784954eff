"""Camera rays marched in bundles: one cone proves the empty space in front of its rays.

Why. A camera ray sphere-traces the whole way from the camera, and its first dozen
steps cross air that its neighbours cross too (goblins, 160x90, 8 spp: 33 steps a ray,
12 of them granted more than 5 m). Consecutive camera lanes are one pixel's samples
(Mitsuba hands a pass's samples pixel by pixel), so a bundle of ``BUNDLE_LANES``
consecutive rays lies in a thin cone; one march of the cone's axis, with free *balls*
in place of the rays' free lengths, proves the air in front of every ray of the bundle,
and each ray then starts where the cone stopped (Amanatides 1984 traces cones; the
bundle here only skips air, the rays still find their own hits).

The cone. A bundle's rays ``o_i + t d_i`` (unit ``d_i``) and its axis ``o_a + t d_a``
(the mean origin and direction of its lanes) give ``delta = max |o_i - o_a|`` and
``c = max |d_i - d_a|``. For ``t' = t + u``, ``0 <= u``,

    |o_i + t' d_i - (o_a + t d_a)| = |(o_i - o_a) + t (d_i - d_a) + u d_i| <= delta + c t + u,

so if the axis point ``p = o_a + t d_a`` has a free ball of radius ``r`` (no point of
the solid ``{f >= 0}`` closer than ``r``: ``eval_bounds`` without a direction,
:mod:`arches_render.field.node`), every ray is free over ``[t, t + s]`` with
``s = r - delta - c t``. The axis advances by ``s`` while ``s`` is more than
``STOP_FRACTION`` of ``r`` (nearer the surface the cone's own width eats the step),
from the bundle's first box entry up to its last exit, and each ray starts at
``max(its own start, t)``. Rays whose whole segment lies behind that point miss.

Level of detail. With cones (footprint level of detail, :mod:`arches_render.field.lod`)
the axis is evaluated as the footprint field of its lanes' cone at ``t``, the field the
rays evaluate there (camera rays share one cone: ``(0, s)``); a bundle whose lanes'
cones differ is not marched. Everything proven is the footprint field's, as a sphere
tracer's own step is.

Cost. A bundle marches at a sixteenth of the rays' width, a few ball bounds a ray; the
rays' own marches lose the steps through open air (160x90, 8 spp, first camera, mean /
packet of 16: goblins 33.3 / 41.7 -> 19.6 / 27.5 steps a ray, the arch bridge 25.9 / 29.0
-> 12.6 / 15.6, floating islands 17.4 / 19.8 -> 7.7 / 9.9, the sea cliffs 15.8 / 18.3 ->
8.9 / 11.2), at 0.35 - 1.7 cone steps a ray. Field renders of those scenes took 0-11 %
less. Hits move within the hit tolerance (a ray starts elsewhere and steps elsewhere);
on grazing rays, which a tracer may find or step over, they may change.

References
----------
Amanatides, J. (1984). Ray tracing with cones. SIGGRAPH '84, 129-135.
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .march import ray_box

__all__ = ["BUNDLE_LANES", "BUNDLE_STEPS", "STOP_FRACTION", "bundle_starts"]

#: Consecutive lanes a bundle holds: one SIMD packet of Dr.Jit's LLVM backend (AVX-512).
BUNDLE_LANES = 16

#: The cone stops where its step would be less than this part of the axis' free ball
#: (goblins' first camera: 0.25, 0.5 and 0.75 left 19.7, 21.4 and 24.2 steps a ray to
#: march, at 1.9, 1.4 and 0.9 cone steps a ray).
STOP_FRACTION = 0.5

#: Steps a cone takes at most (it stops where it is; what it proved stays proven).
BUNDLE_STEPS = 64


def _group_reduce(op, value, group, count, init):
    """``value`` reduced by ``op`` over the lanes of each group (``count`` groups)."""
    out = dr.full(type(value), init, count)
    dr.scatter_reduce(op, out, value, group)
    return out


@dr.syntax
def bundle_starts(tracer, o, d, tmax, active, cone=None, lanes=BUNDLE_LANES):
    """Where each ray of ``o + t d`` may start its march: the end of the air its bundle's
    cone proves free (module docstring), at least the ray's own start.

    Parameters
    ----------
    tracer : SphereTracer
        Its field (``field``, ``footprint``) and box (``lo_op``, ``hi_op``).
    o, d : mi.Point3f, mi.Vector3f
        Ray origins and unit directions, bundled by ``lanes`` consecutive lanes.
    tmax : mi.Float
        The rays' far ends.
    active : mi.Bool
        The rays to trace.
    cone : (mi.Float, mi.Float), optional
        Each ray's cone ``(r0, s)``; None: full detail.
    lanes : int
        Lanes a bundle.

    Returns
    -------
    mi.Float
        Per lane, a distance from which the ray's march may start (``0`` where nothing
        is proven; past ``tmax`` where the ray's whole segment is free).
    """
    width = max(dr.width(o), dr.width(d), dr.width(active))
    o, d = mi.Point3f(o) + dr.zeros(mi.Point3f, width), mi.Vector3f(d) + dr.zeros(mi.Vector3f, width)
    active = mi.Bool(active) & dr.full(mi.Bool, True, width)
    count = (width + lanes - 1) // lanes
    group = dr.arange(mi.UInt32, width) // lanes
    t_in, t_out = ray_box(o, d, tracer.lo_op, tracer.hi_op)
    t_start = dr.maximum(t_in, 0.0)
    t_end = dr.minimum(t_out, tmax)
    active &= t_start <= t_end
    # The axis: the mean origin and direction of the bundle's active lanes.
    weight = dr.select(active, 1.0, 0.0)
    n = _group_reduce(dr.ReduceOp.Add, weight, group, count, 0.0)
    o_a = mi.Point3f(*(_group_reduce(dr.ReduceOp.Add, o[k] * weight, group, count, 0.0) for k in range(3)))
    d_a = mi.Vector3f(*(_group_reduce(dr.ReduceOp.Add, d[k] * weight, group, count, 0.0) for k in range(3)))
    o_a = o_a / dr.maximum(n, 1.0)
    d_a = dr.normalize(d_a)
    # Each lane's offset and chord from the axis, and the bundle's interval.
    delta = dr.norm(o - dr.gather(mi.Point3f, o_a, group))
    chord = dr.norm(d - dr.gather(mi.Vector3f, d_a, group))
    delta = _group_reduce(dr.ReduceOp.Max, dr.select(active, delta, 0.0), group, count, 0.0)
    chord = _group_reduce(dr.ReduceOp.Max, dr.select(active, chord, 0.0), group, count, 0.0)
    t_lo = _group_reduce(dr.ReduceOp.Min, dr.select(active, t_start, dr.inf), group, count, dr.inf)
    t_hi = _group_reduce(dr.ReduceOp.Max, dr.select(active, t_end, -dr.inf), group, count, -dr.inf)
    # Rounding: the bounds grow by a few float32 ulps of what they bound.
    delta = delta * (1.0 + 1e-5) + 1e-5 * dr.max(dr.abs(o_a))
    chord = chord * (1.0 + 1e-5) + 1e-6
    go = (n > 0.0) & (t_lo <= t_hi) & dr.isfinite(t_lo)
    axis_cone = None
    if cone is not None:
        r0 = mi.Float(cone[0]) + dr.zeros(mi.Float, width)
        s = mi.Float(cone[1]) + dr.zeros(mi.Float, width)
        r0_lo = _group_reduce(dr.ReduceOp.Min, dr.select(active, r0, dr.inf), group, count, dr.inf)
        r0_hi = _group_reduce(dr.ReduceOp.Max, dr.select(active, r0, -dr.inf), group, count, -dr.inf)
        s_lo = _group_reduce(dr.ReduceOp.Min, dr.select(active, s, dr.inf), group, count, dr.inf)
        s_hi = _group_reduce(dr.ReduceOp.Max, dr.select(active, s, -dr.inf), group, count, -dr.inf)
        go &= (r0_lo == r0_hi) & (s_lo == s_hi)  # one footprint field a bundle (module docstring)
        axis_cone = (r0_lo, s_lo)
    dr.eval(o_a, d_a, delta, chord, t_lo, t_hi, go, axis_cone)

    t = dr.select(go, t_lo, 0.0)
    steps = mi.UInt32(0)
    # Read-only values stay out of the loop's state (integrator.sample_megakernel).
    while dr.hint(go, label="ray_bundle", exclude=[tracer, o_a, d_a, delta, chord, t_hi, axis_cone]):
        _, (r,) = tracer.field.eval_bounds(o_a + d_a * t, (0.0,), None, tracer.footprint(axis_cone, t))
        advance = r - delta - chord * t
        go &= advance > STOP_FRACTION * r  # (false for a NaN: nothing more is proven)
        t = dr.select(go, t + advance, t)
        steps += 1
        go &= (t < t_hi) & (steps < BUNDLE_STEPS)
    return dr.select(active, dr.maximum(t_start, dr.gather(mi.Float, t, group)), 0.0)
