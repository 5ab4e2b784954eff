"""Helpers shared by the benchmarks: ``benchmarks/run.py`` and each generator's ``benchmarks.py``.

Benchmarks run from a checkout of the repository (``python benchmarks/run.py``),
since several render its scene files or start its CLI: :data:`REPO` is that
checkout (the package is installed in editable mode).
"""

from __future__ import annotations

import resource
import statistics
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

#: The repository root (scenes/, benchmarks/), working folder of benchmark subprocesses.
REPO = Path(__file__).resolve().parents[1]


def timed_eval(fn, points, repeat):
    """Median seconds of ``fn(points)`` with kernels compiled (one warm-up)."""
    times = []
    for i in range(repeat + 1):
        # An opaque offset makes each run a new computation of the same kernel.
        p = points + dr.opaque(mi.Float, 1e-6 * i)
        t = time.perf_counter()
        v = fn(p)
        dr.eval(v)
        dr.sync_thread()
        if i:
            times.append(time.perf_counter() - t)
    return statistics.median(times)


def median_renders(scenes, spp, repeat, warm_spp=4):
    """Median seconds of ``render_image(scene, spp, seed=i)`` for each scene.

    Each scene renders once first (compiling its kernels); the timed renders then
    take turns, scene after scene, so that a load that changes during the run
    affects all of them alike.
    """
    from arches_render.render.renderer import render_image
    for scene in scenes:
        render_image(scene, warm_spp, seed=99)
    times = [[] for _ in scenes]
    for i in range(repeat):
        for scene, ts in zip(scenes, times):
            t = time.perf_counter()
            render_image(scene, spp, seed=i)
            ts.append(time.perf_counter() - t)
    return [statistics.median(ts) for ts in times]


def random_points(n, lo, hi, seed=0):
    """``n`` uniform random points in the box [lo, hi] as an ``mi.Point3f``."""
    pts = np.random.default_rng(seed).uniform(lo, hi, (n, 3)).astype(np.float32)
    return mi.Point3f(*(mi.Float(pts[:, i]) for i in range(3)))


def cpu_seconds() -> float:
    """CPU seconds of this process and its reaped children (e.g. a build's worker processes)."""
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime
