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
from skimage.measure import _marching_cubes_lewiner as _lewiner
from skimage.measure import _marching_cubes_lewiner_luts as _luts
from skimage.measure import marching_cubes

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


@numba.njit(cache=True)
def _stitch(g, faces, keys, order, voxel, lo):
    """Merge the vertices ``order`` (shareable, sorted by key, stably) of equal key into
    the first one in tile order, renumber the kept vertices in order (world
    coordinates ``g voxel + lo``, float32 -> float64 first as scikit-image's
    ``vertices * spacing``), and drop the faces that then repeat a vertex."""
    n = len(g)
    rep = np.arange(n)
    for s in range(1, len(order)):
        if keys[order[s]] == keys[order[s - 1]]:
            rep[order[s]] = rep[order[s - 1]]
    new = np.empty(n, dtype=np.int64)
    kept = 0
    for q in range(n):
        if rep[q] == q:
            new[q] = kept
            kept += 1
    out_g = np.empty((kept, 3), dtype=np.float32)
    for q in range(n):
        if rep[q] == q:
            for a in range(3):
                out_g[new[q], a] = np.float32(np.float64(g[q, a]) * voxel + lo[a])
    out_f = np.empty(faces.shape, dtype=np.uint32)
    m = 0
    for r in range(len(faces)):
        a, b, c = new[rep[faces[r, 0]]], new[rep[faces[r, 1]]], new[rep[faces[r, 2]]]
        if a != b and b != c and a != c:
            out_f[m, 0], out_f[m, 1], out_f[m, 2] = a, b, c
            m += 1
    return out_g, out_f[:m]


#: Lewiner's cases whose tiling is a fixed table (no face or interior test).
_PLAIN = (1, 2, 5, 8, 9, 11, 14)
_TABLES = {}


def _tables():
    """scikit-image's Lewiner tables for the plain cases, as arrays for numba:
    ``cases (256, 2)``, ``til (15, 48, 12)`` edge lists, ``ntri (15,)`` (0: not plain),
    corner offsets ``(8, 3)`` and edge lower ends ``(12, 3)`` and axes ``(12,)`` in
    array axes ``(i, j, k)`` (Lewiner's ``x, y, z`` are the array's axes 2, 1, 0)."""
    if not _TABLES:
        til = np.zeros((15, 48, 12), dtype=np.int64)
        ntri = np.zeros(15, dtype=np.int64)
        for c in _PLAIN:
            a = _lewiner._to_array(getattr(_luts, f"TILING{c}"))
            til[c, :a.shape[0], :a.shape[1]] = a
            ntri[c] = a.shape[1] // 3
        xyz = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
        corner = np.array([(z, y, x) for x, y, z in xyz], dtype=np.int64)
        ex, ey, ez = _lewiner.EDGETORELATIVEPOSX, _lewiner.EDGETORELATIVEPOSY, _lewiner.EDGETORELATIVEPOSZ
        ends = np.stack([ez, ey, ex], axis=-1).astype(np.int64)  # (12 edges, 2 ends, (i, j, k))
        edge_lo = ends.min(axis=1)
        edge_axis = np.argmax(ends[:, 1] != ends[:, 0], axis=1).astype(np.int64)
        _TABLES.update(cases=_lewiner._to_array(_luts.CASES).astype(np.int64), til=til, ntri=ntri,
                       corner=corner, edge_lo=edge_lo, edge_axis=edge_axis)
    return _TABLES


@numba.njit(cache=True)
def _grow(a, n):
    """``a`` with room for at least ``n`` rows (doubling)."""
    if n <= a.shape[0]:
        return a
    shape = (max(n, 2 * a.shape[0]),) + a.shape[1:]
    b = np.empty(shape, dtype=a.dtype)
    b[:a.shape[0]] = a
    return b


# (error_model numpy: no ZeroDivisionError check; a crossing edge has v0 > 0 >= v1 or the reverse.)
@numba.njit(cache=True, error_model="numpy")
def _plain_runs(flat, runs, ny, nz, delta, cases, til, ntri, corner, edge_lo, edge_axis):
    """Lewiner's marching cubes on every run whose crossing cubes are all plain cases:
    the triangles scikit-image emits (same tables, same traversal, same winding,
    vertex positions and keys as :func:`_run_keys`), vertices numbered on first use.

    ``runs[r] = (base, si, sj, sx, sy, sz, oi, oj, ok, i0, i1, j0, j1)``: the run's
    value at ``(i, j, k)`` is ``flat[base + i si + j sj + k]``, its grid origin is
    ``(oi, oj, ok)``, its tile ``(i0, i1, j0, j1)``. Returns ``(g, keys, share, faces,
    declined)``: the runs with a cube of another case (face and interior tests) are
    rolled back and listed in ``declined``, for scikit-image.
    """
    vmax = 0
    for r in range(runs.shape[0]):
        vmax = max(vmax, runs[r, 3] * runs[r, 4] * runs[r, 5])
    table = np.full(vmax * 4, -1, dtype=np.int32)
    g = np.empty((1 << 16, 3), dtype=np.float32)
    keys = np.empty(1 << 16, dtype=np.int64)
    share = np.empty(1 << 16, dtype=np.bool_)
    faces = np.empty((1 << 17, 3), dtype=np.int32)
    declined = np.empty(runs.shape[0], dtype=np.int64)
    touched = np.empty(1 << 16, dtype=np.int64)
    nv, nf, nd, nt = 0, 0, 0, 0
    p = np.empty(3, dtype=np.int64)
    tri = np.empty(3, dtype=np.int64)
    # Cube index from the sign codes of its two horizontal faces: a face's code at
    # level k has bit 2 di + dj for corner (di, dj); ``pair[lo, hi]`` is Lewiner's index.
    pair = np.zeros((16, 16), dtype=np.int64)
    for lo in range(16):
        for hi in range(16):
            for c in range(8):
                q = hi if corner[c, 2] else lo
                if (q >> (2 * corner[c, 0] + corner[c, 1])) & 1:
                    pair[lo, hi] |= 1 << c
    for r in range(runs.shape[0]):
        base, si, sj, sx, sy, sz = runs[r, 0], runs[r, 1], runs[r, 2], runs[r, 3], runs[r, 4], runs[r, 5]
        oi, oj, ok, i0, i1, j0, j1 = runs[r, 6], runs[r, 7], runs[r, 8], runs[r, 9], runs[r, 10], runs[r, 11], runs[r, 12]
        nv0, nf0 = nv, nf
        fail = False
        for i in range(sx - 1):
            for j in range(sy - 1):
                b00 = base + i * si + j * sj
                b01, b10 = b00 + sj, b00 + si
                b11 = b10 + sj
                nxt = (flat[b00] > 0) | ((flat[b01] > 0) << 1) | ((flat[b10] > 0) << 2) | ((flat[b11] > 0) << 3)
                # Room for this column of cubes (at most 12 vertices, 4 faces a cube).
                if nv + 12 * sz > g.shape[0]:
                    g = _grow(g, nv + 12 * sz)
                    keys = _grow(keys, nv + 12 * sz)
                    share = _grow(share, nv + 12 * sz)
                if nf + 4 * sz > faces.shape[0]:
                    faces = _grow(faces, nf + 4 * sz)
                if nt + 24 * sz > touched.shape[0]:
                    touched = _grow(touched, nt + 24 * sz)
                for k in range(sz - 1):
                    cur = nxt
                    nxt = ((flat[b00 + k + 1] > 0) | ((flat[b01 + k + 1] > 0) << 1) | ((flat[b10 + k + 1] > 0) << 2)
                           | ((flat[b11 + k + 1] > 0) << 3))
                    idx = pair[cur, nxt]
                    if idx == 0 or idx == 255:
                        continue
                    case = cases[idx, 0]
                    if case == 0:
                        continue
                    if ntri[case] == 0:
                        fail = True
                        break
                    cfg = cases[idx, 1]
                    for t3 in range(3 * ntri[case]):
                        e = til[case, cfg, t3]
                        a = edge_axis[e]
                        p[0], p[1], p[2] = i + edge_lo[e, 0], j + edge_lo[e, 1], k + edge_lo[e, 2]
                        # An edge's slot holds its vertex (or the grid point's it snapped to).
                        slot = ((p[0] * sy + p[1]) * sz + p[2]) * 4 + a
                        if table[slot] < 0:
                            touched[nt] = slot
                            nt += 1
                            q0 = base + p[0] * si + p[1] * sj + p[2]
                            v0 = np.float64(flat[q0])
                            v1 = np.float64(flat[q0 + (si if a == 0 else sj if a == 1 else 1)])
                            t = v0 / (v0 - v1)
                            axis = a
                            vslot = slot
                            if t < 0.5 * delta or t > 1.0 - 0.5 * delta:  # at a grid point
                                axis = 3
                                if t > 0.5:
                                    p[a] += 1
                                vslot = ((p[0] * sy + p[1]) * sz + p[2]) * 4 + 3
                            if table[vslot] < 0:
                                table[vslot] = nv - nv0
                                if vslot != slot:
                                    touched[nt] = vslot
                                    nt += 1
                                gi, gj, gk = p[0] + oi, p[1] + oj, p[2] + ok
                                g[nv, 0], g[nv, 1], g[nv, 2] = gi, gj, gk
                                if axis < 3:
                                    g[nv, axis] = np.float32(np.float64(g[nv, axis]) + t)
                                keys[nv] = ((gi * ny + gj) * nz + gk) * 4 + axis
                                # Deduplicated within the run: only the tile's side faces are shared.
                                share[nv] = ((axis != 0 and (gi == i0 or gi == i1))
                                             or (axis != 1 and (gj == j0 or gj == j1)))
                                nv += 1
                            table[slot] = table[vslot]
                        tri[t3 % 3] = nv0 + table[slot]
                        if t3 % 3 == 2:
                            # scikit-image's winding ("descent" reverses Lewiner's order)
                            faces[nf, 0], faces[nf, 1], faces[nf, 2] = tri[2], tri[1], tri[0]
                            nf += 1
                if fail:
                    break
            if fail:
                break
        for q in range(nt):
            table[touched[q]] = -1
        nt = 0
        if fail:
            nv, nf = nv0, nf0
            declined[nd] = r
            nd += 1
    return g[:nv], keys[:nv], share[:nv], faces[:nf], declined[:nd]


def _plain_run(vol, origin, box, ny, nz, delta, *luts):
    """:func:`_plain_runs` on one ``(sx, sy, sz)`` array: ``(ok, g, keys, share, faces)``."""
    vol = np.ascontiguousarray(vol, dtype=np.float32)
    sx, sy, sz = vol.shape
    run = np.array([[0, sy * sz, sz, sx, sy, sz, *origin, *box]], dtype=np.int64)
    g, keys, share, faces, declined = _plain_runs(vol.reshape(-1), run, ny, nz, delta, *luts)
    return len(declined) == 0, g, keys, share, faces


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
        tile order, then increasing ``ok`` (see :func:`_plain_runs`).
    shape, lo, voxel
        The grid.
    normals : bool
        Field normals and one orientation (``oriented_mesh``); else none and
        scikit-image's winding.
    """
    ny, nz = int(shape[1]), int(shape[2])
    T = _tables()
    luts = (T["cases"], T["til"], T["ntri"], T["corner"], T["edge_lo"], T["edge_axis"])
    g, keys, share, f, declined = _plain_runs(flat, runs, ny, nz, DELTA, *luts)
    verts, faces, keyl, shares, nv = [g], [f], [keys], [share], len(g)
    # The runs with face or interior tests, through scikit-image (after the plain
    # ones: the same order for the banded and the dense mesh).
    for r in declined.tolist():
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
    if nv == 0:
        raise ValueError("the field has no surface inside its bounds at this voxel size")
    g, f, keys = np.concatenate(verts), np.concatenate(faces), np.concatenate(keyl)
    cand = np.flatnonzero(np.concatenate(shares))
    # (stable sort: the first in order leads)
    v, f = _stitch(g, f, keys, cand[np.argsort(keys[cand], kind="stable")], float(voxel), np.asarray(lo, np.float64))
    if not normals:
        return TriangleMesh(v, f, np.zeros((0, 3), dtype=np.float32))
    return oriented_mesh(node, v, f, voxel)
