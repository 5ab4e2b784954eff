"""Wavefront paths and persistent-lane marches (issue 32; arches_render/render/wavefront.py,
ray_queue.py): a queued march answers every ray as the plain march does, bit for bit
(camera-like, shadow and bounce rays, budgets run out, lanes refilled many times), and
the wavefront integrator renders the megakernel's picture and AOVs bit for bit, in
passes small enough for its state."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.render.ray_queue import queued_march  # noqa: E402
from arches_render.render.march import ray_box  # noqa: E402
from arches_render.render.sphere_tracer import SphereTracer  # noqa: E402

from test_sun_columns import _surface_points  # noqa: E402
from test_surface_cells import TREES, _vec  # noqa: E402

FIELDS = ("arch", "carved")


def _rays(tracer, rng, n=3000):
    """Rays of the three kinds from the field's surface and from above: origins,
    directions, a cone per lane, and lanes that are off."""
    pts, nrm = _surface_points(tracer, n, rng)
    m = len(pts)
    d = rng.normal(size=(m, 3))
    d = np.where((d * nrm).sum(1, keepdims=True) < 0, -d, d)  # leaving the surface, as bounces
    top = pts.copy()
    top[:, 2] = tracer.hi[2] + 3.0
    down = rng.normal(size=(m, 3)) * [0.3, 0.3, 0.0] + [0.0, 0.0, -1.0]
    O = np.concatenate([pts, top])
    D = np.concatenate([d, down])
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    cone = (mi.Float(np.full(len(O), 0.01, np.float32)), mi.Float(rng.uniform(0.0, 0.1, len(O)).astype(np.float32)))
    active = mi.Bool(rng.random(len(O)) > 0.1)
    return _vec(O, mi.Point3f), _vec(D, mi.Vector3f), cone, active


def _same(a, b):
    for k in ("hit", "t", "steps", "exhausted", "unresolved"):
        x, y = getattr(a, k).numpy(), getattr(b, k).numpy()
        assert np.array_equal(x.view(np.uint32) if x.dtype == np.float32 else x,
                              y.view(np.uint32) if y.dtype == np.float32 else y), k


@pytest.mark.parametrize("any_hit", [False, True], ids=["closest", "shadow"])
@pytest.mark.parametrize("name", FIELDS)
def test_a_queued_march_answers_every_ray_as_the_plain_march(name, any_hit):
    """Same hits, distances, steps, exhausted and unresolved lanes, bit for bit: with
    as many lanes as rays, and with 37 lanes that each take ~150 rays in turn; a budget
    of 8 steps leaves rays exhausted and unresolved on both sides."""
    for max_steps in (512, 8):
        tracer = SphereTracer(TREES[name], max_steps=max_steps)
        O, D, cone, active = _rays(tracer, np.random.default_rng(7))
        t_in, t_out = ray_box(O, D, tracer.lo_op, tracer.hi_op)
        t_start = dr.maximum(t_in, 0.0)
        on = active & (t_start <= t_out)
        plain = tracer._march(O, D, t_start, t_out, on, cone, any_hit)
        dr.eval(plain)
        for lanes in (1 << 14, 37):
            queued = queued_march(tracer, O, D, t_start, t_out, on, cone, any_hit, lanes=lanes)
            dr.eval(queued)
            _same(plain, queued)
        if max_steps == 8:
            assert plain.unresolved.numpy().sum() > 10  # the budget's path is exercised
    # No ray at all: nothing marched, nothing hit.
    none = queued_march(tracer, O, D, t_start, t_out, mi.Bool(False) & on, cone, any_hit)
    assert not none.hit.numpy().any() and not none.steps.numpy().any()


def test_the_tracer_marches_by_queue_when_asked():
    """``SphereTracer.queued`` routes ``query`` through the queue, shadow rays with the
    sun map's caps and rock included: the same answers."""
    tracer = SphereTracer(TREES["arch"])
    tracer.aim_at_sun(np.array([0.45, -0.55, 0.45]))
    O, D, cone, active = _rays(tracer, np.random.default_rng(3), 1500)
    for any_hit in (False, True):
        tracer.queued = False
        a = tracer.query(O, D, mi.Float(dr.inf), active, cone, any_hit=any_hit)
        dr.eval(a)
        tracer.queued = True
        b = tracer.query(O, D, mi.Float(dr.inf), active, cone, any_hit=any_hit)
        dr.eval(b)
        _same(a, b)


@pytest.mark.parametrize("scene", ["fig23_arch_bridge", "fig23_goblins"])
def test_the_wavefront_renders_the_megakernels_picture(scene):
    """Beauty and every AOV layer (hits, depth, normals, ray counts, the fog-free beauty)
    equal bit for bit: the same stages fed the same random numbers in the same order."""
    from arches_render.render.renderer import build_scene, render_layers
    from arches_render.scene import load_scene
    from arches_render.timing import REPO
    desc = load_scene(REPO / "scenes" / "gallery" / f"{scene}.toml")
    desc.render.wavefront = False  # (both scenes ask for the wavefront)
    mega = build_scene(desc, "field", 48, 27, aovs=True)
    desc.render.wavefront = True
    wave = build_scene(desc, "field", 48, 27, aovs=True)
    assert wave.integrator().wavefront and wave.integrator().tracer.queued
    assert not mega.integrator().wavefront
    rgb_m, layers_m = render_layers(mega, 4, seed=5)
    rgb_w, layers_w = render_layers(wave, 4, seed=5)
    assert rgb_m.mean() > 0.01
    assert np.array_equal(rgb_m, rgb_w)
    assert layers_m.keys() == layers_w.keys() and len(layers_m) > 5
    for name, (arr, letters) in layers_m.items():
        assert np.array_equal(arr, layers_w[name][0]), name


def test_wavefront_passes_hold_at_most_its_lanes():
    """A wavefront render splits its samples into passes of at most ``WAVEFRONT_LANES``
    paths; the megakernel keeps its passes of about 16 spp."""
    from arches_render.render.renderer import build_scene, pass_limit, plan_passes
    from arches_render.render.wavefront import WAVEFRONT_LANES
    from arches_render.scene import load_scene
    from arches_render.timing import REPO
    assert plan_passes(32) == [16, 16]
    assert plan_passes(32, 0, 3) == [3] * 10 + [2]
    assert plan_passes(5, 0, 8) == [5]
    desc = load_scene(REPO / "scenes" / "gallery" / "fig23_arch_bridge.toml")
    desc.render.wavefront = False  # (the arch bridge's scene asks for the wavefront)
    assert pass_limit(build_scene(desc, "field", 64, 36)) == 0
    desc.render.wavefront = True
    assert pass_limit(build_scene(desc, "field", 1280, 720)) == max(1, WAVEFRONT_LANES // (1280 * 720))
    assert pass_limit(build_scene(desc, "field", 64, 36)) == WAVEFRONT_LANES // (64 * 36)


def test_a_wavefront_depth_computes_nothing_twice():
    """The wavefront's kernels, depth for depth, hold no more operations than the
    megakernel (which computes each value once): what a vertex computes before its
    shadow query and reads after it is kept, not computed again (the material's shading
    and the normal's taps were, a third more work a depth on the arch bridge)."""
    from arches_render.render import integrator as integrator_module
    from arches_render.render.renderer import build_scene, render_image
    from arches_render.scene import load_scene
    from arches_render.timing import REPO
    desc = load_scene(REPO / "scenes" / "gallery" / "fig23_arch_bridge.toml")
    ops = {}
    for wavefront in (False, True):
        desc.render.wavefront = wavefront
        scene = build_scene(desc, "field", 48, 27)
        render_image(scene, 1, seed=1)  # (kernels compiled, not counted)
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        try:
            render_image(scene, 1, seed=2)
        finally:
            history = dr.kernel_history()
            dr.set_flag(dr.JitFlag.KernelHistory, False)
        ops[wavefront] = sum(k["operation_count"] for k in history if k["type"] == dr.KernelType.JIT)
    depths = scene.integrator().max_depth
    assert depths == 3
    assert ops[True] <= depths * ops[False], (ops, depths)


def test_the_queue_gives_every_thread_packets_and_takes_most_rays_from_the_queue():
    """On the CPU a queued march has a few packets a thread (fewer leave threads idle)
    and not many more (a lane's first ray is its own, marched in a plain packet): its
    lanes grow with Dr.Jit's threads; a GPU's fill it."""
    from arches_render.render.ray_queue import CUDA_QUEUE_LANES, queue_lanes
    threads = dr.thread_count()
    try:
        for n in (1, 2, 16, 128):
            dr.set_thread_count(n)
            lanes = queue_lanes(dr.JitBackend.LLVM)
            assert 16 * 8 * n <= lanes <= 16 * 64 * n, (n, lanes)
    finally:
        dr.set_thread_count(threads)
    assert queue_lanes(dr.JitBackend.CUDA) == CUDA_QUEUE_LANES >= 1 << 17


def test_the_wavefront_marches_camera_rays_in_plain_packets():
    """The first depth's camera rays travel together and are marched in plain packets
    (a queue would mix them); every shadow and bounce query takes the queue."""
    from arches_render.render.renderer import build_scene, render_image
    from arches_render.scene import load_scene
    from arches_render.timing import REPO
    desc = load_scene(REPO / "scenes" / "gallery" / "fig23_goblins.toml")
    scene = build_scene(desc, "field", 32, 18)
    tracer = scene.integrator().tracer
    assert scene.integrator().wavefront and tracer.queued
    calls = []
    plain, queued = tracer._march, tracer._queued

    def counted(kind, march):
        def call(o, d, t_start, t_end, active, cone, any_hit=False):
            calls.append((kind, "shadow" if any_hit else "closest", dr.width(t_start)))
            return march(o, d, t_start, t_end, active, cone, any_hit)
        return call

    tracer._march, tracer._queued = counted("plain", plain), counted("queue", queued)
    render_image(scene, 2, seed=1)
    assert calls[0] == ("plain", "closest", 32 * 18 * 2)
    assert [c[0] for c in calls[1:]] == ["queue"] * (len(calls) - 1)
    assert {c[1] for c in calls[1:]} == {"shadow", "closest"}  # shadow and bounce rays
