"""Camera rays marched in bundles (issue 32; arches_render/render/ray_bundles.py): the air
a bundle's cone skips is free for every ray of the bundle (the field sampled densely
over it), the rays then find the hits they find without it (within the hit tolerance,
but for grazes), with fewer steps; bundles of incoherent rays or of different cones
skip nothing; and the renderer's camera queries start where their bundles end."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import SCENES, variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.field.lod import Footprint  # noqa: E402
from arches_render.render.march import ray_box  # noqa: E402
from arches_render.render.ray_bundles import BUNDLE_LANES  # noqa: E402
from arches_render.render.sphere_tracer import SphereTracer  # noqa: E402
from arches_render.scene import load_scene  # noqa: E402

#: Gallery scenes whose fields the bundles are checked on: hoodoos on amplified terrain,
#: and karst tunnels under a plateau seen from kilometres away (rays enter the field's
#: box at distances that differ along a bundle).
SCENES_CHECKED = ("fig23_goblins", "fig17_karst")


def _camera_rays(cam, width, height, spp, seed=1):
    """Pinhole rays as Mitsuba hands a pass's samples: ``spp`` jittered samples of a
    pixel after one another, pixels in rows. ``(o, d, rate)``: numpy origin, unit
    directions and the cone's spread (half a pixel's angle)."""
    o = np.asarray(cam.origin, float)
    fwd = np.asarray(cam.target, float) - o
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    tanx = np.tan(np.radians(cam.fov) / 2)
    rng = np.random.default_rng(seed)
    py, px = np.divmod(np.repeat(np.arange(width * height), spp), width)
    x = (px + rng.random(len(px))) / width * 2 - 1
    y = (py + rng.random(len(px))) / height * 2 - 1
    d = fwd + x[:, None] * tanx * right - y[:, None] * tanx * height / width * up
    return o, d / np.linalg.norm(d, axis=1, keepdims=True), tanx / width


def _vec(a, tp):
    return tp(*(mi.Float(np.ascontiguousarray(a[:, k], dtype=np.float32)) for k in range(3)))


def _view(name, width=96, height=54, spp=4):
    desc = load_scene(SCENES / "gallery" / f"{name}.toml")
    r = desc.render
    tracer = SphereTracer(desc.field, eps=r.eps, omega=r.omega, max_steps=r.max_steps)
    o, d, rate = _camera_rays(desc.camera, width, height, spp)
    n = len(d)
    O, D = _vec(np.broadcast_to(o, (n, 3)), mi.Point3f), _vec(d, mi.Vector3f)
    cone = (mi.Float(np.zeros(n, np.float32)), mi.Float(np.full(n, rate, np.float32)))
    return tracer, o, d, O, D, cone


def _free_over(tracer, o, d, cone_rate, t0, t1, samples=600):
    """The largest footprint-field value on the segments ``[t0, t1]`` of the rays ``o + t d``
    (one origin, a direction a row; ``samples`` points each), as the tracer evaluates them."""
    worst = -np.inf
    u = np.linspace(0.0, 1.0, samples)
    for part in np.array_split(np.arange(len(d)), max(1, len(d) // 400)):
        T = t0[part, None] + (t1[part] - t0[part])[:, None] * u[None, :]
        P = (o[None, None, :] + d[part, None, :] * T[..., None]).reshape(-1, 3)
        t = mi.Float(T.ravel().astype(np.float32))
        f, _ = tracer.field.eval_bounds(_vec(P, mi.Point3f), (), None,
                                        Footprint.on_ray(mi.Float(0.0), mi.Float(cone_rate), t))
        worst = max(worst, float(f.numpy().max()))
    return worst


@pytest.mark.parametrize("name", SCENES_CHECKED)
def test_the_air_a_bundle_skips_is_free_for_each_of_its_rays(name):
    """Every ray's skipped segment, from its own entry into the field's box to where its
    bundle's cone stopped, holds no point of the solid (600 samples a segment, every ray
    whose start moved); the cones skip a fair share of the way to the hits."""
    tracer, o, d, O, D, cone = _view(name)
    start = tracer.bundle_starts(O, D, mi.Float(dr.inf), mi.Bool(True), cone).numpy()
    t_in, t_out = ray_box(O, D, tracer.lo_op, tracer.hi_op)
    own = np.maximum(t_in.numpy(), 0.0)
    inside = own <= t_out.numpy()
    assert np.all(start[inside] >= own[inside])
    moved = inside & (start > own)
    assert moved.mean() > 0.5
    t1 = np.minimum(start, t_out.numpy())
    assert _free_over(tracer, o, d[moved], float(cone[1].numpy()[0]), own[moved], t1[moved]) < 0.0
    hit = tracer.query(O, D, mi.Float(dr.inf), mi.Bool(True), cone)
    t_hit, is_hit = hit.t.numpy(), hit.hit.numpy()
    # Skipped: at least a third of the way to the hit, on average.
    assert np.mean((start - own)[is_hit & inside] / (t_hit - own)[is_hit & inside]) > 0.33


def _least_over(tracer, o, d, cone_rate, t0, t1, samples=2000):
    """The smallest footprint-field value on each segment ``[t0, t1]`` (as :func:`_free_over`)."""
    u = np.linspace(0.0, 1.0, samples)
    T = t0[:, None] + (t1 - t0)[:, None] * u[None, :]
    P = (o[None, None, :] + d[:, None, :] * T[..., None]).reshape(-1, 3)
    f, _ = tracer.field.eval_bounds(_vec(P, mi.Point3f), (), None,
                                    Footprint.on_ray(mi.Float(0.0), mi.Float(cone_rate),
                                                     mi.Float(T.ravel().astype(np.float32))))
    return f.numpy().reshape(len(t0), samples).min(axis=1)


#: Steps a ray (by packet) with bundles at most, against without: goblins 44.2 -> 35.5,
#: karst (whose rays cross less air) 11.9 -> 10.5, at this view's size.
FEWER_STEPS = {"fig23_goblins": 0.85, "fig17_karst": 0.95}


@pytest.mark.parametrize("name", SCENES_CHECKED)
def test_rays_started_by_their_bundles_find_their_hits_in_fewer_steps(name):
    """With ``t_min`` from the bundles: the same hits on all rays but grazes (at most
    0.1 % of rays hit on one side only, or at two points with air between them: the
    field below four times the hit tolerance; a ray grazing a plateau meets its
    tolerance band over metres, and two hits anywhere in it are the same), and fewer
    steps a ray, counted by SIMD packet (what a render pays; ``FEWER_STEPS``)."""
    tracer, o, d, O, D, cone = _view(name)
    plain = tracer.query(O, D, mi.Float(dr.inf), mi.Bool(True), cone)
    start = tracer.bundle_starts(O, D, mi.Float(dr.inf), mi.Bool(True), cone)
    bundled = tracer.query(O, D, mi.Float(dr.inf), mi.Bool(True), cone, t_min=start)
    a, b = plain.hit.numpy(), bundled.hit.numpy()
    ta, tb = plain.t.numpy(), bundled.t.numpy()
    tol = tracer.tolerance(plain.t, cone).numpy()
    apart = np.where(a & b & (np.abs(ta - tb) > 4.0 * tol))[0]
    gap = _least_over(tracer, o, d[apart], float(cone[1].numpy()[0]), np.minimum(ta, tb)[apart],
                      np.maximum(ta, tb)[apart]) < -4.0 * tol[apart]
    differ = (a != b).sum() + gap.sum()
    assert differ <= 1e-3 * len(a), (differ, len(apart))
    assert not bundled.unresolved.numpy().any()
    steps_a = plain.steps.numpy().reshape(-1, 16).max(axis=1).mean()
    steps_b = bundled.steps.numpy().reshape(-1, 16).max(axis=1).mean()
    assert steps_b < FEWER_STEPS[name] * steps_a, (steps_a, steps_b)


def test_bundles_of_incoherent_rays_or_of_different_cones_skip_no_more_than_is_free():
    """Rays in random directions from one point lie in no thin cone: their bundles prove
    the ball around the point free, and beyond it only what is free (sampled); from
    random origins nothing. A bundle whose lanes trace different footprint fields is
    not marched; one of equal cones is."""
    tracer, o, d, O, D, cone = _view("fig23_goblins", 32, 18, 4)
    rng = np.random.default_rng(3)
    scattered = rng.normal(size=d.shape)
    scattered /= np.linalg.norm(scattered, axis=1, keepdims=True)
    Ds = _vec(scattered, mi.Vector3f)
    start = tracer.bundle_starts(O, Ds, mi.Float(dr.inf), mi.Bool(True), cone).numpy()
    f0, (ball,) = tracer.field.eval_bounds(mi.Point3f(*map(float, o)), (0.0,))
    assert np.all(start >= 0.99 * ball.numpy()[0])
    assert _free_over(tracer, o, scattered, float(cone[1].numpy()[0]), np.zeros(len(start)), start) < 0.0
    lo, hi = np.asarray(tracer.lo), np.asarray(tracer.hi)
    origins = _vec(rng.uniform(lo, hi, size=d.shape), mi.Point3f)
    t_in, _ = ray_box(origins, Ds, tracer.lo_op, tracer.hi_op)
    start = tracer.bundle_starts(origins, Ds, mi.Float(dr.inf), mi.Bool(True), cone).numpy()
    assert np.array_equal(start, np.maximum(t_in.numpy(), 0.0))
    rates = cone[1].numpy().copy()
    rates[::BUNDLE_LANES] *= 1.5  # one lane of each bundle traces a coarser field
    t_in, _ = ray_box(O, D, tracer.lo_op, tracer.hi_op)
    mixed = (cone[0], mi.Float(rates))
    start = tracer.bundle_starts(O, D, mi.Float(dr.inf), mi.Bool(True), mixed).numpy()
    assert np.array_equal(start, np.maximum(t_in.numpy(), 0.0))
    assert np.mean(tracer.bundle_starts(O, D, mi.Float(dr.inf), mi.Bool(True), cone).numpy() >
                   np.maximum(t_in.numpy(), 0.0)) > 0.5


@pytest.mark.parametrize("wavefront", [False, True], ids=["megakernel", "wavefront"])
def test_a_render_starts_its_camera_rays_where_their_bundles_end(wavefront, monkeypatch):
    """The integrator passes the bundles' starts to the camera rays' field queries only
    (megakernel and wavefront): the primary rays' steps (AOV ``steps``) fall, the
    picture does not change beyond the rays' noise."""
    import dataclasses

    from arches_render.render.integrator import integrator_class
    from arches_render.render.renderer import build_scene, render_layers
    desc = load_scene(SCENES / "gallery" / "fig23_goblins.toml")
    desc = dataclasses.replace(desc, render=dataclasses.replace(desc.render, wavefront=wavefront))
    asked = []
    query = SphereTracer.query

    def spy(self, *args, **kwargs):
        asked.append(kwargs.get("t_min") is not None)
        return query(self, *args, **kwargs)
    monkeypatch.setattr(SphereTracer, "query", spy)

    def render():
        scene = build_scene(desc, "field", 64, 36, aovs=True)
        return render_layers(scene, 4, seed=5)
    bundled = render()
    # Hit queries ask with t_min (the megakernel's one, 0 past the camera; the wavefront's
    # camera query), shadow queries never.
    assert asked.count(True) >= 1 and asked.count(False) >= 1
    monkeypatch.setattr(integrator_class(), "camera_starts", lambda self, path: None)
    asked.clear()
    plain = render()
    assert not any(asked)
    steps_b, steps_p = (layers["steps"][0].mean() for _, layers in (bundled, plain))
    assert steps_b < 0.85 * steps_p, (steps_b, steps_p)
    beauty_b, beauty_p = bundled[0], plain[0]
    assert abs(beauty_b.mean() - beauty_p.mean()) < 0.01 * beauty_p.mean()
