"""Direct tracing (issue 16): footprint level of detail and the tracer's costs.

``lod_octaves_cost``  time to trace the camera rays of a fixed view (320x180 pinhole,
                      one ray a pixel) through a displaced sphere whose fBm has 3, 6
                      and 12 octaves of the same base wavelength (the finer ones far
                      below the pixel), with footprint level of detail: value
                      ``t(12) / t(3)``. Sub-linear in octaves means below 4 (the
                      octave ratio); baseline: the same ratio without level of
                      detail (full detail pays for every octave). Extra fields: the
                      times, and the load average.

``render_landscape_field_vs_mesh``  (issue 21) every gallery scene and each in-repo
                      real DEM (``real_nm_canyon_10m``, ``real_jacksboro_80m``,
                      ``real_salish_sea_2435m``) amplified with the default preset,
                      rendered from every named camera: field time (``implicit_path``)
                      against stock ``path`` on the scene's marching-cubes mesh, same
                      resolution and spp, warm kernels, polygonization not counted.
                      Value: the median of the per-scene ratios (each scene's ratio
                      is its summed field time over its summed mesh time); baseline:
                      the goal, 1.5 (worst: 2.5). Extra fields: per-scene ratios,
                      the worst, the field path's samples per second, the counts of
                      exhausted and unresolved primary rays, the load. Size by
                      ``ARCHES_BENCH_LANDSCAPE="WxH,SPP"`` (default ``160x90,8``) and
                      ``ARCHES_BENCH_LANDSCAPE_SCENES`` (comma-separated names: a subset).
                      The Salish Sea DEM is amplified with ``--max-cells 3000`` (at
                      full size its sea erosion alone takes minutes).

                      Extra fields per scene: ``cells_build_s`` and ``cells_mb``, the
                      surface cells' build time and memory (issue 32: built once a
                      scene), ``sun_build_s`` and ``sun_mb``, the sun map's (opt-in:
                      ``[render] sun_columns``), against ``mesh_mb``, the marching-cubes mesh's.

``trace_steps_by_ray_type``  (issue 32) steps (field evaluations) per ray of camera,
                      shadow and bounce rays (``benchmarks/ray_steps.py``: 320x180, one
                      camera ray a pixel, a shadow ray to the sun's disk and a cosine
                      bounce from each hit) on ``fig23_goblins``, ``every_generator`` and
                      the amplified NM canyon, with the renderer's tracer, the sphere
                      tracer alone, the cell tracer (surface cells), the cover tracer
                      (``cover``: casts against the cells' cover) and the sphere tracer
                      with its sun map (``sun_columns``) in the same run. Value: the largest mean
                      of shadow steps with the renderer's tracer; baseline: the goal,
                      20. Extra fields: mean, 99th percentile and mean packet maximum
                      (over 16 consecutive lanes: a SIMD packet loops until its slowest
                      lane is done, so this, not the mean, is what a render pays) per
                      scene, tracer and ray type; shadow rays also split into
                      ``shadow_free`` (reaching the sky) and ``shadow_blocked``.
``render_field_vs_sdfgrid``  (issue 32) the default scene traced by ``implicit_path``
                      against the same field sampled at the mesh voxel and rendered as
                      Mitsuba's own ``sdfgrid`` shape (320x180, 16 spp, warm): field
                      seconds over sdfgrid seconds; baseline: the goal, 1.
``render_cover_vs_sphere``  (issue 32) the alternative the issue asked to measure: the
                      cells where the surface may be as a cover traced by Mitsuba's ray
                      tracer (``arches_render.render.cover_tracer``), against the sphere
                      tracer, rendering ``fig23_goblins``, ``fig23_arch_bridge`` and
                      ``every_generator`` from every camera (160x90, 8 spp, warm, the
                      renderer's settings otherwise). Value: the median of the per-scene
                      time ratios (cover over sphere); baseline: 1 (below pays). Extra
                      fields: per-scene ratios, the cover's build seconds and triangles.
``render_wavefront_vs_megakernel``  (issue 32) the integrator's wavefront
                      (``[render] wavefront``: paths depth by depth, queries by
                      persistent lanes, ``arches_render.render.wavefront``) against its
                      megakernel, field renders of ``fig23_goblins``,
                      ``fig23_arch_bridge``, ``fig23_coastal_cliff``, ``fig17_karst`` and
                      ``fig21_floating_islands`` from every camera (160x90, 8 spp, warm,
                      whatever the scene asks). Value: the median of the per-scene time
                      ratios (wavefront over megakernel); baseline: 1 (below pays).
                      Extra fields: per-scene ratios (the choice a scene makes, and
                      whether it would pay on a GPU: ``benchmarks/device_check.sh``).
``render_landscape_end_to_end``  (issue 32) per landscape (the gallery and the real
                      DEMs), the field path (scene build: the tracer's structures
                      included, plus the render) over the mesh path (polygonization at
                      the scene's mesh voxel plus the render), at
                      ``ARCHES_BENCH_E2E="WxH,SPP"`` (default ``1280x720,16``) and the
                      scenes of ``ARCHES_BENCH_LANDSCAPE_SCENES``; cold builds, warm
                      kernels (each path renders once at 16x9 first). Value: the median
                      ratio; baseline: 1.0 (the aim beyond issue 32). Extra fields:
                      per-scene ratios and seconds.

Timings taken while other processes load the machine are inflated: compare the
ratios of one run, and read ``load`` beside them.
"""

from __future__ import annotations

import contextlib
import os
import statistics
import sys
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render import field as F
from arches_render.render.sphere_tracer import SphereTracer


def camera_rays(origin, target, fov_deg, width, height):
    """Pinhole camera rays, one a pixel: ``(o, d, rate)`` with ``rate`` the cone's
    spread (half a pixel's angle at the centre)."""
    o = np.asarray(origin, float)
    fwd = np.asarray(target, float) - o
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    tanx = np.tan(np.radians(fov_deg) / 2)
    x = (np.arange(width) + 0.5) / width * 2 - 1
    y = (np.arange(height) + 0.5) / height * 2 - 1
    X, Y = np.meshgrid(x, y)
    d = fwd + X.ravel()[:, None] * tanx * right - Y.ravel()[:, None] * tanx * height / width * up
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    D = mi.Vector3f(*(mi.Float(d[:, i].astype(np.float32)) for i in range(3)))
    return mi.Point3f(*map(float, o)), D, float(tanx / width)


def _trace_seconds(tracer, o, d, cone, repeat):
    times = []
    for i in range(repeat + 1):
        t0 = time.perf_counter()
        # An opaque offset: a new computation of the same kernel each time.
        hit, t = tracer.trace(o + dr.opaque(mi.Float, 1e-7 * i), d, mi.Float(1e4), mi.Bool(True), cone)
        dr.eval(hit, t)
        dr.sync_thread()
        if i:
            times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bench_lod_octaves_cost(repeat):
    load0 = os.getloadavg()[0]
    o, d, rate = camera_rays([0.0, -14.0, 4.0], [0.0, 0.0, 0.5], 40.0, 320, 180)
    out = {}
    for lod in (True, False):
        for octaves in (3, 6, 12):
            node = F.Displace(F.Sphere([0.0, 0.0, 0.5], 3.0), amplitude=0.4, wavelength=2.0,
                              octaves=octaves, seed=3)
            cone = (mi.Float(0.0), mi.Float(rate)) if lod else None
            out[(lod, octaves)] = _trace_seconds(SphereTracer(node), o, d, cone, repeat)
    load = 0.5 * (load0 + os.getloadavg()[0])
    lod_ratio = out[(True, 12)] / out[(True, 3)]
    full_ratio = out[(False, 12)] / out[(False, 3)]
    return dict(value=lod_ratio, unit="x", baseline=full_ratio, baseline_is="the ratio at full detail",
                goal="< 4 (sub-linear)", **{f"{'lod' if k[0] else 'full'}_{k[1]}_s": v for k, v in out.items()},
                resolution="320x180", load=round(load, 2))


#: Real DEMs of the landscape benchmark: file, cell size (m), extra amplify options. The
#: Salish Sea's whole tile, as every run before coarse DEMs were refined by default
#: (``--no-refine``), so that the figure follows the tracer, not the scene.
REAL_DEMS = {"real_nm_canyon_10m": ("real_nm_canyon_10m.npy", 10.0, []),
             "real_jacksboro_80m": ("real_jacksboro_80m.npy", 80.0, []),
             "real_salish_sea_2435m": ("real_salish_sea_2435m.npy", 2435.0, ["--max-cells", "3000", "--no-refine"])}


def _landscape_scenes(tmp):
    """``{name: scene path}``: the gallery and the real DEMs amplified into ``tmp``."""
    from arches_render.cli import main
    from arches_render.timing import REPO
    wanted = os.environ.get("ARCHES_BENCH_LANDSCAPE_SCENES")
    keep = (lambda name: name in wanted.split(",")) if wanted else (lambda name: True)
    scenes = {p.stem: p for p in sorted((REPO / "scenes" / "gallery").glob("*.toml")) if keep(p.stem)}
    for name, (file, cell, extra) in REAL_DEMS.items():
        if not keep(name):  # amplifying takes minutes: only the DEMs asked for
            continue
        out = Path(tmp) / f"{name}.toml"
        with contextlib.redirect_stdout(sys.stderr):  # stdout holds the figures only
            code = main(["amplify", str(REPO / "scenes" / "data" / file), "-o", str(out), "--cell-size",
                         str(cell), "--seed", "5", "-q", *extra])
        if code != 0:
            raise RuntimeError(f"amplify {file} exited {code}")
        scenes[name] = out
    return scenes


def _structure_and_mesh_size(desc, mesh_scene):
    """``{cells_build_s, cells_mb, sun_build_s, sun_mb, mesh_mb}``: the surface cells of the
    scene's field (as the cell tracer builds them) and its sun map (as the renderer builds it)
    against its marching-cubes mesh in ``mesh_scene``."""
    from arches_render.render.cell_tracer import CellTracer
    from ray_steps import aim_at_sun
    r = desc.render
    t0 = time.perf_counter()
    tracer = CellTracer(desc.field, eps=r.eps, omega=r.omega, max_steps=r.max_steps)
    built = time.perf_counter() - t0
    sun_tracer = SphereTracer(desc.field, eps=r.eps, omega=r.omega, max_steps=r.max_steps)
    t0 = time.perf_counter()
    aim_at_sun(desc, sun_tracer)
    sun_built = time.perf_counter() - t0
    sun = getattr(sun_tracer, "sun", None)
    params = mi.traverse(mesh_scene)
    mesh_bytes = sum(4 * dr.width(params[k]) for k in params.keys()
                     if k.startswith("field_mesh.") and k.split(".")[-1] in ("vertex_positions", "vertex_normals",
                                                                              "faces"))
    return dict(cells_build_s=round(built, 2), cells_mb=round(tracer.cells.nbytes() / 1e6, 2),
                sun_build_s=round(sun_built, 2), sun_mb=round(sun.nbytes() / 1e6, 2) if sun is not None else 0.0,
                mesh_mb=round(mesh_bytes / 1e6, 2))


def bench_render_landscape_field_vs_mesh(repeat):
    import tempfile

    from arches_render.render.jobs import set_camera
    from arches_render.render.renderer import build_scene, render_layers
    from arches_render.scene import load_scene
    from arches_render.timing import median_renders
    size, spp = os.environ.get("ARCHES_BENCH_LANDSCAPE", "160x90,8").split(",")
    w, h = (int(v) for v in size.split("x"))
    spp = int(spp)
    load0 = os.getloadavg()[0]
    ratios, rates, counts, structure = {}, [], {"exhausted": 0, "unresolved": 0}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in _landscape_scenes(tmp).items():
            desc = load_scene(path)
            field, mesh = build_scene(desc, "field", w, h), build_scene(desc, "mesh", w, h)
            structure[name] = _structure_and_mesh_size(desc, mesh)
            tf = tm = 0.0
            for cam in desc.cameras.values():
                for scene in (field, mesh):
                    set_camera(scene, cam.origin, cam.target, cam.up, cam.fov)
                # Warm-up at the timed spp: a new pass size may compile new kernels.
                a, b = median_renders([field, mesh], spp, repeat, warm_spp=spp)
                tf, tm = tf + a, tm + b
                rates.append(w * h * spp / a)
            # Exhausted and unresolved primary rays, from the AOVs of one render a camera.
            counted = build_scene(desc, "field", w, h, aovs=True)
            for cam in desc.cameras.values():
                set_camera(counted, cam.origin, cam.target, cam.up, cam.fov)
                _, layers = render_layers(counted, 1, seed=3)
                for kind in counts:
                    if kind in layers:  # (older trees, run beside this one, lack them)
                        arr, letters = layers[kind]
                        counts[kind] += int(round(float(arr[..., letters.index("primary")].sum())))
            ratios[name] = round(tf / tm, 3)
    values = sorted(ratios.values())
    return dict(value=statistics.median(values), unit="x", baseline=1.5, baseline_is="goal",
                worst=max(values), worst_goal=2.5, per_scene=ratios,
                field_samples_per_s=round(statistics.median(rates)), resolution=f"{w}x{h}", spp=spp,
                primary_exhausted_1spp=counts["exhausted"], primary_unresolved_1spp=counts["unresolved"],
                structure=structure,
                load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


def bench_trace_steps_by_ray_type(repeat):
    import tempfile

    from arches_render.render.cell_tracer import CellTracer
    from arches_render.render.cover_tracer import CoverTracer
    from arches_render.render.heightfield_caster import make_tracer
    from arches_render.scene import load_scene
    from ray_steps import aim_at_sun, ray_steps
    out, worst = {}, 0.0
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["ARCHES_BENCH_LANDSCAPE_SCENES"] = "fig23_goblins,every_generator,real_nm_canyon_10m"
        try:
            scenes = _landscape_scenes(tmp)
        finally:
            del os.environ["ARCHES_BENCH_LANDSCAPE_SCENES"]
        for name, path in scenes.items():
            desc = load_scene(path)
            r = desc.render
            tracers = {"renderer": make_tracer(desc.field, eps=r.eps, omega=r.omega, max_steps=r.max_steps,
                                               cells=r.surface_cells),
                       "sphere": SphereTracer(desc.field, eps=r.eps, omega=r.omega, max_steps=r.max_steps),
                       "cells": CellTracer(desc.field, eps=r.eps, omega=r.omega, max_steps=r.max_steps),
                       "cover": CoverTracer(desc.field, eps=r.eps, omega=r.omega, max_steps=r.max_steps)}
            if r.sun_columns:
                aim_at_sun(desc, tracers["renderer"])  # as the renderer does
            tracers["sun_columns"] = SphereTracer(desc.field, eps=r.eps, omega=r.omega, max_steps=r.max_steps)
            aim_at_sun(desc, tracers["sun_columns"])
            for label, tracer in tracers.items():
                for kind, st in ray_steps(desc, tracer).items():
                    out[f"{name}.{label}.{kind}"] = [round(st["mean"], 1), round(st["p99"], 1),
                                                      round(st["packet"], 1)]
                    if label == "renderer" and kind == "shadow":
                        worst = max(worst, st["mean"])
    return dict(value=worst, unit="steps", baseline=20.0, baseline_is="goal (shadow rays, mean)",
                fields="[mean, p99, mean packet max of 16 lanes]", **out, load=round(os.getloadavg()[0], 2))


def bench_render_field_vs_sdfgrid(repeat):
    from arches_render.render.renderer import build_scene
    from arches_render.scene import load_scene
    from arches_render.timing import REPO, median_renders
    desc = load_scene(REPO / "scenes" / "default.toml")
    w, h, spp = 320, 180, 16
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    field = build_scene(desc, "field", w, h)
    t1 = time.perf_counter()
    grid = build_scene(desc, "sdfgrid", w, h)
    t2 = time.perf_counter()
    a, b = median_renders([field, grid], spp, repeat, warm_spp=spp)
    return dict(value=a / b, unit="x", baseline=1.0, baseline_is="goal", field_s=a, sdfgrid_s=b,
                field_setup_s=t1 - t0, sdfgrid_setup_s=t2 - t1, resolution=f"{w}x{h}", spp=spp,
                load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


@contextlib.contextmanager
def _cover_tracers(built):
    """Within the block, scenes built trace their sphere-traced fields with a
    :class:`~arches_render.render.cover_tracer.CoverTracer` (the renderer has no
    setting for it: it does not pay on the CPU), appending each to ``built``."""
    from arches_render.render import integrator
    from arches_render.render.cover_tracer import CoverTracer
    from arches_render.render.heightfield_caster import make_tracer
    from arches_render.render.sphere_tracer import SphereTracer

    def cover_or_cast(field, eps=2e-4, omega=1.6, max_steps=512, cast=True, cells=False):
        tracer = make_tracer(field, eps=eps, omega=omega, max_steps=max_steps, cast=cast)
        if type(tracer) is SphereTracer:
            tracer = CoverTracer(field, eps=eps, omega=omega, max_steps=max_steps)
            built.append(tracer)
        return tracer

    integrator.make_tracer = cover_or_cast
    try:
        yield
    finally:
        integrator.make_tracer = make_tracer


def bench_render_cover_vs_sphere(repeat):
    from arches_render.render.jobs import set_camera
    from arches_render.render.renderer import build_scene
    from arches_render.scene import load_scene
    from arches_render.timing import REPO, median_renders
    w, h, spp = 160, 90, 8
    load0 = os.getloadavg()[0]
    ratios, cover = {}, {}
    for name in ("fig23_goblins", "fig23_arch_bridge", "every_generator"):
        desc = load_scene(REPO / "scenes" / "gallery" / f"{name}.toml")
        sphere, built = build_scene(desc, "field", w, h), []
        with _cover_tracers(built):
            covered = build_scene(desc, "field", w, h)
        ts = tc = 0.0
        for cam in desc.cameras.values():
            for scene in (sphere, covered):
                set_camera(scene, cam.origin, cam.target, cam.up, cam.fov)
            a, b = median_renders([sphere, covered], spp, repeat, warm_spp=spp)
            ts, tc = ts + a, tc + b
        ratios[name] = round(tc / ts, 3)
        cover[name] = {k: round(float(built[0].stats[k]), 2) for k in ("cover_s", "cover_triangles", "leaf")} \
            if built else None
    return dict(value=statistics.median(ratios.values()), unit="x", baseline=1.0, baseline_is="break-even",
                per_scene=ratios, cover=cover, resolution=f"{w}x{h}", spp=spp,
                load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


def bench_render_wavefront_vs_megakernel(repeat):
    from arches_render.render.jobs import set_camera
    from arches_render.render.renderer import build_scene
    from arches_render.scene import load_scene
    from arches_render.timing import REPO, median_renders
    w, h, spp = 160, 90, 8
    load0 = os.getloadavg()[0]
    ratios = {}
    for name in ("fig23_goblins", "fig23_arch_bridge", "fig23_coastal_cliff", "fig17_karst",
                 "fig21_floating_islands"):
        desc = load_scene(REPO / "scenes" / "gallery" / f"{name}.toml")
        scenes = []
        for wavefront in (False, True):
            desc.render.wavefront = wavefront
            scenes.append(build_scene(desc, "field", w, h))
        tm = tw = 0.0
        for cam in desc.cameras.values():
            for scene in scenes:
                set_camera(scene, cam.origin, cam.target, cam.up, cam.fov)
            a, b = median_renders(scenes, spp, repeat, warm_spp=spp)
            tm, tw = tm + a, tw + b
        ratios[name] = round(tw / tm, 3)
    return dict(value=statistics.median(ratios.values()), unit="x", baseline=1.0, baseline_is="break-even",
                per_scene=ratios, resolution=f"{w}x{h}", spp=spp, load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


def bench_render_landscape_end_to_end(repeat):
    import tempfile

    from arches_render.render.renderer import build_scene, render_image
    from arches_render.scene import load_scene
    size, spp = os.environ.get("ARCHES_BENCH_E2E", "1280x720,16").split(",")
    w, h = (int(v) for v in size.split("x"))
    spp = int(spp)
    load0 = os.getloadavg()[0]
    ratios, seconds = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in _landscape_scenes(tmp).items():
            warm = load_scene(path)
            for geometry in ("field", "mesh"):  # kernels warm, builds cold
                render_image(build_scene(warm, geometry, 16, 9), 1, seed=1)
            # A scene loaded anew: its field tree is not the warm-up's, so the mesh path
            # polygonizes again (meshes are kept per field tree, renderer.field_mesh_shape).
            desc = load_scene(path)
            times = {}
            for geometry in ("field", "mesh"):
                t0 = time.perf_counter()
                scene = build_scene(desc, geometry, w, h)
                t1 = time.perf_counter()
                render_image(scene, spp, seed=1)
                times[geometry] = (t1 - t0, time.perf_counter() - t1)
                del scene
            ratios[name] = round(sum(times["field"]) / sum(times["mesh"]), 3)
            seconds[name] = {g: [round(v, 2) for v in t] for g, t in times.items()}
    return dict(value=statistics.median(ratios.values()), unit="x", baseline=1.0, baseline_is="aim",
                per_scene=ratios, seconds_build_render=seconds, resolution=f"{w}x{h}", spp=spp,
                load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


BENCHMARKS = {
    "lod_octaves_cost": (bench_lod_octaves_cost, 5),
    "render_landscape_field_vs_mesh": (bench_render_landscape_field_vs_mesh, 2),
    "trace_steps_by_ray_type": (bench_trace_steps_by_ray_type, 1),
    "render_field_vs_sdfgrid": (bench_render_field_vs_sdfgrid, 3),
    "render_cover_vs_sphere": (bench_render_cover_vs_sphere, 3),
    "render_wavefront_vs_megakernel": (bench_render_wavefront_vs_megakernel, 3),
    "render_landscape_end_to_end": (bench_render_landscape_end_to_end, 1),
}
