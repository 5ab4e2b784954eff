"""Direct tracing (issue 16): footprint level of detail and the tracer's costs.

``lod_octaves_cost``  time to trace the camera rays of a fixed view (320x180 pinhole,
                      one ray a pixel) through a displaced sphere whose fBm has 3, 6
                      and 12 octaves of the same base wavelength (the finer ones far
                      below the pixel), with footprint level of detail: value
                      ``t(12) / t(3)``. Sub-linear in octaves means below 4 (the
                      octave ratio); baseline: the same ratio without level of
                      detail (full detail pays for every octave). Extra fields: the
                      times, and the load average.

Timings taken while other processes load the machine are inflated: compare the
ratios of one run, and read ``load`` beside them.
"""

from __future__ import annotations

import os
import statistics
import time

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


BENCHMARKS = {
    "lod_octaves_cost": (bench_lod_octaves_cost, 5),
}
