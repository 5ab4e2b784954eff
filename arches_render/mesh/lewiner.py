"""Lewiner's marching cubes, compiled for most of its cases: scikit-image's tables and traversal.

One kernel, :func:`plain_runs`, serves two callers that need different vertices:

* the terrain's tiled banded meshes (``exact=False``): vertices at
  ``float32(k + v0 / (v0 - v1))`` on the *global* grid, snapped to grid points
  within ``delta / 2``, keyed by edge for stitching (``generators.terrain.tiled_mc``);
* single volumes that must give scikit-image's ``marching_cubes`` bit for bit
  (``exact=True``, the rock meshes): scikit-image's vertex positions (its
  "centre of mass" of the edge's two corners, weights ``1 / (eps + |v|)``), its
  vertex normals (the corner gradients it accumulates at every use of a vertex,
  normalised in double), its vertex and face order and winding, at any
  ``level`` and ``step_size``.

Both walk the cubes as scikit-image does (array axis 0 outermost, axis 2
innermost), number vertices on first use and wind faces as its default
``gradient_direction='descent'``. Lewiner's plain cases (fixed tilings) are
compiled for both; ``exact`` runs also resolve cases 3, 4 and 6 by scikit-image's
face and interior tests (:mod:`.lewiner_ambiguous`; all but tiling 6.1.2, which needs
the cube's centre vertex). A run holding a cube of another case (terrain: 3, 4, 6, 7, 10, 12, 13;
``exact``: 7, 10, 12, 13, 6.1.2) is rolled back and *declined*: the caller hands
it to scikit-image itself. ``exact`` runs are also declined when a face is
degenerate (two corners at one position), which scikit-image's
``allow_degenerate=False`` would remove with its vertex merging. Of 785 n = 5
rock fields that leaves none to scikit-image at step 1, 21 at step 2, 33 at 3.

References
----------
Lewiner, T. et al. (2003). Efficient implementation of marching cubes' cases with
topological guarantees. Journal of Graphics Tools 8(2).
scikit-image 0.26, ``skimage/measure/_marching_cubes_lewiner_cy.pyx`` (``Cell``).
"""

from __future__ import annotations

import numba
import numpy as np
from skimage.measure import _marching_cubes_lewiner as _lewiner
from skimage.measure import _marching_cubes_lewiner_luts as _luts

from .lewiner_ambiguous import BIT_TO_V as _BIT_TO_V
from .lewiner_ambiguous import EPS as _EPS
from .lewiner_ambiguous import ambiguous_tiling as _ambiguous_tiling

__all__ = ["PLAIN", "lewiner_tables", "lewiner_luts", "plain_runs", "plain_runs_chunked", "plain_volume"]

#: Lewiner's cases whose tiling is a fixed table (no face or interior test).
PLAIN = (1, 2, 5, 8, 9, 11, 14)
#: The tilings of the ambiguous cases that ``exact`` runs resolve (3, 4 and 6), by number
#: (6.1.2, number 5, is declined: it needs the cube's centre vertex).
_AMBIGUOUS = ("TILING3_1", "TILING3_2", "TILING4_1", "TILING4_2", "TILING6_1_1", "TILING6_1_2", "TILING6_2")
_TABLES = {}


def lewiner_tables() -> dict:
    """scikit-image's Lewiner tables for the compiled cases, as arrays for numba.

    Returns
    -------
    dict
        ``cases (256, 2)``; ``til (15, 48, 12)`` edge lists and ``ntri (15,)``
        (0: not plain); ``corner (8, 3)`` offsets of scikit-image's cell corners
        ``v0 .. v7``; ``edge_lo (12, 3)`` lower ends and ``edge_axis (12,)`` axes of
        the edges; ``ends (12, 2, 3)`` the edges' two ends in scikit-image's order;
        ``amb_til (7, 48, 27)`` and ``amb_n (7,)`` the tilings 3.1, 3.2, 4.1, 4.2, 6.1.1,
        6.1.2, 6.2 and their triangle counts, ``amb_test (3, 48, 3)`` the tests of cases
        3, 4 and 6 (``exact`` runs resolve them as scikit-image does);
        ``pair (16, 16)`` a cube's index from its lower and upper faces' sign codes.
        All in array axes ``(i, j, k)`` (Lewiner's ``x, y, z`` are axes 2, 1, 0).
    """
    if not _TABLES:
        til = np.zeros((15, 48, 12), dtype=np.int64)
        ntri = np.zeros(15, dtype=np.int64)
        for c in PLAIN:
            a = _lewiner._to_array(getattr(_luts, f"TILING{c}"))
            til[c, :a.shape[0], :a.shape[1]] = a
            ntri[c] = a.shape[1] // 3
        xyz = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
        corner = np.array([(z, y, x) for x, y, z in xyz], dtype=np.int64)
        ex, ey, ez = _lewiner.EDGETORELATIVEPOSX, _lewiner.EDGETORELATIVEPOSY, _lewiner.EDGETORELATIVEPOSZ
        ends = np.stack([ez, ey, ex], axis=-1).astype(np.int64)  # (12 edges, 2 ends, (i, j, k))
        edge_lo = ends.min(axis=1)
        edge_axis = np.argmax(ends[:, 1] != ends[:, 0], axis=1).astype(np.int64)
        # Cases 3, 4, 6 (``exact`` runs): the tests pick one of these tilings.
        amb_til = np.zeros((len(_AMBIGUOUS), 48, 27), dtype=np.int64)
        amb_n = np.zeros(len(_AMBIGUOUS), dtype=np.int64)
        for t, name in enumerate(_AMBIGUOUS):
            a = _lewiner._to_array(getattr(_luts, name))
            amb_til[t, :a.shape[0], :a.shape[1]] = a
            amb_n[t] = a.shape[1] // 3
        amb_test = np.zeros((3, 48, 3), dtype=np.int64)
        amb_test[0, :24, 0] = _lewiner._to_array(_luts.TEST3)
        amb_test[1, :8, 0] = _lewiner._to_array(_luts.TEST4)
        amb_test[2] = _lewiner._to_array(_luts.TEST6)
        # Cube index from the sign codes of its two horizontal faces: a face's code at
        # level k has bit 2 di + dj for corner (di, dj); ``pair[lo, hi]`` is Lewiner's index.
        pair = np.zeros((16, 16), dtype=np.int64)
        for lo in range(16):
            for hi in range(16):
                for c in range(8):
                    q = hi if corner[c, 2] else lo
                    if (q >> (2 * corner[c, 0] + corner[c, 1])) & 1:
                        pair[lo, hi] |= 1 << c
        _TABLES.update(pair=pair, cases=_lewiner._to_array(_luts.CASES).astype(np.int64), til=til, ntri=ntri,
                       corner=corner, edge_lo=edge_lo, edge_axis=edge_axis, ends=ends, amb_til=amb_til,
                       amb_n=amb_n, amb_test=amb_test)
    return _TABLES


def lewiner_luts() -> tuple:
    """:func:`lewiner_tables` in :func:`plain_runs`'s argument order."""
    T = lewiner_tables()
    return (T["cases"], T["til"], T["ntri"], T["corner"], T["edge_lo"], T["edge_axis"], T["ends"], T["amb_til"],
            T["amb_n"], T["amb_test"], T["pair"])


@numba.njit(cache=True, nogil=True)
def _grow(a, n):
    """``a`` with room for at least ``n`` rows (doubling)."""
    if n <= a.shape[0]:
        return a
    shape = (max(n, 2 * a.shape[0]),) + a.shape[1:]
    b = np.empty(shape, dtype=a.dtype)
    b[:a.shape[0]] = a
    return b


@numba.njit(cache=True, nogil=True)
def _corner_gradients(vc, vg):
    """scikit-image's per-corner gradients (``Cell.prepare_for_adding_triangles``) of the
    cube values ``vc`` (corners ``v0 .. v7``, level subtracted) into ``vg (8, 3)``, ``x, y, z``.

    scikit-image reads them back by the corner's *bit* index ``4 dz + 2 dy + dx``, not
    by its ``v`` number: corners 2/3 and 6/7 swap. :func:`plain_runs` does the same.
    """
    v0, v1, v2, v3, v4, v5, v6, v7 = vc[0], vc[1], vc[2], vc[3], vc[4], vc[5], vc[6], vc[7]
    vg[0, 0], vg[0, 1], vg[0, 2] = v0 - v1, v0 - v3, v0 - v4
    vg[1, 0], vg[1, 1], vg[1, 2] = v0 - v1, v1 - v2, v1 - v5
    vg[2, 0], vg[2, 1], vg[2, 2] = v3 - v2, v1 - v2, v2 - v6
    vg[3, 0], vg[3, 1], vg[3, 2] = v3 - v2, v0 - v3, v3 - v7
    vg[4, 0], vg[4, 1], vg[4, 2] = v4 - v5, v4 - v7, v0 - v4
    vg[5, 0], vg[5, 1], vg[5, 2] = v4 - v5, v5 - v6, v1 - v5
    vg[6, 0], vg[6, 1], vg[6, 2] = v7 - v6, v5 - v6, v2 - v6
    vg[7, 0], vg[7, 1], vg[7, 2] = v7 - v6, v4 - v7, v3 - v7


@numba.njit(cache=True, nogil=True)
def _column_spans(flat, base, si, sj, sx, sy, sz, level, span):
    """Per column ``(i, j)`` of a run (row ``i sy + j``): the first and last ``k``
    inside (``> level``) and the first and last outside; ``sz`` and -1 when none.
    A column of one sign is read once; one of both, from each end to its last change."""
    for i in range(sx):
        for j in range(sy):
            b = base + i * si + j * sj
            c = i * sy + j
            bottom = flat[b] > level
            change = sz
            for k in range(1, sz):
                if (flat[b + k] > level) != bottom:
                    change = k
                    break
            if change == sz:  # one sign: first 0, last sz - 1; none of the other
                if bottom:
                    span[c, 0], span[c, 1], span[c, 2], span[c, 3] = 0, sz - 1, sz, -1
                else:
                    span[c, 0], span[c, 1], span[c, 2], span[c, 3] = sz, -1, 0, sz - 1
                continue
            top = flat[b + sz - 1] > level
            last = 0
            for k in range(sz - 2, -1, -1):
                if (flat[b + k] > level) != top:
                    last = k
                    break
            # The first of the bottom's sign is 0, of the other ``change``; the last of
            # the top's sign is sz - 1, of the other ``last``.
            if bottom:
                span[c, 0], span[c, 2] = 0, change
            else:
                span[c, 0], span[c, 2] = change, 0
            if top:
                span[c, 1], span[c, 3] = sz - 1, last
            else:
                span[c, 1], span[c, 3] = last, sz - 1


def plain_runs(flat, runs, ny, nz, delta, level, step, exact, *tables):
    """Lewiner's marching cubes on every run whose crossing cubes are all of cases it compiles.

    Parameters
    ----------
    flat : (N,) float32
        The values the runs index.
    runs : (R, 13) int64
        ``(base, si, sj, sx, sy, sz, oi, oj, ok, i0, i1, j0, j1)``: the run's value at
        ``(i, j, k)`` is ``flat[base + i si + j sj + k]``, its grid origin is
        ``(oi, oj, ok)``, its tile ``(i0, i1, j0, j1)`` (``exact=False`` only).
    ny, nz : int
        The global grid's sizes along axes 1 and 2 (edge keys; ``exact=False``).
    delta : float
        Grid-point snapping distance (``exact=False``).
    level : float
        The iso level: a corner is inside where ``value - level > 0`` (in double).
    step : int
        Voxels a sample stands for (``exact=True`` positions: scikit-image's
        ``step_size`` on the volume sampled every ``step`` voxels).
    exact : bool
        scikit-image's vertex positions and normals (see module docstring) instead
        of the terrain's keyed positions.
    cases, til, ntri, corner, edge_lo, edge_axis, ends, amb_til, amb_n, amb_test, pair
        :func:`lewiner_tables`.

    Returns
    -------
    (g, keys, share, faces, normals, declined)
        float32 ``(P, 3)`` vertices (grid units; ``exact``: voxels from the run's
        origin), int64 edge keys and bool shareability (``exact=False``: see
        ``tiled_mc._run_keys``; else -1 and false), int32 ``(F, 3)`` faces,
        float32 ``(P, 3)`` unit normals (``exact``; else ``(0, 3)``), and the
        indices of the runs rolled back for scikit-image.
    """
    kernel = _plain_runs_exact if exact else _plain_runs_keyed
    return kernel(flat, runs, ny, nz, delta, level, step, *tables)


# The kernel's body, inlined into one compiled kernel per mode with ``exact`` a constant:
# the other mode's branches are then removed (the keyed mode, the terrain's, ran 12 %
# faster than the one kernel taking ``exact`` at run time: its loop kept both modes' code).
# (error_model numpy: no ZeroDivisionError check; a crossing edge has v0 > 0 >= v1 or the reverse.)
@numba.njit(error_model="numpy", nogil=True, inline="always")
def _plain_runs_body(flat, runs, ny, nz, delta, level, step, exact, cases, til, ntri, corner, edge_lo, edge_axis,
                     ends, amb_til, amb_n, amb_test, pair):
    vmax, cmax, columns = 0, 0, 0
    for r in range(runs.shape[0]):
        vmax = max(vmax, runs[r, 3] * runs[r, 4] * runs[r, 5])
        cmax = max(cmax, runs[r, 3] * runs[r, 4])
        columns += (runs[r, 3] - 1) * (runs[r, 4] - 1)
    span = np.empty((cmax, 4), dtype=np.int64)
    table = np.full(vmax * 4, -1, dtype=np.int32)
    # Room for 1.5 vertices and 3 faces a column of cubes (a terrain's runs make about 1.2
    # and 2.3): growing by doubling from a small guess copied and faulted in twice the
    # output (0.28 s of the 3 km coast's 1.85 s, serial). Pages never written cost no memory.
    # (The output does not depend on it.)
    cap = max(256, (3 * columns) // 2)
    g = np.empty((cap, 3), dtype=np.float32)
    keys = np.empty(cap, dtype=np.int64)
    share = np.empty(cap, dtype=np.bool_)
    acc = np.empty((cap if exact else 0, 3), dtype=np.float32)   # scikit-image's x, y, z order
    faces = np.empty((2 * cap, 3), dtype=np.int32)
    declined = np.empty(runs.shape[0], dtype=np.int64)
    touched = np.empty(max(256, 24 * cmax), dtype=np.int64)  # (a run's slots: reset after each)
    nv, nf, nd, nt = 0, 0, 0, 0
    p = np.empty(3, dtype=np.int64)
    tri = np.empty(3, dtype=np.int64)
    vc = np.empty(8, dtype=np.float64)
    vg = np.empty((8, 3), dtype=np.float64)
    w = np.empty(8, dtype=np.float64)   # corner weights by bit index, and as float32
    w32 = np.empty(8, dtype=np.float64)
    cb = np.empty(3, dtype=np.float64)
    eoff = np.empty(12, dtype=np.int64)
    stp = np.float64(step)
    for r in range(runs.shape[0]):
        base, si, sj, sx, sy, sz = runs[r, 0], runs[r, 1], runs[r, 2], runs[r, 3], runs[r, 4], runs[r, 5]
        oi, oj, ok, i0, i1, j0, j1 = runs[r, 6], runs[r, 7], runs[r, 8], runs[r, 9], runs[r, 10], runs[r, 11], runs[r, 12]
        nv0, nf0 = nv, nf
        fail = False
        # An edge's slot is the slot of its cube's lower corner plus the edge's offset.
        for e in range(12):
            eoff[e] = ((edge_lo[e, 0] * sy + edge_lo[e, 1]) * sz + edge_lo[e, 2]) * 4 + edge_axis[e]
        _column_spans(flat, base, si, sj, sx, sy, sz, level, span)
        for i in range(sx - 1):
            for j in range(sy - 1):
                # Only the layers where the four columns hold both an inside and an outside
                # corner can cross; the others emit nothing (a shortcut, same output).
                c00, c01 = i * sy + j, i * sy + j + 1
                c10, c11 = c00 + sy, c01 + sy
                k0 = max(min(span[c00, 0], span[c01, 0], span[c10, 0], span[c11, 0]),
                         min(span[c00, 2], span[c01, 2], span[c10, 2], span[c11, 2])) - 1
                k1 = min(max(span[c00, 1], span[c01, 1], span[c10, 1], span[c11, 1]),
                         max(span[c00, 3], span[c01, 3], span[c10, 3], span[c11, 3]), sz - 2)
                k0 = max(k0, 0)
                if k0 > k1:
                    continue
                b00 = base + i * si + j * sj
                b01, b10 = b00 + sj, b00 + si
                b11 = b10 + sj
                # (v - level > 0 in double is v > level: an IEEE difference is 0 only for equal values)
                nxt = ((flat[b00 + k0] > level) | ((flat[b01 + k0] > level) << 1) | ((flat[b10 + k0] > level) << 2)
                       | ((flat[b11 + k0] > level) << 3))
                # Room for this column of cubes (at most 12 vertices, 4 faces a cube).
                if nv + 12 * sz > g.shape[0]:
                    g = _grow(g, nv + 12 * sz)
                    keys = _grow(keys, nv + 12 * sz)
                    share = _grow(share, nv + 12 * sz)
                    if exact:
                        acc = _grow(acc, nv + 12 * sz)
                if nf + 4 * sz > faces.shape[0]:
                    faces = _grow(faces, nf + 4 * sz)
                if nt + 24 * sz > touched.shape[0]:
                    touched = _grow(touched, nt + 24 * sz)
                column_slot = (i * sy + j) * sz * 4
                for k in range(k0, k1 + 1):
                    cur = nxt
                    nxt = ((flat[b00 + k + 1] > level) | ((flat[b01 + k + 1] > level) << 1)
                           | ((flat[b10 + k + 1] > level) << 2) | ((flat[b11 + k + 1] > level) << 3))
                    idx = pair[cur, nxt]
                    if idx == 0 or idx == 255:
                        continue
                    case = cases[idx, 0]
                    if case == 0:
                        continue
                    if ntri[case] == 0 and not (exact and (case == 3 or case == 4 or case == 6)):
                        fail = True
                        break
                    cfg = cases[idx, 1]
                    # (the tables indexed in place: a row view per cube cost more than its use)
                    tv, n3 = -1, 3 * ntri[case]
                    if exact:
                        for c in range(8):
                            q = b00 + corner[c, 0] * si + corner[c, 1] * sj + k + corner[c, 2]
                            vc[c] = np.float64(flat[q]) - level
                        _corner_gradients(vc, vg)
                        # scikit-image's weights 1 / (eps + |v|) of the corners, by bit index
                        # (its ``vv``), and the float32 it passes them as to add_gradient.
                        for b in range(8):
                            w[b] = 1.0 / (_EPS + abs(vc[_BIT_TO_V[b]]))
                            w32[b] = np.float64(np.float32(w[b]))
                        cb[0], cb[1], cb[2] = np.float64(i * step), np.float64(j * step), np.float64(k * step)
                        if case == 3 or case == 4 or case == 6:
                            tv = _ambiguous_tiling(vc, case, cfg, amb_test)
                            if tv < 0:
                                fail = True
                                break
                            n3 = 3 * amb_n[tv]
                    cube_slot = column_slot + k * 4
                    for t3 in range(n3):
                        e = til[case, cfg, t3] if tv < 0 else amb_til[tv, cfg, t3]
                        # An edge's slot holds its vertex (or the grid point's it snapped to).
                        slot = cube_slot + eoff[e]
                        if exact:
                            # scikit-image's Cell._add_face_from_edge_index: the corners' weights
                            # 1 / (eps + |v|), in the edge's table order (its sums' order).
                            c1 = ends[e, 0, 0] * 4 + ends[e, 0, 1] * 2 + ends[e, 0, 2]  # bit 4 dz + 2 dy + dx
                            c2 = ends[e, 1, 0] * 4 + ends[e, 1, 1] * 2 + ends[e, 1, 2]
                            w1, w2 = w[c1], w[c2]
                            if table[slot] < 0:
                                table[slot] = nv - nv0
                                touched[nt] = slot
                                nt += 1
                                ff = 0.0
                                ff += w1
                                ff += w2
                                for ax in range(3):
                                    fa = 0.0
                                    fa += ends[e, 0, ax] * w1
                                    fa += ends[e, 1, ax] * w2
                                    g[nv, ax] = np.float32(cb[ax] + stp * fa / ff)
                                acc[nv, 0], acc[nv, 1], acc[nv, 2] = 0.0, 0.0, 0.0
                                keys[nv] = -1
                                share[nv] = False
                                nv += 1
                            q = nv0 + table[slot]
                            s1, s2 = w32[c1], w32[c2]
                            for ax in range(3):
                                acc[q, ax] += np.float32(vg[c1, ax] * s1)
                            for ax in range(3):
                                acc[q, ax] += np.float32(vg[c2, ax] * s2)
                        elif table[slot] < 0:
                            a = edge_axis[e]
                            p[0], p[1], p[2] = i + edge_lo[e, 0], j + edge_lo[e, 1], k + edge_lo[e, 2]
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
                            if exact and (_same(g, tri[0], tri[1]) or _same(g, tri[1], tri[2])
                                          or _same(g, tri[0], tri[2])):
                                fail = True  # degenerate: scikit-image merges vertices
                            # scikit-image's winding ("descent" reverses Lewiner's order)
                            faces[nf, 0], faces[nf, 1], faces[nf, 2] = tri[2], tri[1], tri[0]
                            nf += 1
                    if fail:
                        break
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
    normals = np.empty((nv if exact else 0, 3), dtype=np.float32)
    for q in range(normals.shape[0]):
        # Cell.get_normals: |n|^2 summed in double in x, y, z order, then 1 / length ** 0.5.
        length = 0.0
        for ax in range(3):
            d = np.float64(acc[q, ax])
            length += d * d
        if length > 0.0:
            length = 1.0 / length ** 0.5
        for ax in range(3):  # (x, y, z) -> array axes (i, j, k), as its np.fliplr
            normals[q, 2 - ax] = np.float32(np.float64(acc[q, ax]) * length)
    return g[:nv], keys[:nv], share[:nv], faces[:nf], normals, declined[:nd]


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _plain_runs_keyed(flat, runs, ny, nz, delta, level, step, cases, til, ntri, corner, edge_lo, edge_axis, ends,
                      amb_til, amb_n, amb_test, pair):
    return _plain_runs_body(flat, runs, ny, nz, delta, level, step, False, cases, til, ntri, corner, edge_lo,
                            edge_axis, ends, amb_til, amb_n, amb_test, pair)


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _plain_runs_exact(flat, runs, ny, nz, delta, level, step, cases, til, ntri, corner, edge_lo, edge_axis, ends,
                      amb_til, amb_n, amb_test, pair):
    return _plain_runs_body(flat, runs, ny, nz, delta, level, step, True, cases, til, ntri, corner, edge_lo,
                            edge_axis, ends, amb_til, amb_n, amb_test, pair)


def plain_runs_chunked(flat, runs, *args, workers=None, min_cubes=1 << 20):
    """:func:`plain_runs` on contiguous chunks of ``runs``, in threads.

    A run's vertices and faces depend on its own values only, and the kernel
    appends them in run order (vertex numbers offset by those before it), so the
    chunks' outputs, concatenated with their faces offset by the vertices of the
    chunks before and their declined runs by the chunk's first run, are the single
    call's arrays bit for bit. The kernel releases the GIL (``nogil``); chunks are
    cut at equal shares of the runs' cubes. The caller concatenates (once: the
    arrays are large).

    Parameters
    ----------
    flat, runs, *args
        As :func:`plain_runs`.
    workers : int, optional
        Threads (default: numba's, ``numba.get_num_threads()``, as its parallel
        kernels: 1 in a process that asked numba for one thread).
    min_cubes : int
        Below this many cubes in all, one call (threads would cost more than they save).

    Returns
    -------
    list of (int, tuple)
        ``(first run, plain_runs output)`` per chunk, in run order.
    """
    from concurrent.futures import ThreadPoolExecutor
    workers = int(workers or numba.get_num_threads())
    work = np.cumsum(runs[:, 3] * runs[:, 4] * runs[:, 5])
    if workers <= 1 or len(runs) < 16 * workers or work[-1] < min_cubes:
        return [(0, plain_runs(flat, runs, *args))]
    # Eight chunks a thread: a chunk of slow runs (ambiguous cubes, tall cliffs) then
    # delays the end by an eighth of a thread's share, not by all of it (four a thread:
    # 0.87 s against 0.81 s on the 3 km coast, 2 threads).
    chunks = 8 * workers
    cuts = np.searchsorted(work, work[-1] * np.arange(1, chunks) / chunks)
    bounds = [0, *sorted(set(int(c) for c in cuts if 0 < c < len(runs))), len(runs)]
    with ThreadPoolExecutor(workers) as pool:
        parts = pool.map(lambda c: plain_runs(flat, runs[c[0]:c[1]], *args), zip(bounds[:-1], bounds[1:]))
        return list(zip(bounds[:-1], parts))


@numba.njit(cache=True, nogil=True, inline="always")
def _same(g, a, b):
    return g[a, 0] == g[b, 0] and g[a, 1] == g[b, 1] and g[a, 2] == g[b, 2]


def plain_volume(vol, level=0.0, step=1, exact=True, origin=(0, 0, 0), box=(0, 0, 0, 0), ny=None, nz=None,
                 delta=0.0):
    """:func:`plain_runs` on one ``(sx, sy, sz)`` array (one run).

    Parameters
    ----------
    vol : (sx, sy, sz) array
        The samples (converted to contiguous float32).
    level, step, exact, delta
        As :func:`plain_runs`.
    origin, box, ny, nz
        The run's grid origin and tile and the grid's sizes (``exact=False``;
        ``ny, nz`` default to the array's).

    Returns
    -------
    (ok, g, keys, share, faces, normals)
        ``ok`` false when the volume was declined (then the arrays are empty).
    """
    vol = np.ascontiguousarray(vol, dtype=np.float32)
    sx, sy, sz = vol.shape
    run = np.array([[0, sy * sz, sz, sx, sy, sz, *origin, *box]], dtype=np.int64)
    g, keys, share, faces, normals, declined = plain_runs(
        vol.reshape(-1), run, int(ny or sy), int(nz or sz), float(delta), float(level), int(step), bool(exact),
        *lewiner_luts())
    return len(declined) == 0, g, keys, share, faces, normals
