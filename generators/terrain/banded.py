"""Banded polygonization of amplified terrains (Paris et al. 2019, Sec. 7).

Section 7 of the terrain amplification paper, so it lives with the terrain
generator: it reads the terrain's own node types (implicit heightfields, skeletal
sets, sums, erosion, local warps) directly, and the core polygonizer
(:mod:`arches_render.mesh.polygonize`) knows none of them.

The grid is the one of :func:`arches_render.mesh.polygonize.sample_grid` (the
field's bounds grown by one voxel, vertices ``lo + (i, j, k) voxel``). Instead of
sampling every vertex, the tree is asked where its surface can be:

* **Surface bounds.** Each node marks, in a boolean *band* over the grid, the
  vertices near which its surface may pass. A heightfield marks, in each column,
  ``[h_min - S v / sqrt 2, h_max + S v / sqrt 2]`` with ``h_min, h_max`` the extreme
  elevations at the vertex columns of the 1-ring (the paper's dilation) and ``S``
  the slope bound: every point of a grid cell is within ``v / sqrt 2`` of one of its
  corner columns, so the surface over the four cells around a column lies in
  that range; its prism adds the bottom plane and, in the columns near its
  walls, the span from the bottom to the ground band.
  A compactly supported operand (a sculpting or erosion
  :class:`~.skeletal_set.SkeletalSet` in a sum,
  an erosion or a local warp) marks its primitives' support boxes: outside them it
  adds exactly 0 and the surface is its sibling's. Unions, intersections and
  differences mark their operands' bands (``max(a, b) = 0`` needs ``a = 0`` or
  ``b = 0``), a box operand only its faces (a terrain clipped to a tile); any
  other node marks its whole box. Boxes are marked on the
  vertices of every cell they touch (floor / ceil), so every cube that the
  surface crosses has its 8 corners in the band.
* **Constant sign elsewhere.** Between two band intervals of a column no surface
  is met, so the field keeps one sign along that run, the sign of the band voxel
  next to it (a sign change on that edge would be a crossing, whose two end points
  are in the band); the run is filled with ``+-voxel`` (as ``sample_grid`` fills
  certified blocks). A window column without band voxels costs one evaluation.
* **Direct elevation extraction.** When the tree is a terrain with compactly
  supported modifiers (sum, erosion, local warp of skeletal sets), a column that
  no support touches holds the terrain's field alone, which is a closed form of
  the elevation ``h`` at the column: ``min(s(h - z), f_P)`` for an
  :class:`~.implicit_heightfield.ImplicitHeightfield`
  (``min(h - z, box)`` for a plain heightfield), intersected with clip boxes if
  the tree is clipped to a tile. One elevation per column then
  replaces the field evaluations of its band voxels (numba, float32); values
  within float32 rounding of 0, whose sign could differ from the tree's own
  arithmetic, are left to the tree.

**Windows, O(band).** Nothing is allocated or scanned per grid voxel: the band is
kept as marks (column intervals, index boxes), and the columns are cut into tiles
(:mod:`.tiled_mc`); each tile holds one *window* per run of levels where some of its
columns has band voxels (a level without any is a layer of non-crossing cubes on
both sides, so runs separated by it mesh apart). Values, gap filling and the search
for crossing cubes touch the windows only (:mod:`.banded_kernels`), and marching
cubes runs on each window's runs of crossing layers.

Cubes crossed by the surface see exactly the values a dense sampling gives them
(up to float rounding of the direct extraction), and every other cube sees one
sign, so the mesh is the one :func:`polygonize_dense` builds the same way from
every vertex of the grid (tested bit for bit in its faces). Vertex normals are
central differences of the field, as in ``polygonize``.

References
----------
Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
38(5), Sec. 7 (surface bounds, 1-ring dilation, direct elevation extraction).
Lorensen, W. E., Cline, H. E. (1987). Marching cubes. SIGGRAPH '87.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render.backend import variant
from arches_render.field import Node, evaluate
from arches_render.field.heightfield import Heightfield
from arches_render.field.node import finite_box
from arches_render.field.operators import Difference, Intersection, Union
from arches_render.field.primitives import Box
from arches_render.mesh.polygonize import MAX_VOXELS, TriangleMesh, default_voxel

from . import banded_kernels as K

from .erosion_node import Erosion
from .implicit_heightfield import R0_FACTOR, ImplicitHeightfield
from .operators import LocalWarp, Sum
from .skeletal_set import SkeletalSet
from .tiled_mc import TILE, mesh_runs

__all__ = ["BandStats", "sample_banded", "polygonize_banded", "polygonize_dense", "slab_mesh"]

#: Terrain nodes whose field is a closed form of one elevation per column.
TERRAINS = (ImplicitHeightfield, Heightfield)


@dataclass
class BandStats:
    """What the banded sampler did (for reports and benchmarks)."""

    voxels: int = 0
    #: Band voxels of the windows; a tile's last column is also its neighbour's
    #: first, so band, evaluated and direct count those columns twice (~6 %).
    band: int = 0
    evaluated: int = 0
    direct: int = 0
    #: Window columns without band voxels (one evaluation each).
    runs: int = 0
    #: Voxels of the windows (allocated, filled and scanned for crossings; O(band)).
    allocated: int = 0
    #: Voxels handed to marching cubes (the crossing runs).
    meshed: int = 0
    #: Fraction of the grid's columns touched by non-terrain nodes (the paper's ``a``).
    coverage: float = 0.0
    notes: list = field(default_factory=list)


def _compact_boxes(node: Node):
    """Per-primitive support boxes ``(lo (N,3), hi (N,3))`` outside which the node is
    exactly 0, or ``None`` when it has no such support."""
    if isinstance(node, SkeletalSet) and node.threshold_np == 0.0:
        return node.primitive_boxes()
    if isinstance(node, Sum):
        parts = [_compact_boxes(c) for c in node.children]
        if all(p is not None for p in parts):
            return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
    return None


#: Boxes are grown by this fraction of a voxel before marking (float32 evaluation
#: of points that lie exactly on a box face).
_SLACK = 1e-3


class _Grid:
    def __init__(self, node, voxel):
        box = finite_box(node)
        if box is None or np.any(box[1] < box[0]):
            raise ValueError("banded polygonization needs a bounded, non-empty field")
        lo, hi = box
        self.lo = lo - voxel
        self.voxel = voxel
        self.shape = np.ceil((hi + voxel - self.lo) / voxel).astype(int) + 1
        if np.prod(self.shape) > MAX_VOXELS:
            raise ValueError(f"voxel {voxel:g} m gives a {self.shape.tolist()} grid "
                             f"({np.prod(self.shape):.3g} voxels, at most {MAX_VOXELS:.3g}): use a larger voxel")
        # The band as marks, never as a grid-sized mask (O(columns + boxes) memory):
        # column intervals [K0, K1] ((nx, ny) int arrays, empty where K0 > K1) and
        # inclusive index boxes (i0, j0, k0, i1, j1, k1).
        self.intervals = []
        self.boxes = []
        self.other = np.zeros(tuple(self.shape[:2]), dtype=bool)  # columns touched by non-terrain marks
        self.terrains = []

    def mark_intervals(self, k0, k1):
        """Mark levels ``[k0, k1]`` (float or int arrays over the columns) of each column."""
        top = int(self.shape[2]) - 1
        self.intervals.append((np.clip(k0, 0, top + 1).astype(np.int32), np.clip(k1, -1, top).astype(np.int32)))

    def index_range(self, blo, bhi):
        """Inclusive vertex index ranges of the cells a box touches (clipped), or None."""
        i0 = np.floor((np.asarray(blo) - self.lo) / self.voxel - _SLACK).astype(np.int64)
        i1 = np.floor((np.asarray(bhi) - self.lo) / self.voxel + _SLACK).astype(np.int64) + 1
        if np.any(i1 < 0) or np.any(i0 > self.shape - 1) or np.any(i1 < i0):
            return None
        return np.clip(i0, 0, self.shape - 1), np.clip(i1, 0, self.shape - 1)

    def mark_box(self, blo, bhi, other=True):
        r = self.index_range(blo, bhi)
        if r is None:
            return
        (a, b, c), (d, e, f) = r
        self.boxes.append(np.array([[a, b, c, d, e, f]], dtype=np.int64))
        if other:
            self.other[a:d + 1, b:e + 1] = True

    def mark_boxes(self, los, his):
        los = np.asarray(los, dtype=np.float64)
        his = np.asarray(his, dtype=np.float64)
        i0 = np.floor((los - self.lo) / self.voxel - _SLACK).astype(np.int64)
        i1 = np.floor((his - self.lo) / self.voxel + _SLACK).astype(np.int64) + 1
        keep = np.all(i1 >= 0, axis=1) & np.all(i0 <= self.shape - 1, axis=1)
        i0 = np.clip(i0[keep], 0, self.shape - 1)
        i1 = np.clip(i1[keep], 0, self.shape - 1)
        self.boxes.append(np.concatenate([i0, i1], axis=1))
        for (a, b, _), (d, e, _) in zip(i0.tolist(), i1.tolist()):
            self.other[a:d + 1, b:e + 1] = True

    def columns(self):
        xs = self.lo[0] + np.arange(self.shape[0]) * self.voxel
        ys = self.lo[1] + np.arange(self.shape[1]) * self.voxel
        return np.meshgrid(xs, ys, indexing="ij")


def _elevation(node, X, Y):
    """Elevation of a terrain node at numpy columns, through its own Dr.Jit code."""
    variant()
    x = mi.Float(X.astype(np.float32).ravel())
    y = mi.Float(Y.astype(np.float32).ravel())
    h = node.elevation(x, y) if hasattr(node, "elevation") else node.height(x, y)
    dr.eval(h)
    return h.numpy().reshape(X.shape)


def _walls_and_bottom(node):
    """(xy rectangle outside of which columns are walls, bottom z) of a terrain node."""
    if isinstance(node, ImplicitHeightfield):
        lo, hi = node.prism_lo, node.prism_hi
        return (lo[0], lo[1], hi[0], hi[1]), lo[2] - R0_FACTOR * node.R_np
    x0, y0, x1, y1 = node.extent
    return (x0, y0, x1, y1), node.base_np


def _mark_terrain(grid: _Grid, node):
    X, Y = grid.columns()
    h = _elevation(node, X, Y).astype(np.float64)
    v = grid.voxel
    # float32 rounding of h and z: a few ulps of the largest magnitude.
    eps = 1e-5 * (np.abs(h).max() + np.abs(grid.lo[2]) + v * grid.shape[2]) + 1e-3 * v
    pad = node.slope_bound * v / math.sqrt(2.0) + eps
    hlo, hhi = K.neighbour_range(h)
    hlo, hhi = hlo - pad, hhi + pad
    k0 = np.floor((hlo - grid.lo[2]) / v)
    k1 = np.ceil((hhi - grid.lo[2]) / v)
    grid.mark_intervals(k0, k1)
    (rx0, ry0, rx1, ry1), zb = _walls_and_bottom(node)
    kb0 = int(math.floor((zb - eps - grid.lo[2]) / v))
    kb1 = int(math.ceil((zb + eps - grid.lo[2]) / v))
    nx, ny, nz = (int(n) for n in grid.shape)
    if kb1 >= 0 and kb0 <= nz - 1:
        grid.boxes.append(np.array([[0, 0, max(kb0, 0), nx - 1, ny - 1, min(kb1, nz - 1)]], dtype=np.int64))
    # Near the prism's sides the wall lies between the bottom and the ground (above
    # the ground the field is already negative): mark that span of the column.
    # Closed comparisons (with rounding slack): a column one voxel from the wall has
    # a cell that touches it.
    w = v * (1.0 + 1e-6) + 1e-6 * (abs(rx0) + abs(rx1) + abs(ry0) + abs(ry1))
    wall = (X <= rx0 + w) | (X >= rx1 - w) | (Y <= ry0 + w) | (Y >= ry1 - w)
    grid.mark_intervals(np.where(wall, kb0, nz), np.where(wall, k1, -1))
    grid.terrains.append((node, h))


def _mark(grid: _Grid, node: Node, stats: BandStats):
    if isinstance(node, TERRAINS):
        _mark_terrain(grid, node)
        return
    if isinstance(node, SkeletalSet):
        # With a threshold != 0 the set is not compact, but its positive part
        # still lies inside the primitives' supports.
        grid.mark_boxes(*node.primitive_boxes())
        return
    if isinstance(node, (Sum, Erosion, LocalWarp)):
        main, compact = _split_compact(node)
        if main is not None:
            _mark(grid, main, stats)
            for boxes in compact:
                grid.mark_boxes(*boxes)
            return
    if isinstance(node, (Union, Intersection, Difference)):
        for c in node.children:
            if isinstance(c, Box):
                _mark_box_faces(grid, c)
            else:
                _mark(grid, c, stats)
        return
    stats.notes.append(f"{type(node).__name__}: whole box sampled")
    grid.mark_box(*node.bounds())


def _mark_box_faces(grid: _Grid, box):
    """A box primitive's surface: its six faces (thickened by its rounding). The side
    faces make their columns non-direct; the top and bottom are part of the direct
    closed form (see :func:`_direct_values`)."""
    lo, hi = box.bounds()
    r = box.round_np
    for axis in range(3):
        for side in (lo[axis], hi[axis]):
            a, b = lo - r, hi + r
            a[axis], b[axis] = side - r, side + r
            grid.mark_box(a, b, other=axis < 2)


def _split_compact(node):
    """``(main child, [support boxes of the compact operands])`` or ``(None, [])``."""
    if isinstance(node, Erosion):
        boxes = _compact_boxes(node.children[1])
        return (node.children[0], [boxes]) if boxes is not None else (None, [])
    if isinstance(node, LocalWarp):
        boxes = _compact_boxes(node.children[1])
        if boxes is None:
            return None, []
        # Inside a control support the warp moves points by up to the warp's reach.
        r = node.max_offset * math.sqrt(3.0)
        return node.children[0], [(boxes[0] - r, boxes[1] + r)]
    parts = [(c, _compact_boxes(c)) for c in node.children]
    mains = [c for c, b in parts if b is None]
    if len(mains) != 1:
        return None, []
    return mains[0], [b for _, b in parts if b is not None]


def _direct_terrain(node):
    """``(terrain, clip boxes)``: the root equals ``min(terrain, boxes...)`` outside the
    compact supports, or ``(None, [])``."""
    if isinstance(node, TERRAINS):
        return node, []
    if isinstance(node, (Sum, Erosion, LocalWarp)):
        main, _ = _split_compact(node)
        return (None, []) if main is None else _direct_terrain(main)
    if isinstance(node, (Union, Intersection)) and len(node.children) == 1:
        return _direct_terrain(node.children[0])
    if isinstance(node, Intersection):
        rest = [c for c in node.children if not isinstance(c, Box)]
        if len(rest) == 1:
            terrain, boxes = _direct_terrain(rest[0])
            if terrain is not None:
                return terrain, boxes + [c for c in node.children if isinstance(c, Box)]
    return None, []


def _direct_params(terrain, boxes):
    """``(kind, params, boxes)`` float32 arrays of the direct closed forms for numba."""
    if isinstance(terrain, ImplicitHeightfield):
        kind = 0
        params = [terrain.R_np, terrain.sig_a, terrain.sig_b, terrain.T_np, *terrain.prism_lo, *terrain.prism_hi]
    else:
        kind = 1
        x0, y0, x1, y1 = terrain.extent
        params = [(x0 + x1) / 2, (y0 + y1) / 2, (terrain.base_np + terrain.top_np) / 2,
                  (x1 - x0) / 2, (y1 - y0) / 2, (terrain.top_np - terrain.base_np) / 2]
    b = np.array([[*bx.c_np, *(bx.h_np - bx.round_np), bx.round_np] for bx in boxes], dtype=np.float32)
    return kind, np.asarray(params, dtype=np.float32), b.reshape(-1, 7)


@dataclass
class Band:
    """The sampled band: windows (see :mod:`.banded_kernels`) and their flat values."""

    win: np.ndarray
    off: np.ndarray
    vol: np.ndarray
    mask: np.ndarray
    shape: np.ndarray
    lo: np.ndarray

    def window(self, w):
        """Values of window ``w`` as an ``(sx, sy, sz)`` view."""
        sx, sy, sz = (int(n) for n in self.win[w, [2, 3, 5]])
        return self.vol[self.off[w]:self.off[w + 1]].reshape(sx, sy, sz)


def _windows(grid: _Grid):
    """Windows ``(i0, j0, sx, sy, k0, sz)`` of each tile's runs of band levels (at least
    two levels: a cube with a corner off the band does not cross, module docstring),
    their flat offsets, and the box lists of the tiles."""
    nx, ny, nz = (int(n) for n in grid.shape)
    ntx, nty = -(-(nx - 1) // TILE), -(-(ny - 1) // TILE)
    K0 = np.stack([k for k, _ in grid.intervals]) if grid.intervals else np.zeros((0, nx, ny), np.int32)
    K1 = np.stack([k for _, k in grid.intervals]) if grid.intervals else np.zeros((0, nx, ny), np.int32)
    boxes = np.concatenate(grid.boxes) if grid.boxes else np.zeros((0, 6), np.int64)
    occ, ptr, idx = K.tile_levels(TILE, ntx, nty, nz, K0, K1, boxes)
    edge = np.diff(np.pad(occ.reshape(-1, nz), ((0, 0), (1, 1))).astype(np.int8), axis=1)
    t, k0 = np.nonzero(edge == 1)
    _, k1 = np.nonzero(edge == -1)  # same row-major order: runs pair up
    keep = k1 - k0 >= 2
    t, k0, sz = t[keep], k0[keep], (k1 - k0)[keep]
    i0, j0 = (t // nty) * TILE, (t % nty) * TILE
    sx, sy = np.minimum(TILE, nx - 1 - i0) + 1, np.minimum(TILE, ny - 1 - j0) + 1
    win = np.stack([i0, j0, sx, sy, k0, sz], axis=1).astype(np.int64)
    off = np.concatenate([[0], np.cumsum(sx * sy * sz)]).astype(np.int64)
    return win, off, (K0, K1, boxes, ptr, idx)


def sample_banded(node: Node, voxel: float, stats: BandStats | None = None, progress=None) -> Band:
    """Sample the field where its surface can be (see module docstring), window by
    window: memory and work are those of the windows, O(band), not of the grid.

    Returns
    -------
    Band
        Window values (exact in the band, ``+-voxel`` elsewhere) and band mask.
    """
    stats = stats if stats is not None else BandStats()
    grid = _Grid(node, voxel)
    _mark(grid, node, stats)
    shape, lo = grid.shape, grid.lo
    win, off, (K0, K1, boxes, ptr, idx) = _windows(grid)
    n = int(off[-1])
    mask = np.zeros(n, dtype=bool)
    vol = np.zeros(n, dtype=np.float32)
    stats.voxels, stats.allocated = int(np.prod(shape)), n
    stats.band = int(K.window_mask(win, off, TILE, -(-(int(shape[1]) - 1) // TILE), K0, K1, boxes, ptr, idx, mask))
    stats.coverage = float(grid.other.mean())
    terrain, clip_boxes = _direct_terrain(node)
    if terrain is not None:
        # Direct columns: the closed form from the column's elevation (numba, float32).
        h_cols = next(h for t, h in grid.terrains if t is terrain)
        direct = ~grid.other
        kind, params, cboxes = _direct_params(terrain, clip_boxes)
        stats.direct = int(K.direct_fill(vol, mask, win, off, direct, h_cols.astype(np.float32),
                                         lo.astype(np.float32), np.float32(voxel), kind, params, cboxes))
    else:
        direct = np.zeros(tuple(shape[:2]), dtype=bool)

    def values(ijk):
        """Field values of the tree at grid indices (the dense grid's points exactly)."""
        pts = K.grid_points(ijk, lo, voxel)
        batch = 1 << 21
        out = np.empty(len(pts), dtype=np.float32)
        for s in range(0, len(pts), batch):
            out[s:s + batch] = evaluate(node, pts[s:s + batch])
            if progress:
                progress(min(s + batch, len(pts)), len(pts))
        stats.evaluated += len(pts)
        return out

    pos, ijk = K.to_evaluate(vol, mask, win, off, direct)
    vol[pos] = values(ijk)
    # A gap voxel has the sign of the band voxel next to it: a sign change on that
    # edge would be a surface crossing, whose end points are both in the band. A
    # window column without band voxels lies in one gap run: one evaluation.
    starts, ijk = K.fill_gaps(vol, mask, win, off, np.float32(voxel))
    if len(starts):
        sign = np.where(values(ijk) > 0, np.float32(voxel), np.float32(-voxel))
        sz = win[np.searchsorted(off, starts, side="right") - 1, 5]
        for s, z, v in zip(starts.tolist(), sz.tolist(), sign.tolist()):
            vol[s:s + z] = v
    stats.runs = len(starts)
    return Band(win, off, vol, mask, shape, lo)


def polygonize_banded(node: Node, voxel: float | None = None, progress=None,
                      stats: BandStats | None = None, normals: bool = True) -> TriangleMesh:
    """Marching-cubes mesh of ``f = 0`` sampled only in the surface band.

    Marching cubes runs on each window's runs of crossing cube layers only
    (:func:`~.tiled_mc.mesh_runs`), in tile order.

    Parameters
    ----------
    node : Node
        Bounded field (typically an amplified terrain).
    voxel : float, optional
        Grid spacing in metres (default :func:`~arches_render.mesh.polygonize.default_voxel`).
    progress : callable, optional
        ``progress(done, total)`` over evaluated points.
    stats : BandStats, optional
        Filled with the counts of voxels, band voxels, evaluations and direct values.
    normals : bool
        Compute field normals and orient the faces (as ``polygonize``); without, the
        bare marching-cubes extraction.

    Returns
    -------
    TriangleMesh
        The mesh of :func:`polygonize_dense` on the same grid.
    """
    voxel = float(voxel) if voxel else default_voxel(node)
    stats = stats if stats is not None else BandStats()
    band = sample_banded(node, voxel, stats, progress)
    w, c0, c1 = K.crossing_runs(band.vol, band.win, band.off).T
    i0, j0, sx, sy, k0, sz = band.win[w].T
    # Run rows of mesh_runs: windows are in tile order and, within a tile, by
    # increasing k0; so are their runs.
    runs = np.stack([band.off[w] + c0, sy * sz, sz, sx, sy, c1 - c0 + 2, i0, j0, k0 + c0,
                     i0, i0 + sx - 1, j0, j0 + sy - 1], axis=1)
    stats.meshed = int((sx * sy * (c1 - c0 + 2)).sum())
    return mesh_runs(node, band.vol, runs, band.shape, band.lo, voxel, normals)


def polygonize_dense(node: Node, voxel: float | None = None, normals: bool = True) -> TriangleMesh:
    """Reference: every vertex of the same grid evaluated, every cube of the grid
    tested for a crossing, and marching cubes on each tile's runs of crossing layers
    (:func:`~.tiled_mc.mesh_runs`: the triangles of one marching cubes on the whole
    grid, in tile order). Built as the banded mesh is, from the whole grid's
    values: equal signs give the same runs, hence the same mesh bit for bit."""
    voxel = float(voxel) if voxel else default_voxel(node)
    grid = _Grid(node, voxel)
    nx, ny, nz = (int(n) for n in grid.shape)
    vol = np.empty((nx, ny, nz), dtype=np.float32)
    jk = np.stack(np.meshgrid(np.arange(ny), np.arange(nz), indexing="ij"), -1).reshape(-1, 2)
    step = max(1, (1 << 21) // (ny * nz))
    for i in range(0, nx, step):
        ii = np.arange(i, min(i + step, nx))
        idx = np.concatenate([np.repeat(ii, len(jk))[:, None], np.tile(jk, (len(ii), 1))], axis=1)
        vol[i:i + len(ii)] = evaluate(node, K.grid_points(idx, grid.lo, voxel)).reshape(len(ii), ny, nz)
    i0, j0, sx, sy, c0, c1 = K.tile_crossing_runs(vol, TILE).T
    runs = np.stack([(i0 * ny + j0) * nz + c0, np.full_like(i0, ny * nz), np.full_like(i0, nz), sx, sy,
                     c1 - c0 + 2, i0, j0, c0, i0, i0 + sx - 1, j0, j0 + sy - 1], axis=1)
    return mesh_runs(node, vol.reshape(-1), runs, grid.shape, grid.lo, voxel, normals)


def slab_mesh(root: Node, extent, z0: float, z1: float, voxel: float, border: float):
    """Mesh of ``root`` inside the slab ``z0 <= z <= z1`` and its faces off the tile's border.

    Parameters
    ----------
    root : Node
        The tree (an amplified terrain).
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` of the tile.
    z0, z1 : float
        The slab's floor and ceiling (m).
    voxel : float
        Grid spacing (m).
    border : float
        Faces closer than this to the tile's sides are not *inner*.

    Returns
    -------
    (trimesh.Trimesh, numpy.ndarray) or None
        The mesh and the boolean mask of its inner faces (away from the border and
        from the slab's cut faces); ``None`` when the slab holds no surface at this
        voxel (the terrain lies wholly above or below it, or the slab falls between
        two rows of grid vertices): a caller that guides sampling with it keeps what
        it has, rather than stopping on an error.

    References
    ----------
    Paris et al. (2019), section 6.1: each sea-erosion step samples the mesh of the
    terrain carved so far.
    """
    import trimesh
    x0, y0, x1, y1 = extent
    box = Box([(x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2], [(x1 - x0) / 2, (y1 - y0) / 2, (z1 - z0) / 2])
    try:
        m = polygonize_banded(Intersection(root, box), voxel)
    except ValueError:  # "no surface inside its bounds at this voxel size"
        return None
    mesh = trimesh.Trimesh(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64), process=False)
    c = mesh.triangles_center
    inner = ((c[:, 0] > x0 + border) & (c[:, 0] < x1 - border) & (c[:, 1] > y0 + border)
             & (c[:, 1] < y1 - border) & (c[:, 2] > z0 + 0.5 * voxel) & (c[:, 2] < z1 - 0.5 * voxel))
    return mesh, inner
