"""Timing helpers shared by the benchmark modules (``run.py`` and ``bench_*.py``)."""

from __future__ import annotations

import statistics
import time

import arches_render  # noqa: F401  (first: it chooses the libLLVM that Dr.Jit loads)
import drjit as dr
import mitsuba as mi
import numpy as np


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


def random_points(n, lo, hi, seed=0):
    """``n`` uniform random points in the box [lo, hi] as an ``mi.Point3f``."""
    pts = np.random.default_rng(seed).uniform(lo, hi, (n, 3)).astype(np.float32)
    return mi.Point3f(*(mi.Float(pts[:, i]) for i in range(3)))
