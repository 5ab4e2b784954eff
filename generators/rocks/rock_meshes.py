"""Rock meshes from the eroded voxel volumes (Peytavie et al. 2009, section 5, "Mesh generation").

The paper defines each rock's field at the voxel centres as ``r = 2 rho - 1``
(``rho = 0`` outside the rock), interpolates it trilinearly and polygonizes
``r = 0`` with marching cubes. We do the same on ``rho`` at level ``1/2``
(Lewiner's marching cubes: scikit-image's, bit for bit, compiled in
:mod:`arches_render.mesh.lewiner` but for a few ambiguous cases), after a small Gaussian low-pass of
``rho`` (``sigma`` voxels, 0 disables it). The paper's field is binary on the
uneroded contact faces, where marching cubes leaves voxel staircases; the
low-pass removes them. It keeps rocks apart: the filter is linear and
positive, so ``sum_k rho_k <= 1`` at every voxel still holds after it, and two
rocks' interpolated fields can never both exceed ``1/2`` at one point.

Cleaning: the volume is padded with empty voxels so the surface is closed;
only the largest connected component is kept (erosion can cut off crumbs);
the result is checked to be a closed, consistently oriented (edge-manifold)
triangle mesh with outward normals, and rejected otherwise. The checks are
numpy versions of trimesh's ``is_watertight``/``is_winding_consistent`` (the
tests cross-check them with trimesh): per-rock ``trimesh.Trimesh`` objects
cost more than the whole tile budget for tens of thousands of rocks.
"""

from __future__ import annotations

import functools

import numba
import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from arches_render.mesh.lewiner import plain_volume

__all__ = ["mesh_rock", "rock_field", "field_padding", "blur_weights", "blur_field", "closed_oriented", "mesh_volume",
           "keep_largest_component", "anchor_voxels", "bounding_radius"]


@numba.njit(cache=True, nogil=True)
def _closed_oriented(f):
    n = f.shape[0]
    if n < 4 or (3 * n) % 2:
        return False
    # Directed edges a -> b listed by tail (out) and by head (in), two counting sorts.
    # The mesh is closed and oriented iff no edge is degenerate or repeated and every
    # edge's reverse exists, i.e. every vertex's out-neighbours are distinct and among
    # its in-neighbours (the totals being equal, the two sets are then equal). One
    # stamp per vertex checks both in O(1) an edge: pairwise scans of the short
    # lists cost 2.3 times as much (branches that do not predict).
    nv = f.max() + 1
    out_s = np.zeros(nv + 1, dtype=np.int64)
    in_s = np.zeros(nv + 1, dtype=np.int64)
    for i in range(n):
        for e in range(3):
            a, b = f[i, e], f[i, (e + 1) % 3]
            if a == b:
                return False
            out_s[a + 1] += 1
            in_s[b + 1] += 1
    for v in range(nv):
        out_s[v + 1] += out_s[v]
        in_s[v + 1] += in_s[v]
    outs = np.empty(3 * n, dtype=np.int64)
    ins = np.empty(3 * n, dtype=np.int64)
    fo = out_s[:nv].copy()
    fi = in_s[:nv].copy()
    for i in range(n):
        for e in range(3):
            a, b = f[i, e], f[i, (e + 1) % 3]
            outs[fo[a]] = b
            fo[a] += 1
            ins[fi[b]] = a
            fi[b] += 1
    mark = np.full(nv, -1, dtype=np.int64)
    for a in range(nv):
        for p in range(in_s[a], in_s[a + 1]):
            mark[ins[p]] = a
        for p in range(out_s[a], out_s[a + 1]):
            b = outs[p]
            if mark[b] != a:  # no reverse edge, or a repeated one (its stamp is used)
                return False
            mark[b] = -1
    return True


def closed_oriented(faces: np.ndarray) -> bool:
    """True if every edge is shared by exactly two faces that traverse it in opposite directions.

    That is a closed, consistently oriented, edge-manifold triangle mesh
    (trimesh's ``is_watertight and is_winding_consistent``). One compiled pass:
    called once per rock, numpy's dozen small operations cost more than the sort.
    """
    return bool(_closed_oriented(np.ascontiguousarray(faces, dtype=np.int64)))


@numba.njit(cache=True, nogil=True)
def _anchor_voxels(field, count):
    inside = 0
    for v in field.ravel():
        if v > 0.5:
            inside += 1
    # numpy.linspace(0, inside - 1, count).round(): i * step, the last one exactly inside - 1.
    top = inside - 1
    want = np.empty(count, dtype=np.int64)
    step = top / (count - 1) if count > 1 else 0.0
    for i in range(count):
        want[i] = int(np.rint(i * step if step != 0.0 else 0.0))
    if count > 1:
        want[count - 1] = top
    out = np.empty((count, 3), dtype=np.int64)
    nx, ny, nz = field.shape
    c, w = 0, 0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if field[i, j, k] > 0.5:
                    while w < count and want[w] == c:
                        out[w, 0], out[w, 1], out[w, 2] = i, j, k
                        w += 1
                    c += 1
    return out


def anchor_voxels(field: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` voxels of a rock, evenly picked from those with ``field > 0.5``.

    The picks are ``numpy.linspace(0, m - 1, count).round()`` of the ``m``
    inside voxels in C order (repeats when ``m < count``); the field must hold
    at least one inside voxel. Rocks are instanced by these anchors (section 6).

    Returns
    -------
    (count, 3) int64
    """
    return _anchor_voxels(np.ascontiguousarray(field), int(count))


@numba.njit(cache=True, nogil=True)
def _signed_volume(v, f):
    # In float64 whatever the vertices' type (float32 from marching cubes).
    s = 0.0
    for i in range(f.shape[0]):
        a0, a1, a2 = np.float64(v[f[i, 0], 0]), np.float64(v[f[i, 0], 1]), np.float64(v[f[i, 0], 2])
        b0, b1, b2 = np.float64(v[f[i, 1], 0]), np.float64(v[f[i, 1], 1]), np.float64(v[f[i, 1], 2])
        c0, c1, c2 = np.float64(v[f[i, 2], 0]), np.float64(v[f[i, 2], 1]), np.float64(v[f[i, 2], 2])
        s += a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)
    return s / 6.0


@numba.njit(cache=True, nogil=True)
def _nudged_max(field):
    """The field's maximum before values exactly at the level 1/2 are moved off it (in place)."""
    top = -np.inf
    for p in range(field.size):
        v = field.flat[p]
        top = max(top, v)
        if v == 0.5:
            field.flat[p] = np.float32(0.5 + 1e-6)
    return top


@numba.njit(cache=True, nogil=True)
def _outward_cells(verts, faces, normals, origin, V):
    """Closed-mesh check, outward winding, cell coordinates and unit normals of a marching-cubes mesh.

    Returns ``(ok, x, f, n)``: ``ok`` false when the mesh is not closed and
    oriented or has no volume; ``x`` float32 ``(verts + origin + 0.5) / V``
    (formed in float64); ``f`` int32 faces, reversed if the volume is negative;
    ``n`` the float32 normals over ``max(|n|, 1e-12)``, ``|n|`` summed in
    float32 in axis order as numpy's ``linalg.norm(axis=1)`` does (same bits).
    """
    x = np.empty((verts.shape[0], 3), dtype=np.float32)
    f = np.empty((faces.shape[0], 3), dtype=np.int32)
    nrm = np.empty((normals.shape[0], 3), dtype=np.float32)
    if not _closed_oriented(faces):
        return False, x, f, nrm
    vol = _signed_volume(verts, faces)
    if vol == 0.0:
        return False, x, f, nrm
    for i in range(faces.shape[0]):
        for e in range(3):
            f[i, e] = faces[i, 2 - e] if vol < 0 else faces[i, e]
    for i in range(verts.shape[0]):
        for a in range(3):
            x[i, a] = np.float32((np.float64(verts[i, a]) + (origin[a] + 0.5)) / V)
    for i in range(normals.shape[0]):
        n0, n1, n2 = np.float32(normals[i, 0]), np.float32(normals[i, 1]), np.float32(normals[i, 2])
        length = max(np.sqrt(n0 * n0 + n1 * n1 + n2 * n2), np.float32(1e-12))
        nrm[i, 0], nrm[i, 1], nrm[i, 2] = n0 / length, n1 / length, n2 / length
    return True, x, f, nrm


@numba.njit(cache=True, nogil=True)
def _bounding_radius(v, c):
    top = 0.0
    for i in range(v.shape[0]):
        d0 = np.float64(v[i, 0]) - c[0]
        d1 = np.float64(v[i, 1]) - c[1]
        d2 = np.float64(v[i, 2]) - c[2]
        top = max(top, d0 * d0 + d1 * d1 + d2 * d2)
    return np.sqrt(top)


def bounding_radius(vertices: np.ndarray, centre) -> float:
    """Radius of the sphere about ``centre`` that holds every vertex (in float64).

    The same bits as ``sqrt(((vertices - centre) ** 2).sum(axis=1).max())``, in
    one compiled pass rather than four array operations per rock.
    """
    return float(_bounding_radius(np.ascontiguousarray(vertices), np.asarray(centre, dtype=np.float64)))


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume of a closed triangle mesh (positive for outward winding)."""
    return float(_signed_volume(np.ascontiguousarray(vertices, dtype=np.float64),
                                np.ascontiguousarray(faces, dtype=np.int64)))


def keep_largest_component(vertices, faces, normals=None):
    """The connected component (by shared vertices) with the most faces, reindexed."""
    nv = len(vertices)
    f = np.asarray(faces, dtype=np.int64)
    rows = np.concatenate([f[:, 0], f[:, 1]])
    cols = np.concatenate([f[:, 1], f[:, 2]])
    g = sparse.coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(nv, nv))
    count, comp = csgraph.connected_components(g, directed=False)
    if count > 1:
        fc = comp[f[:, 0]]
        best = np.argmax(np.bincount(fc, minlength=count))
        f = f[fc == best]
    used = np.nonzero(np.bincount(f.ravel(), minlength=nv))[0]
    remap = np.full(nv, -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    out_n = None if normals is None else normals[used]
    return vertices[used], remap[f], out_n


@numba.njit(cache=True, nogil=True)
def _blur_axis(src, w, axis):
    """One axis of the truncated Gaussian (zero outside the array), float32 throughout.

    Every output voxel sums ``w[a - i + r] * src[i]`` over its window in
    increasing ``i``: the order in which a scatter from the sources would add
    them (an empty source adds +0, which changes nothing), written as a gather
    whose inner loop runs along the contiguous axis.
    """
    out = np.zeros_like(src)
    r = (len(w) - 1) // 2
    nx, ny, nz = src.shape
    n = src.shape[axis]
    for a in range(n):
        for i in range(max(0, a - r), min(n, a + r + 1)):
            wt = w[a - i + r]
            if axis == 0:
                for j in range(ny):
                    for k in range(nz):
                        out[a, j, k] += wt * src[i, j, k]
            elif axis == 1:
                for x in range(nx):
                    for k in range(nz):
                        out[x, a, k] += wt * src[x, i, k]
            else:
                for x in range(nx):
                    for y in range(ny):
                        out[x, y, a] += wt * src[x, y, i]
    return out


@numba.njit(cache=True, nogil=True)
def _rock_field(labels, rho, k, lo, hi, pad, w):
    f = np.zeros((hi[0] - lo[0] + 2 * pad, hi[1] - lo[1] + 2 * pad, hi[2] - lo[2] + 2 * pad),
                 dtype=np.float32)
    for i in range(lo[0], hi[0]):
        for j in range(lo[1], hi[1]):
            for m in range(lo[2], hi[2]):
                if labels[i, j, m] == k:
                    f[i - lo[0] + pad, j - lo[1] + pad, m - lo[2] + pad] = rho[i, j, m]
    if w.shape[0] > 1:
        for axis in range(3):
            f = _blur_axis(f, w, axis)
    return f


@functools.lru_cache(maxsize=8)
def _taps(sigma: float) -> np.ndarray:
    if sigma <= 0:
        w = np.ones(1, dtype=np.float32)
    else:
        r = max(1, int(2.0 * sigma + 0.5))
        x = np.arange(-r, r + 1, dtype=np.float64)
        w = np.exp(-0.5 * (x / sigma) ** 2)
        w = (w / w.sum()).astype(np.float32)
    w.setflags(write=False)       # shared by every caller of the cache
    return w


def blur_weights(sigma: float) -> np.ndarray:
    """Normalised Gaussian taps truncated at 2 sigma (one tap of 1 for ``sigma = 0``)."""
    return _taps(float(sigma)).copy()


def rock_field(labels, rho, k: int, lo, hi, sigma: float, pad: int) -> np.ndarray:
    """Rock ``k``'s ``rho`` on the voxel box ``[lo, hi)`` of a grid, padded, low-passed.

    The Gaussian (truncated at 2 sigma, zero outside) is separable and applied
    one axis at a time.
    """
    # The taps are computed once per sigma: this runs once per rock.
    return _rock_field(labels, rho, int(k), np.asarray(lo, np.int64), np.asarray(hi, np.int64),
                       int(pad), _taps(float(sigma)))


def blur_field(field: np.ndarray, sigma: float) -> np.ndarray:
    """The same Gaussian low-pass as :func:`rock_field` on an already extracted field."""
    f = np.asarray(field, dtype=np.float32)
    w = blur_weights(sigma)
    if len(w) > 1:
        for axis in range(3):
            f = _blur_axis(f, w, axis)
    return f


def field_padding(sigma: float, step: int) -> int:
    """Empty voxels around a rock's box: the blur's reach plus one marching-cubes step."""
    return len(blur_weights(sigma)) // 2 + step


def _marching_cubes(field: np.ndarray, step: int):
    """scikit-image's ``marching_cubes(field, 0.5, step_size=step, allow_degenerate=False)``,
    bit for bit, or ``None`` where its grid holds no surface ("No surface found").

    The compiled cases (:mod:`arches_render.mesh.lewiner`) give the same vertices,
    faces and normals; a rock with a cube they decline (ambiguous cases 7, 10, 12,
    13 or tiling 6.1.2, a degenerate face) goes to scikit-image itself.
    """
    vol = field if step == 1 else np.ascontiguousarray(field[::step, ::step, ::step])
    ok, verts, _, _, faces, normals = plain_volume(vol, 0.5, step)
    if not ok:
        from skimage.measure import marching_cubes
        try:
            verts, faces, normals, _ = marching_cubes(field, 0.5, step_size=step, allow_degenerate=False)
        except RuntimeError:  # no crossing cube on the step's grid
            return None
    return (verts, faces, normals) if len(faces) else None


def _closed_mesh(field, origin, V, step):
    mc = _marching_cubes(field, step)
    if mc is None:
        return None
    verts, faces, normals = mc
    if len(faces) < 8:
        return None
    # Euler characteristic V - F/2 of a closed mesh is 2 per sphere-like component;
    # anything else (crumbs cut off by erosion, a handle) gets the component pass.
    if len(verts) - len(faces) // 2 != 2 or len(faces) % 2:
        verts, faces, normals = keep_largest_component(verts, faces, normals)
    # Winding kept outward whatever the library's convention.
    ok, x, faces, nrm = _outward_cells(verts, faces, normals, np.asarray(origin, np.float64), int(V))
    return (x, faces, nrm) if ok else None


def mesh_rock(field: np.ndarray, origin, V: int, step: int = 1):
    """Closed triangle mesh of one rock's field (from :func:`rock_field`).

    Parameters
    ----------
    field : (a, b, c) float32
        The rock's low-passed ``rho``, zero on the box border. Values exactly
        ``1/2`` are moved off the level in place.
    origin : (3,) int
        Global index of voxel ``[0, 0, 0]`` of ``field``.
    V : int
        Voxels per cell; output coordinates are in cells, voxel ``i``'s centre
        at ``(i + 0.5) / V``.
    step : int
        Marching-cubes step in voxels (1: full resolution). A rock whose mesh at
        this step is missing or not closed (one smaller than the step's grid:
        the grid holds no surface, or a sliver of it) is meshed at the next finer
        step, down to 1: a coarser step trades triangles for time, it does not
        remove rocks from the pile (their neighbours' contacts expect them).

    Returns
    -------
    (vertices, faces, normals) or None
        float32 ``(P, 3)`` vertices in cell units, int32 ``(F, 3)`` faces with
        outward winding, float32 unit normals; ``None`` when nothing of the rock
        is left (no voxel above ``1/2``) or no step gives a closed oriented mesh.

    References
    ----------
    Peytavie et al. 2009, section 5; Lorensen and Cline 1987; Lewiner et al. 2003.
    """
    # A value exactly at the level makes zero-area triangles; nudge it off.
    if _nudged_max(field) <= 0.5:
        return None
    for s in range(int(step), 0, -1):
        mesh = _closed_mesh(field, origin, V, s)
        if mesh is not None:
            return mesh
    return None
