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


#: Real DEMs of the landscape benchmark: file, cell size (m), extra amplify options.
REAL_DEMS = {"real_nm_canyon_10m": ("real_nm_canyon_10m.npy", 10.0, []),
             "real_jacksboro_80m": ("real_jacksboro_80m.npy", 80.0, []),
             "real_salish_sea_2435m": ("real_salish_sea_2435m.npy", 2435.0, ["--max-cells", "3000"])}


def _landscape_scenes(tmp):
    """``{name: scene path}``: the gallery and the real DEMs amplified into ``tmp``."""
    from arches_render.cli import main
    from arches_render.timing import REPO
    scenes = {p.stem: p for p in sorted((REPO / "scenes" / "gallery").glob("*.toml"))}
    for name, (file, cell, extra) in REAL_DEMS.items():
        out = Path(tmp) / f"{name}.toml"
        with contextlib.redirect_stdout(sys.stderr):  # stdout holds the figures only
            code = main(["amplify", str(REPO / "scenes" / "data" / file), "-o", str(out), "--cell-size",
                         str(cell), "--seed", "5", "-q", *extra])
        if code != 0:
            raise RuntimeError(f"amplify {file} exited {code}")
        scenes[name] = out
    wanted = os.environ.get("ARCHES_BENCH_LANDSCAPE_SCENES")
    if wanted:
        scenes = {k: v for k, v in scenes.items() if k in wanted.split(",")}
    return scenes


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
    ratios, rates, counts = {}, [], {"exhausted": 0, "unresolved": 0}
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in _landscape_scenes(tmp).items():
            desc = load_scene(path)
            field, mesh = build_scene(desc, "field", w, h), build_scene(desc, "mesh", w, h)
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
                load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


BENCHMARKS = {
    "lod_octaves_cost": (bench_lod_octaves_cost, 5),
    "render_landscape_field_vs_mesh": (bench_render_landscape_field_vs_mesh, 2),
}
