"""The integrator's path loop as a wavefront: one kernel a stage, live paths compacted.

Why. In Mitsuba's megakernel a SIMD packet of 16 paths marches each of its field
queries until its slowest ray is done, and a shadow or bounce ray's packet took 1.7-2.2
times the steps of its mean ray (goblins, 320x180). Here the path loop runs depth by
depth in Python: its shadow and bounce queries are marched by persistent lanes that
take the next ray from a queue (:mod:`.ray_queue`; the camera rays, which march
alike, in plain packets: :meth:`~.sphere_tracer.SphereTracer.query`), and between
depths the paths still alive are gathered into compact arrays, so that no stage runs
on dead lanes. Every
depth runs the megakernel's own vertex
(:meth:`~.integrator.ImplicitPathIntegrator.path_vertex` on a
:class:`~.path_state.PathState`), fed the same random numbers in the same order
(:class:`LaneSampler`), so a pass renders the megakernel's picture bit for bit. (A
render's passes may differ: a wavefront pass holds at most ``WAVEFRONT_LANES`` paths,
:func:`~.renderer.pass_limit`, so a large frame takes more, smaller passes, with their
own seeds.)

Cost. Each query splits a depth's kernel in two and the state live across it goes
through memory (what the vertex computed before its shadow query and reads after it
is scheduled with the query's rays: :meth:`~.integrator.ImplicitPathIntegrator.path_vertex`);
on a field cheap to march (a heightfield, a few carving spheres) that costs more than
the full packets save. Field renders at 160x90, 8 spp, every camera, against the
megakernel (with the queue's 1,024 lanes, :mod:`.ray_queue`): goblins -33 %, the arch
bridge -24 %, every_generator -11 to -16 %, karst -13 to +2 %, the coastal cliff and
the sea cliffs +2 to +30 %, canyon overhangs +27 %, floating islands +44 %. So it is a
scene's choice (``[render] wavefront``), off by default; the goblins', the arch
bridge's and every_generator's gallery scenes take it. With the queue off (plain
marches over compacted paths) the kernels took what the megakernel's took: the gain
is the queue's.

References
----------
Laine, S., Karras, T., Aila, T. (2013). Megakernels considered harmful: wavefront path
tracing on GPUs. HPG 2013.
Aila, T., Laine, S. (2009). Understanding the efficiency of ray traversal on GPUs. HPG 2009.
"""

from __future__ import annotations

import dataclasses

import drjit as dr
import mitsuba as mi

__all__ = ["WAVEFRONT_LANES", "LaneSampler", "take", "wavefront_sample"]

#: Paths a wavefront pass holds at most (their state, some 80 floats a path, lives in
#: memory between stages: about 320 MB): the renderer splits its passes to stay below.
WAVEFRONT_LANES = 1 << 20


class LaneSampler:
    """The path sampler's numbers for the lanes ``lanes`` of its wavefront: each draw is
    drawn for every lane, as the megakernel's loop draws it, and the lanes' kept, so a
    path gets the numbers it would have got there."""

    def __init__(self, sampler, lanes):
        self.sampler, self.lanes = sampler, lanes

    def next_1d(self, active=True):
        return dr.gather(mi.Float, self.sampler.next_1d(), self.lanes)

    def next_2d(self, active=True):
        v = self.sampler.next_2d()
        return mi.Point2f(dr.gather(mi.Float, v.x, self.lanes), dr.gather(mi.Float, v.y, self.lanes))


def take(value, index):
    """``value`` (a Dr.Jit array, a Mitsuba struct such as ``SurfaceInteraction3f``, a
    dataclass or a tuple of them) at the lanes ``index``: one gather a leaf array."""
    if isinstance(value, tuple):
        return tuple(take(v, index) for v in value)
    if dataclasses.is_dataclass(value):
        return dataclasses.replace(value, **{f.name: take(getattr(value, f.name), index)
                                             for f in dataclasses.fields(value)})
    tp = type(value)
    fields = getattr(tp, "DRJIT_STRUCT", None)
    if fields is not None:
        out = tp()
        for name in fields:
            setattr(out, name, take(getattr(value, name), index))
        return out
    if not dr.is_array_v(tp):
        return value
    if dr.depth_v(tp) > 1:
        return tp(*(take(value[i], index) for i in range(len(value))))
    return dr.gather(tp, value, index)


def _put(target, value, index):
    """Scatter ``value`` (an array or a tuple of them, as :func:`take` reads) to ``index``."""
    if isinstance(target, tuple):
        for t, v in zip(target, value):
            _put(t, v, index)
    elif dr.depth_v(type(target)) > 1:
        for i in range(len(target)):
            _put(target[i], value[i], index)
    else:
        dr.scatter(target, value, index)


def wavefront_sample(integ, scene, sampler, ray, active=True):
    """:meth:`~.integrator.ImplicitPathIntegrator.sample` depth by depth over compacted
    live paths (module docstring): ``(L, valid, aovs)``, the megakernel's numbers.

    Parameters
    ----------
    integ : ImplicitPathIntegrator
        The integrator whose :meth:`path_vertex` runs.
    scene, sampler, ray, active
        As Mitsuba's ``sample``.

    Returns
    -------
    (mi.Spectrum, mi.Bool, list of mi.Float)
    """
    ctx = mi.BSDFContext()
    ray = mi.Ray3f(ray)
    width = dr.width(ray.o)
    active = mi.Bool(active) & dr.full(mi.Bool, True, width)
    # Every lane's outcome, written back as its path leaves the live set.
    done = integ.start_paths(sampler, ray, active, width)
    t_min = integ.camera_starts(done)
    dr.eval(done, t_min)
    lanes = dr.compress(active)
    path = take(done, lanes)
    t_min = take(t_min, lanes)
    camera = True  # the first depth's rays: camera rays, marched in plain packets
    while dr.width(lanes) > 0:
        path = integ.path_vertex(scene, LaneSampler(sampler, lanes), ctx, path, coherent=camera,
                                 t_min=t_min if camera else None)
        camera = False
        _put((done.L, done.valid, done.clear, done.aov, done.counts),
             (path.L, path.valid, path.clear, path.aov, path.counts), lanes)
        dr.eval(done, path)
        keep = dr.compress(path.active)
        lanes = dr.gather(mi.UInt32, lanes, keep)
        path = take(path, keep)
    return done.L, done.valid, integ.outputs(done.L, done.aov, done.clear, done.counts)
