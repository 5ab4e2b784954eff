"""Persistent lanes: a sphere march whose lanes take the next ray from a queue.

Why. Dr.Jit's LLVM backend runs a loop per SIMD packet of 16 lanes until its slowest
lane is done, so a packet's cost is its longest ray's: shadow and bounce rays leave
neighbouring pixels in unrelated directions, and a packet of them took 1.7-2.2 times
the steps of its mean ray (goblins, 320x180: shadow 32 steps a ray, 55 a packet; bounce
29 and 65). Here a lane whose ray ends (a hit, the ray leaves, its budget runs out)
writes its result and takes the next ray of the query from a queue (an atomic counter,
``dr.scatter_inc``), so packets stay full until the queue runs dry. It is one kernel a
query, like the plain march, and takes the same steps (the same :meth:`step` from the
same start), so every ray's answer is the plain march's.

It needs the rays in memory: a query from inside a symbolic loop (Mitsuba's megakernel)
cannot use it; the integrator's wavefront mode (``wavefront``: its path loop evaluated
depth by depth, :mod:`.integrator`) can.

Measured on one view's rays (640x360, the rays of ``benchmarks/ray_steps.py``, each
query alone, 2 cores): goblins camera 0.426 -> 0.41 s, shadow 0.25 -> 0.19 s, bounce
0.66 -> 0.45 s; coastal cliff camera 0.093 -> 0.096 s, shadow 0.090 -> 0.066 s, bounce
0.12 -> 0.08 s.

Lanes. Dr.Jit's LLVM backend runs a kernel's packets one after another on each
thread, each to the end of its loop, and each lane starts with the ray of its own
index. So the first packet of each thread drains the queue, and every other packet
then marches only the 16 rays it started with, as the plain march does, its slowest
ray setting its time. With 16,384 lanes that was 31 % of the goblins' 52,800 shadow
rays of a 480x270 view; with 1,024 lanes (512 a thread, 2 threads) it is 2 % (the
queue alone: 139 -> 105 ms; 122,061 bounce rays: 284 -> 252 ms; camera rays, coherent
already, 239 -> 240 ms; 160x90, 8 spp renders, every camera: goblins -17 %,
every_generator and the arch bridge -10 %). 256 and 512 lanes ran as 1,024; 16 lanes (one packet) left one of the
two threads idle, so the lanes grow with the threads. A GPU runs all its lanes at
once and needs many: there the queue keeps ``CUDA_QUEUE_LANES``.

References
----------
Aila, T., Laine, S. (2009). Understanding the efficiency of ray traversal on GPUs.
HPG 2009 (persistent threads fetching work from a global pool).
Laine, S., Karras, T., Aila, T. (2013). Megakernels considered harmful: wavefront path
tracing on GPUs. HPG 2013.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .march import SECOND_PASS_FACTOR, March, ShadowProbe, TraceResult

__all__ = ["CUDA_QUEUE_LANES", "QUEUE_LANES_PER_THREAD", "queue_lanes", "queued_march"]

#: Lanes of a queued march on the CPU, per thread of Dr.Jit's pool (at most): few, so
#: that nearly every ray is taken from the queue by a packet that stays full, and 32
#: packets a thread, so that every thread has some (module docstring, "Lanes").
QUEUE_LANES_PER_THREAD = 512
#: On a GPU, whose lanes all run at once: enough to fill it.
CUDA_QUEUE_LANES = 1 << 18


def queue_lanes(backend):
    """Lanes of a queued march on ``backend`` (a ``dr.JitBackend``), at most."""
    if backend == dr.JitBackend.CUDA:
        return CUDA_QUEUE_LANES
    return QUEUE_LANES_PER_THREAD * max(1, dr.thread_count())


def _gather3(cls, source, index, active):
    return cls(*(dr.gather(mi.Float, source[i], index, active) for i in range(3)))


@dr.syntax
def queued_march(tracer, o, d, t_start, t_end, active, cone=None, any_hit=False, lanes=None):
    """The march of ``tracer`` (a :class:`~.sphere_tracer.SphereTracer`) over
    ``[t_start, t_end]`` of the rays ``o + t d`` on the lanes ``active``, by persistent
    lanes (module docstring): the :class:`~.march.TraceResult` its own loop gives.

    Parameters
    ----------
    tracer : SphereTracer
        Its ``step``, ``max_steps`` and ``omega``.
    o, d : mi.Point3f, mi.Vector3f
        Ray origins and unit directions.
    t_start, t_end : mi.Float
        Each ray's interval.
    active : mi.Bool
        The rays to march.
    cone : (mi.Float, mi.Float), optional
        Each ray's cone.
    any_hit : bool
        Shadow rays (probes, :mod:`.march`).
    lanes : int, optional
        Lanes at most (default: :func:`queue_lanes`).

    Returns
    -------
    TraceResult
    """
    width = dr.width(t_start)
    o, d, t_start, t_end = mi.Point3f(o), mi.Vector3f(d), mi.Float(t_start), mi.Float(t_end)
    active = mi.Bool(active) & dr.full(mi.Bool, True, width)
    cone = tuple(mi.Float(c) + dr.zeros(mi.Float, width) for c in cone) if cone else ()
    dr.eval(o, d, t_start, t_end, active, cone)
    rays = dr.compress(active)
    count = dr.width(rays)
    hit_out, unresolved_out = dr.zeros(mi.Bool, width), dr.zeros(mi.Bool, width)
    t_out, steps_out = mi.Float(t_start), dr.zeros(mi.UInt32, width)
    if count > 0:
        if lanes is None:
            lanes = queue_lanes(dr.backend_v(t_start))
        n = min(count, lanes)
        # Counts as opaque values: literals would make a kernel for every count.
        queue = dr.opaque(mi.UInt32, n, 1)  # the next ray's place in ``rays``
        total = dr.opaque(mi.UInt32, count)
        budget = tracer.max_steps * (1 + SECOND_PASS_FACTOR)
        place = dr.arange(mi.UInt32, n)
        ray = dr.gather(mi.UInt32, rays, place)
        p, u = _gather3(mi.Point3f, o, ray, True), _gather3(mi.Vector3f, d, ray, True)
        end = dr.gather(mi.Float, t_end, ray)
        lane_cone = tuple(dr.gather(mi.Float, c, ray) for c in cone)
        march = March.start(dr.gather(mi.Float, t_start, ray), tracer.omega)
        shadow = ShadowProbe.start(n) if any_hit else None
        hit, invalid, steps = dr.zeros(mi.Bool, n), dr.zeros(mi.Bool, n), dr.zeros(mi.UInt32, n)
        going = dr.full(mi.Bool, True, n)
        # The rays and the outputs are read and scattered to, never loop state: as state
        # (of another width than the lanes), Dr.Jit recorded the body twice
        # (integrator.sample_megakernel).
        while dr.hint(going, label="queued_march", exclude=[tracer, total, queue, rays, o, d, t_start, t_end, cone,
                                                             hit_out, unresolved_out, t_out, steps_out]):
            if dr.hint(any_hit, mode="scalar"):
                march, out, _, shadow = tracer.step(p, u, march, end, lane_cone or None, shadow)
            else:
                march, out, _ = tracer.step(p, u, march, end, lane_cone or None)
            hit |= out.hit
            invalid |= out.invalid
            steps += 1
            alive = ~(hit | out.done | invalid)
            ends = ~alive | (steps >= budget)
            # As march_result: a ray still alive at its budget's end or stopped by a NaN
            # is unresolved, reported at its verified frontier.
            unresolved = alive | invalid
            dr.scatter(hit_out, hit, ray, ends)
            dr.scatter(unresolved_out, unresolved, ray, ends)
            dr.scatter(t_out, dr.select(unresolved, dr.minimum(march.t, march.frontier), march.t), ray, ends)
            dr.scatter(steps_out, steps, ray, ends)
            # The lanes whose ray ended take the next one.
            place = dr.select(ends, dr.scatter_inc(queue, mi.UInt32(0), ends), place)
            going = place < total
            fresh = ends & going
            ray = dr.select(fresh, dr.gather(mi.UInt32, rays, place, fresh), ray)
            p = dr.select(fresh, _gather3(mi.Point3f, o, ray, fresh), p)
            u = dr.select(fresh, _gather3(mi.Vector3f, d, ray, fresh), u)
            end = dr.select(fresh, dr.gather(mi.Float, t_end, ray, fresh), end)
            lane_cone = tuple(dr.select(fresh, dr.gather(mi.Float, cone[i], ray, fresh), lane_cone[i])
                              for i in range(len(cone)))
            march = dr.select(fresh, March.start(dr.gather(mi.Float, t_start, ray, fresh), tracer.omega), march)
            if dr.hint(any_hit, mode="scalar"):
                shadow = dr.select(fresh, ShadowProbe.start(n), shadow)
            hit &= ~fresh
            invalid &= ~fresh
            steps = dr.select(fresh, 0, steps)
    return TraceResult.of(hit_out, t_out, steps_out, unresolved_out, active, tracer.max_steps)
