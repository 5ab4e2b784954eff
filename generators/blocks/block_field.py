"""The replicated block field ``t(p)``: plane arrays of a tile behind a lookup grid.

Block (Paris et al. 2020, section 4.2). Block ``i`` is the smooth intersection of
its half-spaces; with the inside-positive convention of the field language a
half-space is ``h_k(p) = w_k - u_k . p`` (:mod:`.block_hulls`), and

    c_i(p) = smin_R(h_1, ..., h_K),    smin_R(a, b) = -smax_R(-a, -b)

folded over the planes (largest face first), with ``smax_R`` the smooth maximum of
:func:`arches_render.field.operators.smooth_max` (radius ``R = smoothness``,
default the paper's 25 cm). The paper's operator is Barthe's cubic
``max(a, b) - R k^3 / 6``; the language's quadratic one has the same support
(``|a - b| < R``), is C1 as the gradient-based warp requires, and its partial
derivatives are non-negative with sum one, so a fold of 1-Lipschitz planes stays
1-Lipschitz.

Surface details (section 4.2, "gradient-based warping"): ``b = c o w^-1`` with
``w^-1(p) = p + g(p) sum_i alpha_i(g) d(gamma_i(p))``, ``g`` the normalized gradient,
``gamma_i`` the projections on the planes ``xy, xz, yz`` and ``alpha_i = |g . e_i|``.
It is applied here to the leaves of the block's construction tree (Figure 7), the
half-spaces, *before* the smooth intersection: the gradient of ``h_k`` is the
constant ``-u_k``, and for a plane ``h_k(p + g D) = h_k(p) + D`` exactly, so

    h~_k(p) = h_k(p) + e D_k(p),    D_k(p) = sum_i alpha_ki d(gamma_i(p)),
    alpha_ki = |u_k . e_i| / sum_j |u_k . e_j|      (normalized triplanar weights),

with ``d`` a 2-octave fBm of wavelength ``lambda`` (``warp_wavelength``) and ``e``
the amplitude (``warp``). This is the paper's operator on flat faces; at the
rounded edges the smooth intersection blends the displaced faces instead of
warping along a blended gradient. The reason is rigour: the Lipschitz bound of the
paper's form needs a lower bound of ``|grad c|`` and an upper bound of its Hessian,
neither available for a fold of many planes; here

    L = 1 + e L_d / lambda,    L_d = fbm_lipschitz(octaves, 2, 1/2),

because each ``D_k`` is a convex combination of three ``L_d / lambda``-Lipschitz
functions and the fold keeps the largest bound. ``d`` is evaluated at the world
position, so replicated copies of a block get different details.

Replication (section 5): ``t(p) = max_i b_i(p mod s) e_i(a_i + s floor(p / s))``.
With ``T = floor(p / s)`` and ``q = p - s T``, a tile-local grid of cells lists the
*images* ``(i, o)`` (block ``i`` shifted by ``o s``, ``o`` in ``{-2..2}^3``) whose
box, grown by ``m + e |d|_max``, meets the cell: the paper's "contribution in
neighbouring cells to account for blocks straddling C" without a case analysis.
The image ``(i, o)`` is the copy of block ``i`` in the virtual cell ``T + o``, so
its presence is ``e(i, T + o)`` (precomputed by :mod:`.replication`, a table over
the virtual cells of a region; without a table every block is present) and its
value ``b_i(q - o s)``. Then

    t(p) = max(-m, max_{(i, o) in cell(q), present} b_i(q - o s))

equals ``max(-m, max over all present copies)`` everywhere: a copy missing from the
cell has ``b <= min_k h~_k < -m`` there (it lies outside the offset polytope that
was registered). Each copy is a continuous function of ``p`` whatever tile ``p``
falls in, so ``t`` is continuous across tile faces and ``L``-Lipschitz: the
mod-tiling adds nothing to the bound. ``e = 0`` absent copies simply leave the max
(the product ``b_i e_i`` of the paper, read as "absent blocks do not contribute";
with ``f > 0`` inside a literal product would make every absent block a surface).

Evaluation. Without a presence table the tile-local lists above are used as they
are (pure mod-tiling, every block everywhere). With one, presence depends on ``p``
only through the virtual cell, so the present copies ``(i, T)`` are known at build
time; they are listed, with the same grown boxes, in a world grid over the region
(same ``t``, no presence test left in the kernel), whose empty cells answer
``t = -m`` at once. Blocks are evaluated nearest first with an early exit of the
plane fold once it falls below the running maximum (a fold only decreases).
:meth:`eval_bounds` adds to Hart's bound an empty-space distance (distance
transform of the world grid) and a per-copy bound (see the method), so rays stride
further than ``m / L`` near blocks (as in :class:`~arches_render.field.CapsuleSet`).

References
----------
Paris et al. (2020), sections 4.2 (Figures 7-10) and 5.
Barthe, L., Gaildrat, V., Caubet, R. (1998). Combining implicit surfaces with soft
blending in a CSG tree. CSG Conference Series, 17-31.
Stolte, N. (2002). Infinite implicit replication. Shape Modeling International.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render.field.brick_grid import BRICK, MAX_BRICKS, BrickGrid, cell_ranges
from arches_render.field.node import Node, box_distance, cell_index, jit_floats, opaque_float
from arches_render.field.packed_columns import gather_columns, pack_columns, uint_column
from arches_render.field.noise import corner_hash, fade, fbm_lipschitz, fbm_range, grad_dot
from arches_render.field.operators import smooth_max

from .block_hulls import offset_box

__all__ = ["BlockField", "PresentCopies", "image_boxes"]

_RANGE = 2  # image offsets o in {-2..2}^3
#: Most cells the world grid's bricks hold (12 bytes a cell: 25 MB). Fallen blocks
#: along a 5.7 km tile's cliffs: 5.3 M cells at the tile's lookup size, 2.1 M at twice
#: it, the same render time.
WORLD_CELLS = 1 << 21
_CODES = (2 * _RANGE + 1) ** 3


def planar_noise(x, y, seed):
    """:func:`~arches_render.field.noise.gradient_noise` on the plane ``z = 0``.

    The same function as ``gradient_noise(Point3f(x, y, 0), seed)``: with ``z = 0``
    the fade weight of the upper corners ``s(0) = 0`` vanishes and the lower corners
    have ``u_z = 0``, so only the four corners ``c_z = 0`` are summed (half the
    work). Its Lipschitz bound and range are those of the 3D noise.
    """
    fx, fy = dr.floor(x), dr.floor(y)
    ix, iy = mi.UInt32(mi.Int32(fx)), mi.UInt32(mi.Int32(fy))
    ux, uy = x - fx, y - fy
    wx, wy = fade(ux), fade(uy)
    hx = (ix * 0x8DA6B343 ^ seed, (ix + 1) * 0x8DA6B343 ^ seed)
    hy = (iy * 0xD8163841, (iy + 1) * 0xD8163841)
    hz = mi.UInt32(0)
    zero = mi.Float(0.0)
    out = mi.Float(0.0)
    for cx in (0, 1):
        ax = wx if cx else 1.0 - wx
        for cy in (0, 1):
            ay = wy if cy else 1.0 - wy
            out += ax * ay * grad_dot(corner_hash(hx[cx], hy[cy], hz), ux - cx, uy - cy, zero)
    return out


def planar_fbm(x, y, octaves, seed):
    """fBm of :func:`planar_noise` (lacunarity 2, gain 1/2, per-octave offsets in the
    plane): Lipschitz ``fbm_lipschitz(octaves, 2, 1/2)``, range ``fbm_range(octaves, 1/2)``
    (each octave is a restriction of the 3D noise to a plane)."""
    total = mi.Float(0.0)
    for k in range(int(octaves)):
        f = float(2 ** k)
        total += (0.5 ** k) * planar_noise(x * f + 17.31 * k, y * f + 17.31 * k, seed + k)
    return total


def _code(o):
    o = np.asarray(o) + _RANGE
    return (o[..., 0] * (2 * _RANGE + 1) + o[..., 1]) * (2 * _RANGE + 1) + o[..., 2]


def image_boxes(tile, grow: float):
    """Per block, the box of ``{u_k . p <= w_k + grow}`` (``(B, 3)`` lo and hi)."""
    lo = np.empty((tile.n_blocks, 3))
    hi = np.empty((tile.n_blocks, 3))
    for i in range(tile.n_blocks):
        n, w = tile.planes(i)
        lo[i], hi[i] = offset_box(n.astype(np.float64), w.astype(np.float64),
                                  tile.centroid[i].astype(np.float64), grow)
    return lo, hi


def _cell_lists(keys_cells):
    """CSR lists from ``(cell, entry, priority)`` triples."""
    cell, entry, prio, n_cells = keys_cells
    order = np.lexsort((prio, cell))
    count = np.bincount(cell, minlength=n_cells)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    return start.astype(np.uint32), count.astype(np.uint32), entry[order].astype(np.uint32)


@dataclass(frozen=True)
class PresentCopies:
    """The copies a presence table keeps, listed sparsely (a dense ``(nx, ny, nz, B)``
    table over a terrain-wide region would take hundreds of MB).

    Attributes
    ----------
    cells : numpy.ndarray
        ``(n, 3)`` int64: the virtual cell ``T`` of each present copy (absolute index).
    blocks : numpy.ndarray
        ``(n,)`` int64: its block ``i``.
    tiles_lo : numpy.ndarray
        ``(3,)``: the first virtual cell of the region the table was decided over.
    shape : tuple
        ``(nx, ny, nz, B)``: that region's virtual cells and the tile's blocks.
    """

    cells: np.ndarray
    blocks: np.ndarray
    tiles_lo: np.ndarray
    shape: tuple

    def dense(self):
        """The ``(nx, ny, nz, B)`` boolean table (small regions: tests and figures)."""
        out = np.zeros(self.shape, dtype=bool)
        i = self.cells - self.tiles_lo
        out[i[:, 0], i[:, 1], i[:, 2], self.blocks] = True
        return out


class BlockField(Node):
    """Replicated blocks ``t(p)`` of a :class:`~.tile_cache.BlockTile` (module docstring).

    Parameters
    ----------
    tile : BlockTile
        Planes of the blocks of one periodic tile.
    smoothness : float
        Radius ``R`` of the smooth intersection (m), > 0.
    warp : float
        Amplitude ``e`` of the triplanar surface detail (m), >= 0.
    warp_wavelength : float
        Wavelength ``lambda`` of the detail (m), > 0.
    warp_octaves : int
        Octaves of the detail fBm.
    seed : int
        Seed of the detail.
    presence : PresentCopies, optional
        The present copies (block ``i`` in virtual cell ``T``); default: every block in
        every cell (unbounded).
    margin : float
        The clamp ``m`` (m).
    cell_size : float, optional
        Edge of the lookup cells (default half the median middle extent of the
        blocks, rounded to an integer number of cells per tile edge).
    """

    kind = "blocks_field"

    def __init__(self, tile, smoothness=0.25, warp=0.0, warp_wavelength=1.0, warp_octaves=2,
                 seed=0, presence=None, margin=0.25, cell_size=None):
        if not smoothness > 0:
            raise ValueError(f"smoothness must be > 0 (got {smoothness})")
        if not warp >= 0 or not warp_wavelength > 0:
            raise ValueError("warp must be >= 0 and warp_wavelength > 0")
        if not margin > 0:
            raise ValueError("margin must be > 0")
        self.tile = tile
        s = float(tile.size)
        self.s_np, self.m_np, self.R_np = s, float(margin), float(smoothness)
        self.warp_np, self.wavelength_np = float(warp), float(warp_wavelength)
        self.octaves = int(warp_octaves)
        self.detail_max = self.warp_np * fbm_range(self.octaves, 0.5) if self.warp_np > 0 else 0.0
        grow = self.m_np + self.detail_max
        blo, bhi = image_boxes(tile, grow)
        if not cell_size:
            # About half the typical block's middle extent: few copies per cell.
            mid = np.median(np.sort(bhi - blo - 2 * grow, axis=1)[:, 1])
            cell_size = float(np.clip(0.5 * mid, s / 24, s / 2))
        res = max(int(round(s / cell_size)), 1)
        cell = s / res
        self.res_t, self.cell_t = res, cell
        # Images of every block whose grown box meets the tile [0, s)^3.
        o_lo = np.floor(-bhi / s).astype(int) + 1
        o_hi = np.ceil((s - blo) / s).astype(int) - 1
        if np.any(o_lo < -_RANGE) or np.any(o_hi > _RANGE):
            raise ValueError("a block is larger than two tiles: increase the tile size")
        cells, entries, prios = [], [], []
        for i in range(tile.n_blocks):
            for ox in range(o_lo[i, 0], o_hi[i, 0] + 1):
                for oy in range(o_lo[i, 1], o_hi[i, 1] + 1):
                    for oz in range(o_lo[i, 2], o_hi[i, 2] + 1):
                        o = np.array([ox, oy, oz])
                        lo, hi = blo[i] + o * s, bhi[i] + o * s
                        i0 = np.clip(np.floor(lo / cell).astype(int), 0, res - 1)
                        i1 = np.clip(np.floor(hi / cell).astype(int), 0, res - 1)
                        if np.any(hi < 0) or np.any(lo > s):
                            continue
                        g = np.stack(np.meshgrid(*[np.arange(i0[a], i1[a] + 1) for a in range(3)],
                                                 indexing="ij"), -1).reshape(-1, 3)
                        centre = (g + 0.5) * cell
                        cells.append((g[:, 0] * res + g[:, 1]) * res + g[:, 2])
                        entries.append(np.full(len(g), i * _CODES + _code(o)))
                        prios.append(np.linalg.norm(centre - (tile.centroid[i] + o * s), axis=1))
        start, count, index = _cell_lists((np.concatenate(cells), np.concatenate(entries),
                                           np.concatenate(prios), res ** 3))
        self.max_per_cell, self.list_len = int(count.max()), len(index)
        self._start, self._count, self._index = mi.UInt32(start), mi.UInt32(count), mi.UInt32(index)
        # Interleaved (u_x, u_y, u_z, w) per plane: one packet gather per plane.
        self._planes = jit_floats(np.hstack([tile.normals, tile.offsets[:, None]]))
        # Per block, side by side (one packet gather a block): the offsets of its six box
        # faces (its first six planes, unit axes: see _fold), its first plane and count.
        faces = tile.offsets[np.asarray(tile.start)[:, None] + np.arange(6)]
        self._blocks, _ = pack_columns([*faces.T, np.asarray(tile.start), np.asarray(tile.count)])
        self._s, self._inv_s = opaque_float(s), opaque_float(1.0 / s)
        self._inv_cell = opaque_float(1.0 / cell)
        self._m, self._R = opaque_float(self.m_np), opaque_float(self.R_np)
        self._warp, self._inv_wl = opaque_float(self.warp_np), opaque_float(1.0 / self.wavelength_np)
        self._seed = dr.opaque(mi.UInt32, int(seed) & 0xFFFFFFFF)
        self._setup_presence(presence, blo, bhi)

    # -- presence and the world grid -------------------------------------------------
    def _setup_presence(self, presence, blo, bhi):
        self.presence = presence
        self.world_lo = None
        if presence is None:
            return
        if presence.shape[3] != self.tile.n_blocks:
            raise ValueError(f"presence lists {presence.shape[3]} blocks, the tile has {self.tile.n_blocks}")
        s = self.s_np
        b_idx = np.asarray(presence.blocks, dtype=np.int64)
        self.n_present = len(b_idx)
        if self.n_present == 0:
            return
        shift = np.asarray(presence.cells, dtype=np.int64) * s
        lo, hi = blo[b_idx] + shift, bhi[b_idx] + shift
        # The registered boxes contain {t > -m}, a fortiori the solid.
        self.world_lo, self.world_hi = lo.min(0), hi.max(0)
        # The present copies, listed in the cells of a sparse brick grid (cells of the
        # tile's lookup size, or coarser where that would take more than WORLD_CELLS:
        # a few copies a cell; a dense 96^3 grid over a terrain-wide region listed
        # tens) that their grown boxes meet, nearest first. Same exactness argument as the tile-local lists, with no
        # presence test left for the kernel.
        cw = self.cell_t / 1.5
        while True:  # coarser while the bricks would hold more than WORLD_CELLS cells
            cw *= 1.5
            res = np.maximum(np.ceil((self.world_hi - self.world_lo) / cw).astype(np.int64), 1)
            if np.prod(-(-res // BRICK)) > MAX_BRICKS:
                continue
            i0, i1 = cell_ranges(lo, hi, self.world_lo, cw, res)
            if BrickGrid.stored_bricks(i0, i1, res).sum() * BRICK ** 3 <= WORLD_CELLS:
                break
        self.world = BrickGrid(i0, i1, lo, hi, self.world_lo, cw, res)
        cen = self.tile.centroid[b_idx] + shift
        self.world.order_lists(lambda centres, entries: np.linalg.norm(centres - cen[entries], axis=1))
        # A copy's shift and block side by side: one packet gather a copy.
        self._copies, _ = pack_columns([*(shift[:, k] for k in range(3)), b_idx])
        self._wlo = [opaque_float(v) for v in self.world_lo]
        self._whi = [opaque_float(v) for v in self.world_lo + res * cw]
        self._winv = opaque_float(1.0 / cw)

    # -- evaluation ------------------------------------------------------------------
    def _detail(self, p):
        """``d(gamma_i(p))`` for the projections on ``yz, xz, xy`` (weights of e_x, e_y, e_z)."""
        q = p * self._inv_wl
        return (planar_fbm(q.y, q.z, self.octaves, self._seed),
                planar_fbm(q.x, q.z, self.octaves, self._seed + 7919),
                planar_fbm(q.x, q.y, self.octaves, self._seed + 15838))

    def _fold(self, b, x, present, best, det):
        """``(max(best, b_b(x)), v)`` where present; the plane fold stops once below
        ``best``, so ``v >= b_b(x)`` is the value or an upper bound of it."""
        *w, k0, n = gather_columns(self._blocks, b, 8, 8)
        k0 = uint_column(k0)
        k1 = dr.select(present, k0 + uint_column(n), k0)
        # The first six planes of a block are its box faces +x, +y, +z, -x, -y, -z
        # (see tile_cache.build_tile): unit normals, so no dot products.
        box = (w[0] - x.x, w[1] - x.y, w[2] - x.z, w[3] + x.x, w[4] + x.y, w[5] + x.z)
        v = mi.Float(1e30)
        for axis, h in zip((0, 1, 2, 0, 1, 2), box):
            if det is not None:
                h = h + self._warp * det[axis]
            v = -smooth_max(-v, -h, self._R)

        def plane_body(k, v):
            g = dr.gather(mi.Vector4f, self._planes, k)
            n = mi.Vector3f(g.x, g.y, g.z)
            h = g.w - dr.dot(n, x)
            if det is not None:
                a = dr.abs(n)
                h += self._warp * (a.x * det[0] + a.y * det[1] + a.z * det[2]) / (a.x + a.y + a.z)
            return k + 1, -smooth_max(-v, -h, self._R)

        # A fold only decreases: stop once it cannot beat the running maximum.
        _, v = dr.while_loop((k0 + 6, v), lambda k, v: (k < k1) & (v > best),
                             plane_body, label="block_planes")
        return dr.select(present, dr.maximum(best, v), best), dr.select(present, v, -1e30)

    def _tiled(self, p):
        """``t`` by the mod-tiling, every block present (tile-local lists)."""
        T = dr.floor(p * self._inv_s)
        q = p - T * self._s
        res = self.res_t
        ci = [cell_index(q[a] * self._inv_cell, res) for a in range(3)]
        cell = (ci[0] * res + ci[1]) * res + ci[2]
        start = dr.gather(mi.UInt32, self._start, cell)
        count = dr.gather(mi.UInt32, self._count, cell)
        det = self._detail(p) if self.warp_np > 0 else None
        w = 2 * _RANGE + 1

        def body(j, best):
            e = dr.gather(mi.UInt32, self._index, start + j)
            b = e // _CODES
            code = e - b * _CODES
            o = mi.Vector3f(mi.Float(mi.Int32(code // (w * w)) - _RANGE),
                            mi.Float(mi.Int32((code // w) % w) - _RANGE),
                            mi.Float(mi.Int32(code % w) - _RANGE))
            return j + 1, self._fold(b, q - o * self._s, mi.Bool(True), best, det)[0]

        return dr.while_loop((mi.UInt32(0), -self._m + mi.Float(0.0)), lambda j, best: j < count,
                             body, label="block_images")[1]

    def _present(self, p, start, count):
        """``t`` over the ``count`` present copies listed from ``start`` (the world cell of ``p``)."""
        det = self._detail(p) if self.warp_np > 0 else None

        def body(j, best, upper):
            cx, cy, cz, b = gather_columns(self._copies, dr.gather(mi.UInt32, self.world.index, start + j), 4, 4)
            b = uint_column(b)
            x = p - mi.Vector3f(cx, cy, cz)
            best, v = self._fold(b, x, mi.Bool(True), best, det)
            return j + 1, best, dr.maximum(upper, v)

        _, best, upper = dr.while_loop((mi.UInt32(0), -self._m + mi.Float(0.0), mi.Float(-1e30)),
                                       lambda j, best, upper: j < count, body, label="block_copies")
        return best, upper

    def eval(self, p):
        return self._eval(p)[0]

    def _eval(self, p):
        """``(t, extra)``; ``extra`` = (empty-space distance, upper bound of the listed
        copies, distance to the world cell's faces) for :meth:`eval_bounds`."""
        if self.presence is None:
            return self._tiled(p), None
        if self.world_lo is None:
            return -self._m + mi.Float(0.0) * p.x, None
        outside = box_distance(p, self._wlo, self._whi)
        start, count = self.world.cell_list(p)
        f, upper = dr.if_stmt((p, start, count), (outside <= 0.0) & (count > 0),
                              lambda p, start, count: self._present(p, start, count),
                              lambda p, start, count: (-self._m + mi.Float(0.0) * p.x, mi.Float(-1e30)),
                              label="blocks_near")
        empty = dr.maximum(self.world.empty_distance(p), outside)
        rel = (p - mi.Point3f(*self._wlo)) * self._winv
        frac = rel - dr.floor(rel)
        face = dr.minimum(dr.min(frac), dr.min(1.0 - frac)) / self._winv
        return dr.select(outside > 0.0, -self._m - outside, f), (empty, upper, face)

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        """Distances to ``{t >= -c}``: Hart's ``-t / L``; for ``c < m`` also the larger of
        the empty-space distance and ``min(-v_max / L, m - c + face)``, where ``v_max``
        bounds the listed copies and ``face`` is the distance to the world cell's
        faces (an unlisted copy's solid, grown by ``m``, lies outside the cell).

        With no copy present at all (a presence table that kept none) ``t = -m``
        everywhere, so ``{t >= -c}`` is empty for ``c < m``: the distance is infinite.
        (Hart's ``(m - c) / L`` there held every ray of a scene to steps of ~m / L,
        ~20 cm, wherever this node is a union's operand: every_generator with its blocks'
        region emptied took 271 camera steps a ray, against 36 with blocks.)"""
        f, extra = self._eval(p)
        inv = 1.0 / self.lipschitz
        if self.presence is not None and self.world_lo is None:
            return f, tuple(mi.Float(dr.inf) + 0.0 * f if c < self.m_np else 0.0 * f for c in levels)
        out = []
        for c in levels:
            d = dr.maximum(-f - c, 0.0) * inv
            if extra is not None and c < self.m_np:
                empty, upper, face = extra
                listed = dr.maximum(-upper - c, 0.0) * inv
                d = dr.maximum(d, dr.maximum(empty, dr.minimum(listed, self.m_np - c + face)))
            out.append(d)
        return f, tuple(out)

    # -- protocol --------------------------------------------------------------------
    def bounds(self):
        if self.presence is None:
            return np.full(3, -np.inf), np.full(3, np.inf)
        if self.world_lo is None:
            return np.zeros(3), -np.ones(3)  # empty
        return self.world_lo.copy(), self.world_hi.copy()

    # Clamped at -m within the world grid: no unit-rate falloff from the box.
    unit_falloff = False

    @property
    def lipschitz(self):
        slope = self.warp_np * fbm_lipschitz(self.octaves, 2.0, 0.5) / self.wavelength_np
        return 1.0 + slope

    @property
    def cost(self):
        return 4.0 + min(self.max_per_cell, 16) * 3.0 + (18.0 * self.octaves if self.warp_np else 0.0)

    def nbytes(self):
        n = 64 + self.tile.nbytes() + self.res_t ** 3 * 8 + self.list_len * 4
        if self.world_lo is not None:
            n += self.world.nbytes() + self.n_present * 16
        return n
