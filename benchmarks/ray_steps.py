"""Field tracer steps per ray, by kind of ray, as the integrator casts them.

:func:`ray_steps` traces one camera ray a pixel through a scene's field (pixel cone;
starting where its bundle's cone ends, :mod:`arches_render.render.ray_bundles`: the
cone's own steps, a sixteenth of the rays', are not counted),
then from each hit one shadow ray towards the scene's first sun, in a direction drawn
on its disk (the integrator skips
those below the surface: so does this; reported also split into those that reach the
sky and those that rock blocks) and one cosine-sampled bounce ray whose cone
widens by the integrator's ``lod_bounce_spread``; each query reports its steps (field
evaluations) and cells (cheap cell visits of a structure or a heightfield cast).
Only the field is traced (no meshes), with the tracer the renderer would build.

Used by ``trace_steps_by_ray_type`` (``bench_tracing.py``) and by hand::

    python benchmarks/ray_steps.py [--sun-columns] scenes/gallery/fig23_goblins.toml
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

#: The integrator's default ``lod_bounce_spread`` (radians).
BOUNCE_SPREAD = 0.1


def _sun(desc):
    """Unit direction towards the scene's first sun (or a 35 degree default) and its
    angular radius (radians)."""
    from arches_render.render.sun_columns import scene_sun
    sun = scene_sun(desc.lights)
    v, radius = sun if sun is not None else (np.array([0.5, -0.6, 0.7]), 0.0)
    return v / np.linalg.norm(v), radius


def _vector(v, like):
    return mi.Vector3f(*(mi.Float(float(c)) + 0.0 * like for c in v))


def _per_lane(values, n):
    """A query's per-lane counts as a numpy array of ``n`` (a literal 0 has width 1)."""
    if values is None:
        return np.zeros(n)
    return np.broadcast_to(values.numpy(), (n,))


#: Lanes of a SIMD packet of Dr.Jit's LLVM backend with AVX-512 (float32).
PACKET = 16


def _stats(res, lanes):
    every = _per_lane(res.steps, len(lanes))
    steps = every[lanes]
    cells = _per_lane(getattr(res, "cells", None), len(lanes))[lanes]
    if not len(steps):
        return dict(n=0, mean=0.0, p99=0.0, cells_mean=0.0, packet=0.0)
    # A packet loops until its slowest lane is done: what a render pays per ray is about
    # the mean over packets of their largest count (lanes in pixel order, as at 1 spp).
    n = len(every) // PACKET * PACKET
    groups = np.where(lanes[:n], every[:n], 0).reshape(-1, PACKET)
    busy = lanes[:n].reshape(-1, PACKET).any(axis=1)
    return dict(n=int(len(steps)), mean=float(steps.mean()), p99=float(np.percentile(steps, 99)),
                cells_mean=float(np.mean(cells)), packet=float(groups.max(axis=1)[busy].mean()))


def aim_at_sun(desc, tracer):
    """Give ``tracer`` the scene's sun map, as the renderer does (:mod:`arches_render.render.sun_columns`)."""
    from arches_render.render.sun_columns import scene_sun
    sun = scene_sun(desc.lights)
    if sun is not None and hasattr(tracer, "aim_at_sun"):
        tracer.aim_at_sun(*sun)


def ray_steps(desc, tracer, width=320, height=180, seed=1):
    """Steps per ray of the camera, shadow and bounce rays of one view (those of
    :func:`traced_rays`).

    Parameters
    ----------
    desc : SceneDescription
        The scene (its camera and lights).
    tracer : SphereTracer, HeightfieldCaster or any tracer with ``query`` and ``surface``
        The field's tracer, as the integrator builds it.
    width, height : int
        One camera ray a pixel.
    seed : int
        Of the bounce directions.

    Returns
    -------
    dict
        ``{kind: {n, mean, p99, cells_mean, packet}}`` for ``camera``, ``shadow``, ``bounce``
        and the shadow rays split into ``shadow_free`` and ``shadow_blocked``;
        ``packet``: the mean over packets of 16 consecutive lanes of their largest count.
    """
    rays = traced_rays(desc, tracer, width, height, seed)
    out = {"camera": _stats(rays["camera"].result, rays["camera"].lanes)}
    shadow = rays["shadow"]
    blocked = np.broadcast_to(shadow.result.hit.numpy(), shadow.lanes.shape)
    out["shadow"] = _stats(shadow.result, shadow.lanes)
    # Rays that reach the sky and rays stopped by rock cost differently (goblins: 49 and
    # 61 steps): a structure that ends free rays early does nothing for blocked ones.
    out["shadow_free"] = _stats(shadow.result, shadow.lanes & ~blocked)
    out["shadow_blocked"] = _stats(shadow.result, shadow.lanes & blocked)
    out["bounce"] = _stats(rays["bounce"].result, rays["bounce"].lanes)
    return out


@dataclass
class TracedRays:
    """One kind of ray of :func:`traced_rays`: origins, unit directions and cones
    ``(r0, spread)`` per lane, the query's result, and the lanes cast (numpy bools)."""

    origin: object
    direction: object
    cone: tuple
    result: object
    lanes: np.ndarray


def traced_rays(desc, tracer, width=320, height=180, seed=1):
    """The camera, shadow and bounce rays of one view, traced as :func:`ray_steps`
    describes: ``{kind: TracedRays}``."""
    from bench_tracing import camera_rays
    cam = desc.camera
    o, d, rate = camera_rays(cam.origin, cam.target, cam.fov, width, height)
    o = o + 0.0 * d
    cone = (mi.Float(0.0) + 0.0 * d.x, mi.Float(rate) + 0.0 * d.x)
    # Camera rays start where their bundles' cones end, as the integrator starts them
    # (arches_render.render.ray_bundles; here bundles of pixels in a row, as at 1 spp).
    bundled = hasattr(tracer, "bundle_starts")
    t_min = tracer.bundle_starts(o, d, mi.Float(dr.inf), mi.Bool(True), cone) if bundled else None
    first = tracer.query(o, d, mi.Float(dr.inf), mi.Bool(True), cone, t_min=t_min)
    dr.eval(first.hit, first.t, first.steps)
    hit = first.hit.numpy()
    out = {"camera": TracedRays(o, d, cone, first, np.ones_like(hit))}
    p, n = tracer.surface(o + d * first.t, first.t, d, cone)
    # The integrator's lift off the surface.
    from arches_render.render import integrator  # noqa: F401  (same variant, plugins)
    lift = dr.maximum(0.1 * tracer.eps * first.t, 32 * 1.1920929e-7 * dr.max(dr.abs(p)) + 1e-6)
    origin = p + n * lift
    hit_cone = (cone[0] + cone[1] * first.t, cone[1])
    rng = np.random.default_rng(seed)
    axis, radius = _sun(desc)
    from arches_render.render.sun_columns import disk_directions
    rays = disk_directions(axis, radius, dr.width(origin), rng).astype(np.float32)
    sun = mi.Vector3f(*(mi.Float(rays[:, k]) for k in range(3)))
    lit = first.hit & (dr.dot(n, sun) > 0.0) & (dr.dot(n, -d) > 0.0)
    shadow = tracer.query(origin, sun, mi.Float(dr.inf), lit, hit_cone, any_hit=True)
    dr.eval(shadow.steps, shadow.hit)
    out["shadow"] = TracedRays(origin, sun, hit_cone, shadow, lit.numpy())
    u1, u2 = rng.random(len(hit)).astype(np.float32), rng.random(len(hit)).astype(np.float32)
    local = mi.Vector3f(mi.Float(np.sqrt(u1) * np.cos(2 * np.pi * u2)),
                        mi.Float(np.sqrt(u1) * np.sin(2 * np.pi * u2)), mi.Float(np.sqrt(1 - u1)))
    bounce_dir = mi.Frame3f(n).to_world(local)
    bounce_cone = (hit_cone[0], hit_cone[1] + BOUNCE_SPREAD)
    bounce = tracer.query(origin, bounce_dir, mi.Float(dr.inf), first.hit, bounce_cone)
    dr.eval(bounce.steps)
    out["bounce"] = TracedRays(origin, bounce_dir, bounce_cone, bounce, hit)
    return out


def main(argv):
    """``ray_steps.py [--sun-columns] SCENE...``: the renderer's tracer, or with the
    option, with the sun map whatever the scene says."""
    sun_columns = "--sun-columns" in argv
    argv = [a for a in argv if a != "--sun-columns"]
    from arches_render import backend
    backend.set_variant()
    from arches_render.render.heightfield_caster import make_tracer
    from arches_render.scene import load_scene
    for path in argv:
        desc = load_scene(path)
        r = desc.render
        tracer = make_tracer(desc.field, eps=r.eps, omega=r.omega, max_steps=r.max_steps)
        if r.sun_columns or sun_columns:
            aim_at_sun(desc, tracer)
        stats = ray_steps(desc, tracer)
        print(path, type(tracer).__name__)
        for kind, s in stats.items():
            print(f"  {kind:14s} n={s['n']:6d} mean={s['mean']:7.1f} p99={s['p99']:7.0f} cells={s['cells_mean']:6.1f} packet={s['packet']:6.1f}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    sys.exit(main(sys.argv[1:]))
