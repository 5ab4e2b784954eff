"""Scale-out on Dask distributed: turntable frames, image tiles and golden renders.

Work is a list of :class:`~arches_render.render.jobs.RenderJob` (picklable: a scene
*path* and numbers). Workers run :func:`~arches_render.render.jobs.run_job`, the
function a serial run calls, in a render process of their own
(:mod:`arches_render.render.isolated`: a native crash there is a one-line
:class:`~arches_render.render.isolated.RenderCrash` naming scene, frame or tile and
signal, not a worker lost and the job retried), and send back the pixels; the client
writes every file, so a remote cluster needs the scene files (same path) but no
shared output folder. Determinism comes from the jobs: a frame or a tile has its own sample
stream (:func:`arches_render.render.renderer.pass_seed`), and the box filter
makes a render bitwise reproducible, so the gathered files hold the same bits as
a serial run.

By default :func:`dask_client` starts a :class:`dask.distributed.LocalCluster` of
worker *processes* (Dr.Jit's LLVM backend and Mitsuba's scene state are per
process) with one thread each; ``scheduler`` connects to an existing cluster
instead (``tcp://host:8786``).

Threads: Dr.Jit starts one thread per core in every process, so N workers on one
host would run N x cores threads. :func:`map_jobs` gives every job
``cores // (worker processes on its host)`` Dr.Jit threads (at least 1; cores as
Dask counts them, CPU affinity and cgroup limits included), and a process runs one
job at a time whatever its Dask thread count. :func:`drjit_threads` reports what
each worker uses.

A cluster of several machines (every host sees the scene files, and the files they
name, at the same absolute path; outputs are written by the client only)::

    host0$ dask scheduler                                  # listens on tcp://host0:8786
    hostN$ dask worker tcp://host0:8786 --nworkers 1 --nthreads 1   # on every render host
    client$ arches-render render SCENE --tiles 64 --scheduler tcp://host0:8786
    client$ arches-render turntable SCENE -o DIR --scheduler tcp://host0:8786

One worker process per host with one Dask thread lets Dr.Jit use all of the host's
cores for each job; ``--nworkers K`` splits them K ways (more jobs in flight, each
slower: useful when the client's writing or the scene builds are the bottleneck).
Every host compiles its kernels once into its own ``~/.drjit`` (about 10 s a kernel
on two cores). A new camera and a new tile window are parameter edits: a tile renders
through an off-axis camera with the tile's film
(:func:`~arches_render.render.renderer.tile_projection`), not through a crop of the
full film, whose offset Mitsuba's render loop compiles in (that cost 11 s of
compilation per tile of a 2 x 2 tiling; now 0.13 s a tile after the first, as a
turntable frame).

References
----------
Rocklin, M. (2015). Dask: parallel computation with blocked algorithms and task
scheduling. Proc. 14th Python in Science Conference. ``dask.distributed``:
https://distributed.dask.org
"""

from __future__ import annotations

import contextlib
import logging
import os
import warnings
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from ..imaging.golden import update_golden
from .isolated import RenderCrash, render_process, run_isolated
from .jobs import RenderJob, run_job
from .renderer import moments_of

__all__ = ["dask_client", "map_jobs", "tile_grid", "tile_label", "render_tiled", "regenerate_goldens",
           "drjit_threads", "warm_workers"]


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None) -> Iterator:
    """A Dask client: on ``scheduler``, or on a new LocalCluster of ``workers`` processes.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``).
    workers : int, optional
        Worker processes of the LocalCluster (default: the CPU count), one
        thread each.

    Yields
    ------
    dask.distributed.Client
    """
    from dask.distributed import Client, LocalCluster  # on use: dask is slow to import
    if scheduler:
        client = Client(scheduler)
        try:
            yield client
        finally:
            client.close()
        return
    n = int(workers or os.cpu_count() or 1)
    # The default logging reports every worker start and stop on stderr; a failed job's
    # error (a render process's crash included) is logged by its worker as a traceback,
    # and the jobs cancelled after it as warnings: the client reports the error in one
    # line (map_jobs), so the cluster stays quiet below CRITICAL.
    logging.getLogger("distributed").setLevel(logging.CRITICAL)
    with warnings.catch_warnings():
        # Without a dashboard the scheduler still serves HTTP, on port 8787 when free;
        # with another cluster on this machine it warns that it took another port.
        warnings.filterwarnings("ignore", message=r"Port \d+ is already in use", category=UserWarning)
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.CRITICAL)
    with cluster, Client(cluster) as client:
        yield client


def _cores() -> int:
    # Dask's count honours CPU affinity and cgroup quotas; os.cpu_count() does not.
    from dask.system import CPU_COUNT
    return int(CPU_COUNT or os.cpu_count() or 1)


def _threads_per_worker(client) -> int:
    # Dr.Jit would start one thread per core in every worker process; split the
    # cores of each host between its workers instead (the fewest over hosts).
    info = client.scheduler_info().get("workers", {})
    cores = client.run(_cores)  # {worker address: cores of its host}
    hosts: dict[str, int] = {}
    for w in info.values():
        hosts[w.get("host", "")] = hosts.get(w.get("host", ""), 0) + 1
    per = [int(cores.get(addr) or 1) // hosts[w.get("host", "")] for addr, w in info.items()]
    return max(1, min(per, default=1))


def _drjit_thread_count():
    # None where no job ran yet: the render process starts with the first job.
    return render_process().thread_count()


def drjit_threads(client) -> dict:
    """Dr.Jit threads of every worker's render process: ``{worker address: threads or None}``.

    ``None`` for a worker whose render process has not started (it ran no job yet).
    """
    return client.run(_drjit_thread_count)


def _start_renderer():
    render_process().start()


def warm_workers(client) -> None:
    """Start every worker's render process, which imports Mitsuba and chooses its variant
    (seconds a worker, once)."""
    client.run(_start_renderer)


def map_jobs(client, jobs: Sequence[RenderJob], keys: Sequence | None = None):
    """Run jobs on the cluster; yield ``(key, (rgb, layers))`` as results arrive.

    Parameters
    ----------
    client : dask.distributed.Client
    jobs : sequence of RenderJob
    keys : sequence, optional
        What to yield with each result (default: the job's position).

    Yields
    ------
    (key, (numpy.ndarray, dict))

    Raises
    ------
    RenderCrash
        When a job's render process died (a native crash in the worker: no retry), or
        Dask gave up on a job whose workers kept dying; the other jobs are cancelled.
    """
    from dask.distributed import KilledWorker, as_completed  # on use: dask is slow to import
    keys = list(range(len(jobs))) if keys is None else list(keys)
    threads = _threads_per_worker(client)
    jobs = [j if j.threads else j.with_(threads=threads) for j in jobs]
    futures = client.map(run_isolated, jobs, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    try:
        for fut, result in as_completed(futures, with_results=True):
            yield keys[index[fut.key]], result
    except KilledWorker as exc:
        # Workers killed from outside (SIGKILL, out of memory) while running the job, as
        # often as the scheduler allows: one line, not Dask's paragraph. Their nannies
        # log the signal; the scheduler does not pass it on.
        what = jobs[index[exc.task]].describe() if exc.task in index else str(exc.task)
        n = exc.allowed_failures + 1
        raise RenderCrash(f"{what}: the Dask worker running it died, {n} time{'s' if n > 1 else ''} (the last "
                          f"was {getattr(exc.last_worker, 'address', '?')}; its log names the signal)") from None
    finally:
        client.cancel([f for f in futures if not f.done()])


def tile_grid(width: int, height: int, tiles: int) -> list[tuple[int, int, int, int]]:
    """Split an image into about ``tiles`` rectangles ``(x0, y0, w, h)``, row-major.

    The grid has ``ny = round(sqrt(tiles * h / w))`` rows and ``ceil(tiles / ny)``
    columns, clamped to the image; edges are split as evenly as integers allow.
    """
    ny = int(min(height, max(1, round(np.sqrt(tiles * height / width)))))
    nx = int(min(width, max(1, -(-tiles // ny))))
    xs = np.linspace(0, width, nx + 1).round().astype(int)
    ys = np.linspace(0, height, ny + 1).round().astype(int)
    return [(int(xs[i]), int(ys[j]), int(xs[i + 1] - xs[i]), int(ys[j + 1] - ys[j]))
            for j in range(ny) for i in range(nx)]


def tile_label(i: int, n: int, crop) -> str:
    """``'tile I of N (x X0-X1, y Y0-Y1)'``: tile ``i`` (from 0) in messages, pixels inclusive.

    Parameters
    ----------
    i, n : int
        The tile's index and the number of tiles.
    crop : (int, int, int, int)
        The tile's window ``(x0, y0, w, h)``.

    Returns
    -------
    str
    """
    x0, y0, w, h = crop
    return f"tile {i} of {n} (x {x0}-{x0 + w - 1}, y {y0}-{y0 + h - 1})"


def render_tiled(job: RenderJob, tiles: int, client=None, progress=None):
    """Render a still as tiles (on a Dask client or serially) and assemble it.

    Tile ``i`` uses sample stream ``i``, so the image is the same whoever renders
    the tiles; it differs from an untiled render of the same seed only by noise.

    Parameters
    ----------
    job : RenderJob
        The full-image job (``crop`` and ``stream`` are set per tile).
    tiles : int
        About how many tiles.
    client : dask.distributed.Client, optional
    progress : callable, optional
        ``progress(tiles_done, tiles)``.

    Returns
    -------
    (numpy.ndarray, dict)
        Beauty and layers of the whole image.
    """
    grid = tile_grid(job.width, job.height, tiles)
    jobs = [job.with_(crop=c, stream=i, label=tile_label(i, len(grid), c)) for i, c in enumerate(grid)]
    rgb = np.zeros((job.height, job.width, 3), np.float32)
    layers: dict = {}

    def place(i, result):
        x0, y0, w, h = grid[i]
        t_rgb, t_layers = result
        rgb[y0:y0 + h, x0:x0 + w] = t_rgb
        for name, (arr, letters) in t_layers.items():
            if name not in layers:
                layers[name] = (np.zeros((job.height, job.width, arr.shape[2]), np.float32), letters)
            layers[name][0][y0:y0 + h, x0:x0 + w] = arr

    done = 0
    results = (((i, run_job(j)) for i, j in enumerate(jobs)) if client is None
               else map_jobs(client, jobs))
    for i, result in results:
        place(i, result)
        done += 1
        if progress:
            progress(done, len(jobs))
    return rgb, layers


def regenerate_goldens(scenes: Sequence, golden_dir, width: int, height: int, ref_spp: int,
                       test_spp_of, client=None) -> list:
    """Re-create the golden references of scene files, renders spread over a cluster.

    Every scene's reference (seed 0, ``ref_spp``, with its second moments) is one
    job; once gathered, :func:`arches_render.imaging.golden.update_golden` stores
    it exactly as the serial ``pytest --update-goldens`` would (same seed, same
    renderer).

    Parameters
    ----------
    scenes : sequence of path
        Scene files; the golden name is the file stem.
    golden_dir : path
    width, height, ref_spp : int
    test_spp_of : callable
        ``test_spp_of(name) -> int``.
    client : dask.distributed.Client, optional

    Returns
    -------
    list of Golden
    """
    jobs = [RenderJob(scene=str(Path(p).resolve()), width=width, height=height, spp=ref_spp, moments=True,
                      label="golden reference") for p in scenes]
    keys = [Path(p).stem for p in scenes]
    results = ({k: run_job(j) for k, j in zip(keys, jobs)} if client is None
               else dict(map_jobs(client, jobs, keys)))
    return [update_golden(name, lambda seed, spp, n=name: moments_of(*results[n], spp), ref_spp=ref_spp,
                          test_spp=int(test_spp_of(name)), golden_dir=golden_dir)
            for name in keys]
