"""Dask at scale: a tiled 1280x720 still and a 24-frame turntable, distributed vs one process.

``dask_scale_still_tiles``   ``scenes/default.toml`` at 1280x720, 4 spp, with AOVs, as
                             ``render --tiles 16`` (18 tiles): seconds on a Dask
                             LocalCluster of one worker process per core (one Dask
                             thread and one Dr.Jit thread each) over seconds in this
                             process with Dr.Jit's default threads (one per core).
                             Baseline: 1.0 (the distributed path costs nothing).
``dask_scale_turntable_24``  the same comparison for a 24-frame turntable at 320x180,
                             4 spp, with AOVs, frames written as EXR by the client.

Both first render everything once in this process (kernels compiled and in
Dr.Jit's disk cache, which the workers on this machine share) and start the
cluster before timing; the workers import Mitsuba and render everything once
before the clock starts (each builds its scene once and keeps it, as it does over
a session's frames), so both sides are timed warm.
Extra fields: ``workers``, ``threads_per_worker`` (Dr.Jit threads each worker
reports after the run, :func:`arches_render.render.distributed.drjit_threads`),
``threads_single``, ``tasks``, ``single_s``, ``distributed_s``,
``overhead_ms_per_task`` = (workers x distributed wall - sum of the tasks'
compute times measured in the workers by Dask's task stream) / tasks: every
worker-second not spent rendering (scheduling, pickling, transfers, the client's
assembling and writing, idle workers at the end), ``dispatch_gap_ms`` (median gap
on one worker between a task's end and its next task's start),
``compute_s_per_task`` (in the workers) and ``bitwise_equal`` (every pixel of the
beauty and every layer equal between the two runs). With 4 spp and two cores the
whole benchmark takes a few minutes once kernels are cached (before tiles became
off-axis cameras, each tile compiled its own kernel, 10 s each). Figures are noisy when other
processes share the machine: the result carries the load average.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from pathlib import Path

import drjit as dr
import numpy as np

from arches_render.imaging.exr import read_exr
from arches_render.render.distributed import dask_client, drjit_threads, render_tiled, warm_workers
from arches_render.render.jobs import RenderJob
from arches_render.render.turntable import plan_turntable, render_turntable
from arches_render.scene import load_scene
from arches_render.timing import REPO

SCENE = REPO / "scenes" / "default.toml"


def _same(a, b) -> bool:
    """Beauty and every layer bitwise equal (``a``, ``b``: ``(rgb, {name: (array, letters)})``)."""
    return (np.array_equal(a[0], b[0]) and sorted(a[1]) == sorted(b[1])
            and all(np.array_equal(a[1][k][0], b[1][k][0]) for k in a[1]))


def _task_figures(stream, workers: int, wall: float) -> dict:
    """Overhead figures from Dask's task stream (see the module docstring)."""
    compute, by_worker = [], {}
    for rec in stream:
        for ss in rec.get("startstops", ()):
            if ss.get("action") == "compute":
                compute.append(ss["stop"] - ss["start"])
                by_worker.setdefault(rec.get("worker"), []).append((ss["start"], ss["stop"]))
    gaps = [b[0] - a[1] for spans in by_worker.values() for a, b in zip(sorted(spans), sorted(spans)[1:])]
    n = max(1, len(compute))
    return dict(tasks=len(compute), workers_used=len(by_worker),
                compute_s_per_task=sum(compute) / n,
                overhead_ms_per_task=1e3 * (workers * wall - sum(compute)) / n,
                dispatch_gap_ms=1e3 * statistics.median(gaps) if gaps else 0.0)


def _compare(render, workers: int | None = None, load=lambda r: r) -> dict:
    """Time ``render(client)`` in this process (``client=None``) and on a LocalCluster.

    Parameters
    ----------
    render : callable
        ``render(client) -> result`` (timed); ``load(result)`` (not timed) is a
        list of images compared pairwise with :func:`_same`.
    workers : int, optional
        Worker processes (default: the CPU count).

    Returns
    -------
    dict
        The benchmark's fields (value = distributed / single seconds).
    """
    from dask.distributed import get_task_stream
    load0 = os.getloadavg()[0]
    render(None)  # compile every kernel (Dr.Jit's disk cache serves the workers too)
    t = time.perf_counter()
    single = render(None)
    single_s = time.perf_counter() - t
    threads_single = dr.thread_count()
    workers = int(workers or os.cpu_count() or 1)
    with dask_client(workers=workers) as client:
        warm_workers(client)
        # Each worker's render process builds the scene once and keeps it (jobs' cache),
        # as in a session that renders many frames: build it before the clock starts.
        render(client)
        with get_task_stream(client) as ts:
            t = time.perf_counter()
            dist = render(client)
            dist_s = time.perf_counter() - t
        threads = sorted(set(v for v in drjit_threads(client).values() if v))
    single, dist = load(single), load(dist)
    equal = len(single) == len(dist) and all(_same(a, b) for a, b in zip(single, dist))
    return dict(value=dist_s / single_s, unit="x", baseline=1.0,
                baseline_is="one process, all threads (lower is better)", single_s=single_s,
                distributed_s=dist_s, workers=workers,
                threads_per_worker=threads[0] if len(threads) == 1 else threads,
                threads_single=threads_single, **_task_figures(ts.data, workers, dist_s),
                bitwise_equal=bool(equal), load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


def bench_dask_scale_still_tiles(repeat):
    w, h, spp, tiles = 1280, 720, 4, 16
    job = RenderJob(scene=str(SCENE), width=w, height=h, spp=spp)
    res = _compare(lambda client: [render_tiled(job, tiles, client)])
    return dict(res, resolution=f"{w}x{h}", spp=spp)


def bench_dask_scale_turntable_24(repeat):
    w, h, spp, frames = 320, 180, 4, 24
    desc = load_scene(SCENE)
    with tempfile.TemporaryDirectory() as tmp:
        runs = iter(range(1 << 20))

        def render(client):
            folder = Path(tmp) / f"run{next(runs)}"
            folder.mkdir()
            plan = plan_turntable(desc, SCENE, folder, frames, spp, w, h)
            render_turntable(plan, client=client)
            return plan.paths

        def frames_of(paths):
            return [(e.rgb, {k: (v, "") for k, v in e.layers.items()}) for e in map(read_exr, paths)]

        res = _compare(render, load=frames_of)
    return dict(res, resolution=f"{w}x{h}", spp=spp, frames=frames)


BENCHMARKS = {
    "dask_scale_still_tiles": (bench_dask_scale_still_tiles, 1),
    "dask_scale_turntable_24": (bench_dask_scale_turntable_24, 1),
}
