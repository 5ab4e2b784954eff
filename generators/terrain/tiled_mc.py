"""Marching cubes by column tiles and z runs, stitched into one mesh (issue 37 item 2).

The grid's columns are cut into tiles of ``TILE x TILE`` cubes; a tile holds the
vertex columns ``[i0, i0 + TILE]`` (one column shared with each neighbour, so every
cube belongs to exactly one tile). Each tile is meshed by *runs*: its maximal runs
of consecutive cube layers ``c0 .. c1`` that hold a crossing cube (corners on both
sides of 0), i.e. the sub-volume of levels ``c0 .. c1 + 1``. scikit-image's marching
cubes (Lewiner) runs on each run.

**Why the triangles are those of the whole grid.** A cube's triangles depend on its
8 corner values only, and a cube whose corners share one sign emits none; every
crossing cube lies in exactly one run. Two runs share no vertex: a vertex sits on
an edge whose end values differ in sign, every cube holding that edge crosses, and
two runs of a tile are separated by a layer of non-crossing cubes (runs of
different tiles meet only on the tiles' side faces, below).

**Stitching.** Vertices are keyed by the grid edge they lie on (its lower end point
and axis, :func:`_run_keys`), and their positions are recomputed from the edge's
values with the global index, as scikit-image computes them: both are then
independent of the run's origin (whose local ``float32`` coordinates round
differently). Vertices on a tile's side faces and at grid points are merged by key,
keeping the first in tile order; faces that then repeat a vertex are dropped (as
scikit-image drops degenerate faces). Interior vertices of Lewiner's subcases (one
per cube) are never shared.

**Same mesh, banded or dense.** The runs are found from the signs alone, so the
banded mesh (crossing layers searched within the band's windows) and the dense
reference (searched over every cube of the grid) have the same runs as soon as
their values have the same signs, and go through this same function: equal faces
bit for bit, in the same order (tile order, then scikit-image's within each run).
"""

from __future__ import annotations

import numba
import numpy as np
from skimage.measure import marching_cubes

from arches_render.mesh.lewiner import lewiner_luts, plain_runs_chunked
from arches_render.mesh.polygonize import TriangleMesh, oriented_mesh

__all__ = ["TILE", "DELTA", "mesh_runs"]

#: Cubes per tile side.
TILE = 32
#: Coordinates within this many voxels of an integer are on the grid line (see module doc).
DELTA = 2.0 ** -12


@numba.njit(cache=True)
def _edge_t(vt, loc, axis):
    """``t = v0 / (v0 - v1)`` on the run's edge from ``loc`` along ``axis`` (double, as
    scikit-image), or -1 when the edge does not cross (its ends on one side of 0)."""
    if loc[axis] < 0 or loc[axis] + 1 >= vt.shape[axis]:
        return -1.0
    v0 = np.float64(vt[loc[0], loc[1], loc[2]])
    loc[axis] += 1
    v1 = np.float64(vt[loc[0], loc[1], loc[2]])
    loc[axis] -= 1
    if (v0 > 0) == (v1 > 0):
        return -1.0
    return v0 / (v0 - v1)


@numba.njit(cache=True)
def _run_keys(v, vt, origin, box, ny, nz, delta):
    """Grid positions (float32, grid units), edge keys and shareability of one run's
    vertices ``v`` (scikit-image's output on ``vt``, the run's values).

    Key ``((i ny + j) nz + k) 4 + a`` for a vertex on the edge from grid point
    ``(i, j, k)`` along axis ``a``; ``a = 3`` for a vertex at the grid point itself
    (``t < delta / 2`` or ``1 - t < delta / 2``); -1 for a cube's interior vertex
    (never shared). The key and the position, ``float32(k + t)`` with
    ``t = v0 / (v0 - v1)`` in double as scikit-image computes it (checked bit for bit
    in the tests) but from the *global* index, are functions of the edge's values
    alone, not of the run's origin (whose local ``float32`` coordinates round ``t``
    differently): two runs that hold one edge give it one key.

    Which edge: a vertex with two local coordinates within ``delta`` of integers and
    one farther is on that axis' edge (then ``t >= delta - ulp > delta / 2``). One
    with three is near grid point ``p``: of the (at most six) crossing edges at
    ``p``, it is the one whose local ``float32`` position is the vertex's.
    """
    n = v.shape[0]
    g = np.empty((n, 3), dtype=np.float32)  # exact: grid integers and float32(k + t)
    keys = np.full(n, -1, dtype=np.int64)
    share = np.zeros(n, dtype=np.bool_)
    i0, i1, j0, j1 = box[0], box[1], box[2], box[3]
    loc = np.empty(3, dtype=np.int64)
    for q in range(n):
        frac_axis = -1
        nint = 0
        for a in range(3):
            x = np.float64(v[q, a])
            rx = np.floor(x + 0.5)
            if abs(x - rx) < delta:
                loc[a] = np.int64(rx)
                nint += 1
            else:
                loc[a] = np.int64(np.floor(x))
                frac_axis = a
        if nint < 2:
            for a in range(3):
                g[q, a] = np.float32(np.float64(v[q, a]) + origin[a])
            continue
        t = -1.0
        if nint == 2:
            t = _edge_t(vt, loc, frac_axis)
        else:
            # Near a grid point p: find the crossing edge at p that gave this vertex
            # (loc ends at the edge's lower end).
            for a in range(3):
                for back in range(2):
                    loc[a] -= back
                    tt = _edge_t(vt, loc, a)
                    if tt >= 0.0 and np.float32(np.float64(loc[a]) + tt) == v[q, a]:
                        frac_axis, t = a, tt
                        break
                    loc[a] += back
                if t >= 0.0:
                    break
        # Resolve to a grid point when t is within delta / 2 of an end.
        axis = 3
        if t >= 0.0 and 0.5 * delta <= t <= 1.0 - 0.5 * delta:
            axis = frac_axis
        elif t > 0.5:  # at the edge's upper end
            loc[frac_axis] += 1
        i, j, k = loc[0] + origin[0], loc[1] + origin[1], loc[2] + origin[2]
        g[q, 0], g[q, 1], g[q, 2] = i, j, k
        if axis < 3:
            g[q, axis] = np.float32(np.float64(g[q, axis]) + t)
        keys[q] = ((i * ny + j) * nz + k) * 4 + axis
        share[q] = axis == 3 or (axis != 0 and (i == i0 or i == i1)) or (axis != 1 and (j == j0 or j == j1))
    return g, keys, share


#: Vertices or faces a block of the parallel passes below (their counts are prefix-summed by block).
_BLOCK = 1 << 16


@numba.njit(cache=True)
def _merge_targets(order, sorted_keys, target):
    """``target[q]``: the vertex that ``q`` merges into, the first of its key in
    ``order`` (shareable vertices sorted by key, stably: the first in tile order);
    -1 (unchanged) for a vertex that is kept."""
    lead = -1
    for s in range(len(order)):
        if s > 0 and sorted_keys[s] == sorted_keys[s - 1]:
            target[order[s]] = lead
        else:
            lead = order[s]


@numba.njit(cache=True, parallel=True)
def _renumber(target):
    """New index of every vertex: kept ones (``target < 0``) numbered in order, merged
    ones given their target's number. Returns ``(new, kept)``."""
    n = len(target)
    nb = (n + _BLOCK - 1) // _BLOCK
    counts = np.zeros(nb + 1, dtype=np.int64)
    for b in numba.prange(nb):
        c = 0
        for q in range(b * _BLOCK, min(n, (b + 1) * _BLOCK)):
            c += target[q] < 0
        counts[b + 1] = c
    counts = np.cumsum(counts)
    new = np.empty(n, dtype=np.int64)
    for b in numba.prange(nb):
        c = counts[b]
        for q in range(b * _BLOCK, min(n, (b + 1) * _BLOCK)):
            if target[q] < 0:
                new[q] = c
                c += 1
    # A target comes before its vertex in order and is kept: numbered above.
    for q in numba.prange(n):
        if target[q] >= 0:
            new[q] = new[target[q]]
    return new, counts[nb]


@numba.njit(cache=True, parallel=True)
def _place_vertices(out, g, first, target, new, voxel, lo):
    """World positions (``g voxel + lo``, float32 -> float64 first as scikit-image's
    ``vertices * spacing``) of a part's kept vertices (global numbers from ``first``)."""
    for q in numba.prange(len(g)):
        if target[first + q] < 0:
            for a in range(3):
                out[new[first + q], a] = np.float32(np.float64(g[q, a]) * voxel + lo[a])


@numba.njit(cache=True, parallel=True)
def _count_faces(faces, first, new):
    """Faces of each block of a part (vertex numbers local, from ``first``) that keep
    three distinct vertices once renumbered."""
    nb = (len(faces) + _BLOCK - 1) // _BLOCK
    counts = np.zeros(nb, dtype=np.int64)
    for b in numba.prange(nb):
        c = 0
        for r in range(b * _BLOCK, min(len(faces), (b + 1) * _BLOCK)):
            x, y, z = new[first + faces[r, 0]], new[first + faces[r, 1]], new[first + faces[r, 2]]
            c += x != y and y != z and x != z
        counts[b] = c
    return counts


@numba.njit(cache=True, parallel=True)
def _write_faces(out, at, faces, first, new):
    """The faces :func:`_count_faces` counted, renumbered, block ``b`` from ``at[b]``."""
    nb = (len(faces) + _BLOCK - 1) // _BLOCK
    for b in numba.prange(nb):
        m = at[b]
        for r in range(b * _BLOCK, min(len(faces), (b + 1) * _BLOCK)):
            x, y, z = new[first + faces[r, 0]], new[first + faces[r, 1]], new[first + faces[r, 2]]
            if x != y and y != z and x != z:
                out[m, 0], out[m, 1], out[m, 2] = x, y, z
                m += 1


def _stitch(parts, voxel, lo):
    """Merge the shareable vertices of equal key into the first one in tile order,
    renumber the kept vertices in order, and drop the faces that then repeat a vertex.

    Parameters
    ----------
    parts : list of (g, keys, share, faces)
        Vertices (float32 grid units), their edge keys and shareability, and faces
        numbered within the part; the parts in tile order.
    voxel : float
    lo : (3,) float64
        The grid's origin.

    Returns
    -------
    (vertices, faces)
        float32 ``(V, 3)`` world positions, uint32 ``(F, 3)``.

    The parts are never concatenated: the passes over vertices and faces run in
    numba's threads part by part, each vertex and face written once at its final
    place (blocks counted, then prefix-summed), as a serial pass over the
    concatenated arrays would write them, bit for bit.
    """
    firsts = np.cumsum([0] + [len(g) for g, _, _, _ in parts])
    cand = np.concatenate([np.flatnonzero(sh) + f for (_, _, sh, _), f in zip(parts, firsts)])
    cand_keys = np.concatenate([k[sh] for _, k, sh, _ in parts])
    by_key = np.argsort(cand_keys, kind="stable")  # stable: the first in tile order leads
    target = np.full(firsts[-1], -1, dtype=np.int64)
    _merge_targets(cand[by_key], cand_keys[by_key], target)
    new, kept = _renumber(target)
    vertices = np.empty((kept, 3), dtype=np.float32)
    counts = []
    for (g, _, _, f), first in zip(parts, firsts):
        _place_vertices(vertices, g, first, target, new, voxel, lo)
        counts.append(_count_faces(f, first, new))
    at = np.cumsum(np.concatenate([[0]] + counts))
    faces = np.empty((at[-1], 3), dtype=np.uint32)
    b = 0
    for (_, _, _, f), first, c in zip(parts, firsts, counts):
        _write_faces(faces, at[b:b + len(c)], f, first, new)
        b += len(c)
    return vertices, faces


def mesh_runs(node, flat, runs, shape, lo, voxel, normals=True) -> TriangleMesh:
    """Stitched marching-cubes mesh of ``runs`` (see module docstring).

    Parameters
    ----------
    node : Node
        The field (for normals).
    flat : numpy.ndarray
        1-D float32 values the runs index.
    runs : numpy.ndarray
        ``(R, 13)`` rows ``(base, si, sj, sx, sy, sz, oi, oj, ok, i0, i1, j0, j1)`` in
        tile order, then increasing ``ok`` (see :func:`arches_render.mesh.lewiner.plain_runs`).
    shape, lo, voxel
        The grid.
    normals : bool
        Field normals and one orientation (``oriented_mesh``); else none and
        scikit-image's winding.
    """
    ny, nz = int(shape[1]), int(shape[2])
    # The plain cases compiled (arches_render.mesh.lewiner), keyed positions at level 0.
    # (in threads over chunks of runs: the single call's arrays once concatenated)
    parts, declined = [], []
    for first, (g, keys, share, f, _, dec) in plain_runs_chunked(flat, runs, ny, nz, DELTA, 0.0, 1, False,
                                                                 *lewiner_luts()):
        parts.append((g, keys, share, f))
        declined.extend((dec + first).tolist())
    # The runs with face or interior tests, through scikit-image (after the plain
    # ones: the same order for the banded and the dense mesh), as one more part.
    verts, faces, keyl, shares, nv = [], [], [], [], 0
    for r in declined:
        base, si, sj, sx, sy, sz, oi, oj, ok, *box = runs[r].tolist()
        vt = np.lib.stride_tricks.as_strided(flat[base:], (sx, sy, sz), (4 * si, 4 * sj, 4), writeable=False)
        vt = np.ascontiguousarray(vt)
        try:
            # (A run holds a crossing cube, so 0 lies within its values.)
            v, f, _, _ = marching_cubes(vt, 0.0, allow_degenerate=True)
        except RuntimeError:  # "No surface found": the crossing was a 0 corner only
            continue
        g, key, sh = _run_keys(v, vt, np.array([oi, oj, ok]), np.array(box), ny, nz, DELTA)
        verts.append(g)
        keyl.append(key)
        shares.append(sh)
        faces.append(f.astype(np.int32) + np.int32(nv))
        nv += len(g)
    if verts:
        parts.append((np.concatenate(verts), np.concatenate(keyl), np.concatenate(shares), np.concatenate(faces)))
    if sum(len(g) for g, _, _, _ in parts) == 0:
        raise ValueError("the field has no surface inside its bounds at this voxel size")
    v, f = _stitch(parts, float(voxel), np.asarray(lo, np.float64))
    if not normals:
        return TriangleMesh(v, f, np.zeros((0, 3), dtype=np.float32))
    return oriented_mesh(node, v, f, voxel)
