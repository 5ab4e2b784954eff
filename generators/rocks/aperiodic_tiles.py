"""The aperiodic rock tile set: rocks of the 256 corner cubes, region by region.

Pipeline per region (Peytavie et al. 2009, figure 7):

1. seeds of the region's cells and their 1-neighbourhood
   (:mod:`.corner_cubes`, :mod:`.seed_points`);
2. discrete anisotropic Voronoi labels on the region's voxels plus half a
   cell (:mod:`.anisotropic_voronoi`);
3. contact points by bisection (:mod:`.contact_points`), damping field and
   spheroidal erosion (:mod:`.damped_erosion`);
4. one closed mesh per rock whose seed lies in the region (:mod:`.rock_meshes`).

A rock belongs to the region of its seed's cell and is stored once, however
many corner cubes contain that region; a corner cube is the union of its 8
vertex, 12 edge, 6 face and 1 centre regions (:func:`cube_rocks`).

Regions are independent, so they are built in parallel: in threads of this process for
up to :data:`THREAD_WORKERS` workers, in worker processes (forkserver) for more.
"""

from __future__ import annotations

import os
import time
import warnings

import numba
import numpy as np
from scipy import ndimage

from . import corner_cubes as cc
from .anisotropic_voronoi import CellIndex, voronoi_labels
from .contact_points import adjacent_label_pairs, bisect_contacts
from .damped_erosion import LINEAR, damping_field, erode
from .rock_meshes import anchor_voxels, bounding_radius, field_padding, mesh_rock, rock_field
from .rock_store import RockStore
from .seed_points import cell_seeds
from .tile_params import TileParams

__all__ = ["region_seeds", "region_labels", "build_region", "build_aperiodic_tiles", "cube_rocks",
           "cube_slots", "THREAD_WORKERS"]

#: Up to this many workers, threads of this process build the regions (where numba's
#: threading layer allows it, :func:`_threadsafe_kernels`); more, worker processes. Every kernel releases the GIL, but ~30 % of a region's time is Python and
#: numpy holding it, so threads stop scaling where processes go on; a process, though,
#: costs a start (0.5 s for the forkserver's imports) and loads the compiled kernels
#: again (0.3 s). On 2 cores (n = 5, 318 regions): threads 4.0 s, processes 4.7 s with
#: the forkserver running and 5.1-5.5 s when it starts.
THREAD_WORKERS = 2


def region_seeds(mask: int, code: int, params: TileParams):
    """Seeds of a region's known cells (region + 1-neighbourhood), base at the origin."""
    n = params.n
    known = cc.region_known_cells(mask, n)
    m, base, rel = cc.cell_owners(known, n)
    codes = cc.owner_colour_codes(m, base, cc.region_colour_lookup(mask, code))
    keys = cc.cell_keys(m, codes, rel, params.seed)
    seeds = cell_seeds(known, keys, params.seeds)
    lo = known.min(axis=0)
    return CellIndex(seeds, lo, known.max(axis=0) - lo + 1)


def region_grid(mask: int, n: int, V: int):
    """Voxel box of a region: its cells plus half a cell and one voxel (``g0``, ``shape``)."""
    cells = cc.region_cells(mask, n)
    g0 = cells.min(axis=0) * V - V // 2 - 1
    g1 = (cells.max(axis=0) + 1) * V + V // 2 + 1
    return g0, g1 - g0


def region_labels(mask: int, code: int, params: TileParams):
    """Voronoi labels of a region's voxel box and the mask of its own seeds.

    Returns
    -------
    index : CellIndex
    g0 : (3,) int64
    labels : int32 array
    own : (K,) bool
        Seeds whose cell lies in the region.
    """
    index = region_seeds(mask, code, params)
    g0, shape = region_grid(mask, params.n, params.voxels_per_cell)
    labels = voronoi_labels(index, g0, shape, params.voxels_per_cell)
    cells = cc.region_cells(mask, params.n)
    lo, hi = cells.min(axis=0), cells.max(axis=0)
    sc = index.seeds.cell
    own = np.all((sc >= lo) & (sc <= hi), axis=1)
    return index, g0, labels, own


def build_region(mask: int, code: int, params: TileParams, slot: int) -> list[dict]:
    """Rocks of one region (see module docstring).

    Returns
    -------
    list of dict
        Per rock: vertices, faces, normals (cells, region-local), seed,
        radius, uid, slot, anchors.
    """
    V, er = params.voxels_per_cell, params.erosion
    index, g0, labels, own = region_labels(mask, code, params)
    seeds = index.seeds
    pairs = adjacent_label_pairs(labels)
    pairs = pairs[own[pairs[:, 0]] | own[pairs[:, 1]]]
    contacts = bisect_contacts(seeds, pairs)
    omega = damping_field(labels, g0, V, len(seeds), pairs, contacts, er.contact_radius,
                          er.blend_radius, LINEAR, own=own)
    rho = erode(labels, own, omega, er.steps, er.rate)
    return _rocks_from_grid(labels, rho, g0, V, seeds.position, seeds.uid, np.nonzero(own)[0],
                            params, slot)


def _rocks_from_grid(labels, rho, g0, V, seed_pos, uid, own_ids, params, slot):
    """Mesh every rock ``k in own_ids`` of a labelled, eroded grid."""
    pad = field_padding(params.erosion.smoothing, params.mesh_step)
    boxes = ndimage.find_objects(labels + 1)
    rocks = []
    for k in own_ids:
        if k >= len(boxes) or boxes[k] is None:
            continue
        lo = np.array([s.start for s in boxes[k]])
        hi = np.array([s.stop for s in boxes[k]])
        field = rock_field(labels, rho, k, lo, hi, params.erosion.smoothing, pad)
        origin = np.asarray(g0) + lo - pad
        rock = _rock_record(field, origin, V, seed_pos[k], uid[k], params, slot)
        if rock is not None:
            rocks.append(rock)
    return rocks


def _rock_record(field, origin, V, seed_pos, uid, params, slot):
    mesh = mesh_rock(field, origin, V, params.mesh_step)
    if mesh is None:
        return None
    verts, faces, normals = mesh
    # Anchors (section 6): centres of voxels that hold rock, evenly subsampled.
    anchors = (anchor_voxels(field, params.anchors) + np.asarray(origin) + 0.5) / V
    p = np.asarray(seed_pos, dtype=np.float64)
    return dict(vertices=verts, faces=faces, normals=normals, seed=p,
                radius=bounding_radius(verts, p),
                uid=np.uint64(uid), slot=slot, anchors=anchors.astype(np.float32))


def _build_slots(args):
    """Rocks of the regions ``slots`` and the CPU seconds this process spent on them."""
    slots, params = args
    c0 = time.process_time()
    all_regions = cc.regions()
    out = []
    for s in slots:
        mask, code = all_regions[s]
        out.extend(build_region(mask, code, params, s))
    return out, time.process_time() - c0


def build_aperiodic_tiles(params: TileParams, progress=None, workers: int | None = None) -> RockStore:
    """The whole aperiodic tile set: rocks of all 318 regions (2 + 12 + 48 + 256).

    Parameters
    ----------
    params : TileParams
        With ``tiling = 'aperiodic'``.
    progress : callable, optional
        ``progress(done_regions, total_regions)``.
    workers : int, optional
        Workers (default: the CPU count, at most 8; 1 runs inline): threads up to
        :data:`THREAD_WORKERS`, else processes. Processes are started by
        multiprocessing's forkserver and import the main script again, so a script
        calling this wants the usual ``if __name__ == "__main__":`` guard; without it
        the tiles are built in its own process, with a warning (:func:`_in_workers`).
        The tiles are the same bits whatever the workers.

    Returns
    -------
    RockStore
        Slots are region indices of :func:`.corner_cubes.regions`.

    References
    ----------
    Peytavie et al. 2009, sections 3-5 and table 1.
    """
    if params.tiling != "aperiodic":
        raise ValueError("build_aperiodic_tiles needs tiling = 'aperiodic'")
    t0 = time.perf_counter()
    all_regions = cc.regions()
    # Centre regions dominate the cost; interleave so every batch is alike.
    order = list(range(len(all_regions)))
    workers = workers or min(os.cpu_count() or 1, 8)
    batches = [order[i::max(1, 4 * workers)] for i in range(max(1, 4 * workers))]
    rocks = []
    done, cpu = 0, 0.0  # (cpu: of worker processes; threads' is this process's own)
    if 1 < workers <= THREAD_WORKERS and _threadsafe_kernels():
        for b, res in zip(batches, _in_threads(batches, params, workers)):
            rocks.extend(res)
            done += len(b)
            if progress:
                progress(done, len(order))
    elif workers > 1:
        try:
            for b, (res, c) in zip(batches, _in_workers(batches, params, workers)):
                rocks.extend(res)
                cpu += c
                done += len(b)
                if progress:
                    progress(done, len(order))
        except _WorkersFailed as exc:
            # Built in this process instead, from the start (the same slots give the same bits).
            warnings.warn(str(exc), RuntimeWarning, stacklevel=2)
            rocks, done, cpu, workers = [], 0, 0.0, 1
    if workers <= 1:
        for b in batches:
            rocks.extend(_build_slots((b, params))[0])
            done += len(b)
            if progress:
                progress(done, len(order))
    meta = dict(tiling="aperiodic", params=params.to_dict(), n=params.n, cells_per_period=params.n,
                voxels_per_cell=params.voxels_per_cell, build_seconds=time.perf_counter() - t0,
                worker_cpu_seconds=cpu, regions=len(all_regions))
    return RockStore.from_rocks(rocks, len(all_regions), meta)


def _threadsafe_kernels() -> bool:
    """Whether numba's parallel kernels may run from several threads at once: its
    ``omp`` and ``tbb`` layers allow it, its fallback ``workqueue`` aborts the process."""
    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel kernel has run yet: let numba choose its layer now
        try:  # (what the first parallel kernel would do; 18 ms, where compiling one took 10 s)
            from numba.np.ufunc.parallel import _launch_threads
            _launch_threads()
            layer = numba.threading_layer()
        except (ImportError, ValueError):  # numba's internals moved: processes are safe
            return False
    return layer in ("omp", "tbb")


def _in_threads(batches, params, workers):
    """The rocks of each batch, in order, from ``workers`` threads of this process.

    Each thread asks numba for one thread (a thread-local setting), as a worker process
    does: the workers, not the kernels, take the cores.
    """
    from concurrent.futures import ThreadPoolExecutor

    def build(batch):
        numba.set_num_threads(1)
        return _build_slots((batch, params))[0]

    with ThreadPoolExecutor(workers) as pool:
        yield from pool.map(build, batches)


class _WorkersFailed(RuntimeError):
    """The worker processes could not start (see :func:`_in_workers`)."""


def _in_workers(batches, params, workers):
    """``(rocks, cpu seconds)`` of each batch, in order, from ``workers`` processes.

    Not "fork": a parent that already ran numba's (or Dr.Jit's) thread pools can hand a
    child a lock held by a thread that does not exist there, and the child hangs. With
    forkserver (spawn elsewhere) every worker imports the parent's main script again, as
    Python's multiprocessing does; a script whose top level is not guarded by ``if
    __name__ == "__main__":`` then runs again in the worker, where multiprocessing refuses
    to start processes while the worker is still starting (its "bootstrapping phase"
    RuntimeError), so the worker stops and
    :class:`concurrent.futures.ProcessPoolExecutor` reports the broken pool, raised here
    as :class:`_WorkersFailed` with the remedy (``multiprocessing.Pool`` started new
    workers forever: an unguarded script hung). The server preloads this module only,
    not ``__main__`` (a preloaded unguarded script ran inside the server, which then
    waited on itself).
    """
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    ctx = mp.get_context("forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn")
    if ctx.get_start_method() == "forkserver":
        # The server imports this module once and forks the workers from it, so they do
        # not each import numba, scipy and scikit-image again (n = 5 benchmark: a worker's
        # CPU time before its first task 0.88 -> 0.46 s). No effect once the server runs.
        ctx.set_forkserver_preload([__name__])
    try:
        with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_single_thread) as pool:
            yield from pool.map(_build_slots, [(b, params) for b in batches])
    except BrokenProcessPool:
        import sys
        script = getattr(sys.modules.get("__main__"), "__file__", None) or "the main script"
        raise _WorkersFailed(
            f"rock tiles built in this process: their worker processes stopped (most often because "
            f"they import {script} again and its top level is not guarded: guard it with "
            f"'if __name__ == \"__main__\":', Python's multiprocessing rule; else a worker was killed)") from None


def _single_thread():
    import numba
    numba.set_num_threads(1)


def cube_slots(config: int) -> list[tuple[int, np.ndarray]]:
    """The 27 regions of corner cube ``config``: ``(region index, base offset in lattice units)``.

    Vertex regions sit at the 8 corners, edge regions at the 12 edges, face
    regions at the 6 faces, and the centre region inside; each is the region
    whose corners are the cube's corners it touches.
    """
    colours = cc.cube_colours(config).reshape(2, 2, 2, order="F")   # [x, y, z]
    out = []
    for mask in cc.REGION_MASKS:
        near = [(mask >> a) & 1 for a in range(3)]
        for corner in np.ndindex(*(2 if near[a] else 1 for a in range(3))):
            base = np.array(corner, dtype=np.int64)
            code = 0
            for j, off in enumerate(cc.region_vertex_offsets(mask)):
                v = base + off
                code |= int(colours[v[0], v[1], v[2]]) << j
            out.append((int(cc.region_index(mask, code)), base))
    return out


def cube_rocks(store: RockStore, config: int):
    """Rocks of corner cube ``config`` whose seed lies inside the cube ``[0, n)^3`` (cells).

    Returns
    -------
    ids : (K,) int64
        Rock indices into ``store``.
    offsets : (K, 3) float64
        Cell offset to add to each rock's slot-local coordinates.
    """
    n = store.meta["n"]
    ids, offs = [], []
    for slot, base in cube_slots(config):
        r = store.slot_rocks(slot)
        seeds = store.seed[r] + base * n
        inside = np.all((seeds >= 0) & (seeds < n), axis=1)
        ids.append(r[inside])
        offs.append(np.repeat(base[None] * n, inside.sum(), axis=0).astype(np.float64))
    return np.concatenate(ids), np.concatenate(offs)
