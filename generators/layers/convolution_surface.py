"""The implicit surface of material stacks: a box-kernel convolution (Peytavie et al. 2009, 3.3).

Skeleton ``g(p) = 1`` inside the chosen materials (by default sand, rock and the
bedrocks, the ground of section 6), kernel ``h(q) = 1`` for ``|q|_inf < sigma``. The
convolution ``i(p)`` is the volume ``V_M(p)`` of material inside the cube
``Omega(p)`` of half-side ``sigma`` (``V_Omega = 8 sigma^3``), and the paper's field is

    f(p) = 2 i(p) / V_Omega - 1 = V_M(p) / (4 sigma^3) - 1        (in [-1, 1]).

The node returns ``F = sigma f = V_M / (4 sigma^2) - sigma`` (metres): the same zero
set, but near a flat layer boundary ``F`` is the signed distance itself (for the
half-space under ``z = h``, ``V_M = 4 sigma^2 (h - z + sigma)`` so ``F = h - z``),
which is what the renderer's hit tolerance and the blend radii of the language
expect. :func:`paper_field` gives ``f`` itself.

Constant-time evaluation. The stacks are unions of boxes (column squares times
layer intervals), so ``V_M`` separates: with ``w_x(i)``, ``w_y(j)`` the lengths of
``[x - sigma, x + sigma]`` and ``[y - sigma, y + sigma]`` inside column ``(i, j)``,

    V_M(p) = sum_{i, j} w_x(i) w_y(j) (C_ij(z + sigma) - C_ij(z - sigma)),

where ``C_ij(z)`` is the occupied length of the stack below ``z``. ``C`` comes from
per-stack prefix sums: the merged intervals ``[b_k, t_k]`` of a stack store the
occupied length ``S_k`` below ``b_k``; with ``k`` the last interval with ``b_k <= z``
(a binary search with a fixed number of steps, ``ceil(log2(n_max + 1))``),
``C(z) = S_k + min(z - b_k, t_k - b_k)``. The cube touches at most
``K = ceil(2 sigma / s) + 1`` columns per axis, so a point costs ``2 K^2`` searches:
constant for a given ``sigma / s``. This is the paper's "sum of the volume of the
boxes of material layers intersecting the kernel support box", made O(1).

Lipschitz bound (derived): moving ``p`` along x changes ``V_M`` at the rate
``A(+x face) - A(-x face)`` of occupied area on the two faces of the cube, each in
``[0, 4 sigma^2]``; hence ``|grad V_M| <= 4 sigma^2 sqrt(3)``, ``|grad f| <= sqrt(3) /
sigma`` and ``|grad F| <= sqrt(3)``.

Distance bound for sphere tracing: ``F >= -c`` with ``c < sigma`` needs ``V_M > 0``,
i.e. matter in the open cube of half-side ``sigma`` around the point. A coarse grid
of cells marks those touched by matter; its chessboard distance transform ``D``
says that all cells within ``D - 1`` (index distance) of a point's cell are empty,
a box ``B`` around the point. Every point ``q`` of ``B`` shrunk by ``sigma`` has its
cube in ``B``, so ``F(q) = -sigma``: the distance to ``{F >= -c}`` is at least the
distance from ``p`` to the faces of ``B`` minus ``sigma`` (ball), or along a ray of
direction ``u``, ``min_a (dist to the faces of B along axis a - sigma) / |u_a|`` on
both sides. Low over the ground, where the coarse cells end, the window maxima of the
columns' tops (:mod:`.column_tops`) prove longer lengths. The tracer takes the largest
of these and Hart's ``-F / sqrt(3)``.

References
----------
Peytavie, A., Galin, E., Grosjean, J., Merillou, S. (2009). Arches: a framework for
modeling complex terrains. Computer Graphics Forum 28(2), 457-467 (section 3.3).
Bloomenthal, J., Shoemake, K. (1991). Convolution surfaces. SIGGRAPH '91.
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
from numba import njit

from arches_render.backend import variant
from arches_render.field.heightfield import line_factors
from arches_render.field.node import Node, box_distance, cell_index, clip_index, hart_bounds, opaque_float

from .column_tops import ColumnTops
from .material_stacks import SOLID, MaterialStacks

SQRT3 = math.sqrt(3.0)
#: Slope of the tie-break term ``-tilt (z - z_mid)`` (see ConvolutionSurface).
TILT = 1e-4
#: Largest ``sigma / cell`` (the footprint grows as ``(2 sigma / s + 1)^2`` columns).
MAX_SIGMA_CELLS = 2.0


def _prefix_arrays(stacks: MaterialStacks, materials):
    """Merged intervals of ``materials`` with the occupied length below each bottom."""
    off, bot, top = stacks.intervals(materials)
    length = top - bot
    cum = np.cumsum(length) - length                    # exclusive, over all columns
    col = np.repeat(np.arange(len(off) - 1), np.diff(off))
    below = cum - cum[off[col]] if len(cum) else cum    # within each column
    return off, bot, top, below


class _ColumnSums:
    """Dr.Jit arrays of one set of merged intervals and the footprint sum of section 3.3.

    The first ``n_inline`` intervals of every column are stored inline, at a fixed
    stride (``bottom, length`` pairs, zero-length padding): their share of ``C(z_hi) -
    C(z_lo)`` is ``sum_k clamp(z_hi - b_k, 0, l_k) - clamp(z_lo - b_k, 0, l_k)``, with no
    search and no offsets. Only columns with more intervals (rare: caves over caves)
    use the per-stack prefix sums and the fixed-step binary search on the rest, and
    that code is compiled only when such a column exists.
    """

    #: Intervals stored inline per column.
    INLINE = 3

    def __init__(self, stacks: MaterialStacks, materials, sigma: float):
        off, bot, top, below = _prefix_arrays(stacks, materials)
        counts = np.diff(off)
        self.n_max = int(counts.max()) if len(counts) else 0
        self.n_inline = min(self.n_max, self.INLINE)
        self.np = (off, bot, top, below)
        ncol = len(counts)
        F = max(self.n_inline, 1)
        inline = np.zeros((ncol, F, 2), dtype=np.float32)
        rank = np.arange(len(bot)) - np.repeat(off[:-1], counts)
        col = np.repeat(np.arange(ncol), counts)
        first = rank < self.n_inline
        inline[col[first], rank[first], 0] = bot[first]
        inline[col[first], rank[first], 1] = (top - bot)[first]
        self.stride = 2 * F
        self.inline = mi.Float(inline.ravel())
        self.nbytes = inline.nbytes
        # The rest: CSR of the intervals beyond the inline ones, with prefix sums.
        rest = ~first
        self.overflow = bool(rest.any())
        if self.overflow:
            r_counts = np.bincount(col[rest], minlength=ncol)
            r_off = np.concatenate([[0], np.cumsum(r_counts)])
            r_bot, r_top = bot[rest], top[rest]
            ln = r_top - r_bot
            cum = np.cumsum(ln) - ln
            r_below = cum - cum[r_off[np.repeat(np.arange(ncol), r_counts)]]
            n_rest = int(r_counts.max())
            self.steps = max(1, math.ceil(math.log2(n_rest + 1)))
            self.count_bits = self.steps
            if len(r_bot) >= 1 << (32 - self.count_bits):
                raise ValueError(f"too many intervals ({len(r_bot)}) for packed column offsets")
            # Start and count of each column's overflow packed in one word: one gather.
            packed = r_off[:-1].astype(np.uint64) | (r_counts.astype(np.uint64) << (32 - self.count_bits))
            self.packed = mi.UInt32(packed.astype(np.uint32))
            self.start_mask = (1 << (32 - self.count_bits)) - 1
            pad = lambda a: np.concatenate([a, [0.0]]).astype(np.float32)  # noqa: E731
            self.bot, self.top, self.below = mi.Float(pad(r_bot)), mi.Float(pad(r_top)), mi.Float(pad(r_below))
            self.nbytes += 4 * (ncol + 3 * (len(r_bot) + 1))

    def column_length(self, c, z_lo, z_hi, ok):
        """Occupied length of column ``c`` inside ``[z_lo, z_hi]``."""
        total = mi.Float(0.0)
        base = c * self.stride
        for k in range(self.n_inline):
            b = dr.gather(mi.Float, self.inline, base + 2 * k, ok)
            ln = dr.gather(mi.Float, self.inline, base + 2 * k + 1, ok)
            total += dr.clip(z_hi - b, 0.0, ln) - dr.clip(z_lo - b, 0.0, ln)
        if self.overflow:
            word = dr.gather(mi.UInt32, self.packed, c, ok)
            start = word & self.start_mask
            end = start + (word >> (32 - self.count_bits))
            total += self.occupied_below(start, end, z_hi, ok) - self.occupied_below(start, end, z_lo, ok)
        return total

    def occupied_below(self, start, end, z, active):
        """``C(z)``: occupied length of the overflow intervals ``[start, end)`` below ``z``."""
        lo, hi = mi.UInt32(start), mi.UInt32(end)
        for _ in range(self.steps):
            open_ = active & (lo < hi)
            mid = (lo + hi) >> 1
            b = dr.gather(mi.Float, self.bot, mid, open_)
            go_right = open_ & (b <= z)
            lo = dr.select(go_right, mid + 1, lo)
            hi = dr.select(open_ & ~go_right, mid, hi)
        has = active & (lo > start)
        k = lo - 1
        b = dr.gather(mi.Float, self.bot, k, has)
        t = dr.gather(mi.Float, self.top, k, has)
        s = dr.gather(mi.Float, self.below, k, has)
        return dr.select(has, s + dr.minimum(z - b, t - b), 0.0)


class _Footprint:
    """Columns under the kernel cube and their overlap lengths (in cells)."""

    def __init__(self, node, p):
        # Points beyond the grid by more than the kernel keep no column either way; the
        # clip keeps far and NaN points' column indices inside the integers (clip_index).
        u = clip_index((p.x - node._x0) * node._inv_s, -node.K - 1.0, node.nx + node.K + 1.0)
        v = clip_index((p.y - node._y0) * node._inv_s, -node.K - 1.0, node.ny + node.K + 1.0)
        r = node._r
        i0 = mi.Int32(dr.floor(u - r))
        j0 = mi.Int32(dr.floor(v - r))
        self.cols_x, self.cols_y = [], []
        for a in range(node.K):
            i = i0 + a
            fi = mi.Float(i)
            w = dr.clip(dr.minimum(u + r, fi + 1.0) - dr.maximum(u - r, fi), 0.0, 1.0)
            self.cols_x.append((i, w, (i >= 0) & (i < node.nx) & (w > 0.0)))
        for b in range(node.K):
            j = j0 + b
            fj = mi.Float(j)
            w = dr.clip(dr.minimum(v + r, fj + 1.0) - dr.maximum(v - r, fj), 0.0, 1.0)
            self.cols_y.append((j, w, (j >= 0) & (j < node.ny) & (w > 0.0)))

    def integral(self, node, sums: _ColumnSums, z_lo, z_hi):
        """``sum w_x w_y (C(z_hi) - C(z_lo))`` in cell^2 metres."""
        total = mi.Float(0.0)
        for j, wy, oky in self.cols_y:
            for i, wx, okx in self.cols_x:
                ok = okx & oky
                c = mi.UInt32(dr.select(ok, j * node.nx + i, 0))
                total += dr.select(ok, wx * wy * sums.column_length(c, z_lo, z_hi, ok), 0.0)
        return total


class ConvolutionSurface(Node):
    """The convolution surface of material stacks as a field node (see module docstring).

    Parameters
    ----------
    stacks : MaterialStacks
    sigma : float, optional
        Half-side ``sigma`` of the kernel cube in metres, in ``[s / 4, 2 s]``
        (``s`` the cell size); default ``s / 2``: the cube then covers 2 x 2 columns and
        the surface of a heightfield-like stack grid is its bilinear interpolant.
    materials : sequence of int
        Material ids of the skeleton (default :data:`SOLID`).
    """

    kind = "layers"
    unit_falloff = False

    # Tie-break: a layer (or an air gap) thinner than 2 sigma that lies inside the kernel
    # cube leaves F flat (all six faces see the same occupancy), and a flat F near 0 is a
    # hit without a normal (NaN shading). The node returns F - tilt (z - z_mid), tilt =
    # 1e-4 and the offset clamped a little beyond the grid: surfaces move by at most
    # tilt_shift / |grad F| (about 1 mm for a 16 m grid), the Lipschitz bound becomes
    # sqrt(3) + tilt, and tilt = 0 gives the paper's field exactly (tests compare both).

    def __init__(self, stacks: MaterialStacks, sigma=None, materials=SOLID, tilt=TILT):
        variant()
        s = stacks.cell
        sigma = 0.5 * s if sigma is None else float(sigma)
        if not (0.25 * s <= sigma <= MAX_SIGMA_CELLS * s):
            raise ValueError(f"sigma must be in [{0.25 * s:g}, {MAX_SIGMA_CELLS * s:g}] m "
                             f"(a quarter to two cells; got {sigma:g})")
        self.stacks = stacks
        self.sigma = sigma
        self.materials = tuple(int(m) for m in materials)
        self.nx, self.ny = stacks.nx, stacks.ny
        self.K = math.ceil(2.0 * sigma / s - 1e-9) + 1
        self.sums = _ColumnSums(stacks, self.materials, sigma)
        x0, y0, z0 = stacks.origin
        self._x0, self._y0 = opaque_float(x0), opaque_float(y0)
        self._inv_s = opaque_float(1.0 / s)
        self._r = opaque_float(sigma / s)
        self._sigma = opaque_float(sigma)
        z_lo, z_hi = stacks.z_range
        self.tilt = float(tilt)
        self._tilt = opaque_float(self.tilt)
        self._z_mid = opaque_float(0.5 * (z_lo + z_hi))
        # The term is clamped beyond the grid (plus the kernel and a margin), so it
        # never exceeds tilt_shift and bounds() stays true far away.
        self.half_np = 0.5 * (z_hi - z_lo) + 2.0 * sigma + 1.0
        self._half = opaque_float(self.half_np)
        self.tilt_shift = self.tilt * self.half_np
        # V in cell^2 m; F = V s^2 / (4 sigma^2) - sigma.
        self._scale = opaque_float(s * s / (4.0 * sigma * sigma))
        off, bot, top, _ = self.sums.np
        if len(bot):
            self._box = (np.array([x0, y0, float(bot.min())]),
                         np.array([x0 + stacks.nx * s, y0 + stacks.ny * s, float(top.max())]))
        else:
            self._box = (np.array([x0, y0, z0]), np.array([x0, y0, z0]))
        self._coarse = _CoarseDistance(self.sums.np, stacks, sigma)
        self._tops = ColumnTops(off, top, stacks, sigma)
        self._bounds_op = tuple([opaque_float(v) for v in b] for b in self.bounds())

    @property
    def fast_path_fractions(self) -> dict:
        """Shares of the coarse cells that skip the exact integral: ``{'empty', 'full'}``."""
        return dict(self._coarse.fractions)

    # -------------------------------------------------------------- evaluation
    def _exact(self, p):
        fp = _Footprint(self, p)
        F = fp.integral(self, self.sums, p.z - self._sigma, p.z + self._sigma) * self._scale - self._sigma
        return F - self._tie(p)

    def _tie(self, p):
        return self._tilt * dr.clip(p.z - self._z_mid, -self._half, self._half)

    def _flat(self, p, code):
        return code * self._sigma - self._tie(p)

    def cpu_eval(self, points):
        """The node's value on numpy points (float64, CPU), tie-break included."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        z_mid = 0.5 * sum(self.stacks.z_range)
        tie = self.tilt * np.clip(pts[:, 2] - z_mid, -self.half_np, self.half_np)
        return paper_field(self.stacks, pts, self.sigma, self.materials) * self.sigma - tie

    def _value(self, p, code):
        # Where the coarse grid proves the cube empty (code -1) or full (+1) the value is
        # exactly -sigma or +sigma; packets without any other lane skip the column sums.
        if not dr.flag(dr.JitFlag.SymbolicScope):
            # Evaluated mode: compressing the lanes would cost more than it saves.
            return dr.select(code == 0.0, self._exact(p), self._flat(p, code))
        return dr.if_stmt((p, code), code == 0.0, lambda p, code: self._exact(p),
                          lambda p, code: self._flat(p, code), label="layers")

    def eval(self, p):
        code, _ = self._coarse.lookup(p)
        return self._value(p, code)

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        code, S = self._coarse.lookup(p)
        f = self._value(p, code)
        hart = hart_bounds(f, levels, self.lipschitz)
        # With the tilt, F >= -c needs V > 0 only while c + tilt_shift < sigma: matter
        # in the point's cube, so the point lies in the empty box of the coarse grid's
        # distance transform or in bounds() (matter's box grown by sigma), whose
        # distance holds outside the grid, where the clamped cells say nothing.
        free = dr.maximum(self._coarse.free_distance(p, S, self._sigma, direction),
                          box_distance(p, *self._bounds_op))
        # Low over the ground the coarse cells end: the columns' tops reach further.
        free = dr.maximum(free, self._tops.free_length(p, line_factors(direction)))
        ds = tuple(dr.maximum(h, dr.select(self._sigma > c + self.tilt_shift, dr.maximum(free, 0.0), 0.0))
                   for h, c in zip(hart, levels))
        return f, ds

    def bounds(self):
        lo, hi = self._box
        return lo - self.sigma, hi + self.sigma

    @property
    def lipschitz(self):
        return SQRT3 + self.tilt

    @property
    def cost(self):
        return 2.0 * self.K * self.K

    def nbytes(self):
        return 64 + self.sums.nbytes + self._coarse.nbytes + self._tops.nbytes

    def __repr__(self):
        return f"ConvolutionSurface({self.stacks!r}, sigma={self.sigma:g})"


class MaterialRatio(Node):
    """Local ratio of some materials to the ground, for the material blending of section 6.

    ``r(p) = V_A(p) / V_G(p)``: the volume of the materials ``A`` (e.g. sand) over the
    volume of the ground materials ``G`` inside the cube of half-side ``sigma`` around
    ``p`` (0 where the cube holds no ground). It is a shading mask, not a solid: use it
    in a triplanar material's ``masks`` so that a layer's coverage follows the ratio.

    Parameters
    ----------
    stacks : MaterialStacks
    materials : sequence of int
        The materials ``A`` whose share is returned.
    sigma : float, optional
        Half-side of the averaging cube (default one cell, at most 2 cells).
    ground : sequence of int
        The materials ``G`` (default :data:`SOLID`).
    """

    kind = "layers_ratio"

    def __init__(self, stacks: MaterialStacks, materials, sigma=None, ground=SOLID):
        variant()
        s = stacks.cell
        sigma = s if sigma is None else float(sigma)
        if not (0.25 * s <= sigma <= MAX_SIGMA_CELLS * s):
            raise ValueError(f"sigma must be in [{0.25 * s:g}, {MAX_SIGMA_CELLS * s:g}] m (got {sigma:g})")
        self.stacks, self.sigma = stacks, sigma
        self.nx, self.ny = stacks.nx, stacks.ny
        self.K = math.ceil(2.0 * sigma / s - 1e-9) + 1
        self.part = _ColumnSums(stacks, tuple(int(m) for m in materials), sigma)
        self.whole = _ColumnSums(stacks, tuple(int(m) for m in ground), sigma)
        x0, y0, _ = stacks.origin
        self._x0, self._y0 = opaque_float(x0), opaque_float(y0)
        self._inv_s = opaque_float(1.0 / s)
        self._r = opaque_float(sigma / s)
        self._sigma = opaque_float(sigma)

    def eval(self, p):
        fp = _Footprint(self, p)
        lo, hi = p.z - self._sigma, p.z + self._sigma
        a = fp.integral(self, self.part, lo, hi)
        g = fp.integral(self, self.whole, lo, hi)
        return dr.select(g > 0.0, dr.clip(a / dr.maximum(g, 1e-30), 0.0, 1.0), 0.0)

    def bounds(self):
        x0, y0, x1, y1 = self.stacks.extent
        z0, z1 = self.stacks.z_range
        return np.array([x0, y0, z0]), np.array([x1, y1, z1])

    @property
    def lipschitz(self):
        # A ratio has no finite bound where the ground volume vanishes; never traced.
        return math.inf

    def nbytes(self):
        return 64 + self.part.nbytes + self.whole.nbytes


class _CoarseDistance:
    """Coarse cells: chessboard distances to matter (empty cells) and to non-full cells.

    One float per cell: ``S = D_empty`` in a cell touched by no matter, else
    ``-D_full`` (the chessboard distance to the nearest cell not entirely solid; 0 in a
    partly solid cell). A kernel cube around a point of the cell spans at most ``m =
    ceil(sigma / c)`` cells each way, so ``S >= m + 1`` proves it empty and
    ``S <= -(m + 1)`` proves it full.
    """

    def __init__(self, arrays, stacks: MaterialStacks, sigma, max_cells=1 << 21):
        from scipy.ndimage import distance_transform_cdt
        off, bot, top, _ = arrays
        x0, y0, z0 = stacks.origin
        z1 = stacks.z_range[1]
        s = stacks.cell
        # Roughly cubic cells of k columns, at most max_cells of them.
        k = 1
        while True:
            c = k * s
            res = (math.ceil(stacks.nx / k), math.ceil(stacks.ny / k), max(1, math.ceil((z1 - z0) / c)))
            if res[0] * res[1] * res[2] <= max_cells:
                break
            k += 1
        self.res, self.c = res, c
        occ, full = _mark_cells(off, bot, top, stacks.nx, stacks.ny, k, z0, c, res[0], res[1], res[2])
        big = np.float32(1e4)
        d_empty = distance_transform_cdt(~occ, metric="chessboard").astype(np.float32) if occ.any() \
            else np.full(occ.shape, big, dtype=np.float32)
        # Outside the grid there is no matter: pad with non-full cells.
        d_full = distance_transform_cdt(np.pad(full, 1), metric="chessboard")[1:-1, 1:-1, 1:-1]
        d_full = d_full.astype(np.float32)
        S = np.where(occ, -d_full, d_empty)
        m = math.ceil(sigma / c - 1e-9)
        code = np.where(S >= m + 1, -1.0, np.where(S <= -(m + 1), 1.0, 0.0)).astype(np.float32)
        # Two floats per cell, gathered together: the fast-path code and S.
        self._grid = mi.Float(np.stack([code, S], axis=-1).ravel())
        self._g0 = [opaque_float(v) for v in (x0, y0, z0)]
        self._c = opaque_float(c)
        self._inv_c = opaque_float(1.0 / c)
        self.nbytes = S.size * 8
        self.fractions = {"empty": float((code < 0).mean()), "full": float((code > 0).mean())}

    def lookup(self, p):
        """``(code, S)`` of the cell of ``p`` (clamped to the grid), plus the cell data."""
        idx, rel = [], []
        for a, n in enumerate(self.res):
            q = (p[a] - self._g0[a]) * self._inv_c
            i = cell_index(q, n, mi.Int32)
            idx.append(i)
            rel.append(q - mi.Float(i))
        cell = mi.UInt32((idx[2] * self.res[1] + idx[1]) * self.res[0] + idx[0])
        code = dr.gather(mi.Float, self._grid, cell * 2)
        S = dr.gather(mi.Float, self._grid, cell * 2 + 1)
        # Outside the grid the clamped cell says nothing about p's own cube.
        inside = (rel[0] >= 0.0) & (rel[0] <= 1.0) & (rel[1] >= 0.0) & (rel[1] <= 1.0) \
            & (rel[2] >= 0.0) & (rel[2] <= 1.0)
        return dr.select(inside, code, 0.0), (S, rel)

    def free_distance(self, p, S_rel, shrink, direction=None):
        """Distance from ``p`` to the faces of its empty box ``B`` shrunk by ``shrink`` on
        every side (ball, or along a line; negative outside the shrunk box)."""
        S, rel = S_rel
        reach = dr.maximum(S, 0.0) - 1.0
        d = None
        for a in range(3):
            # Distance to the faces of B = [i - (D - 1), i + D) cells along axis a, less
            # the shrink before the line's slope divides it: a line nearly parallel to a
            # face may stay within the shrink of it all along (the shrink taken after
            # the division granted 0.16 m to a point whose cube held matter).
            side = dr.minimum(rel[a] + reach, reach + 1.0 - rel[a]) * self._c - shrink
            if direction is not None:
                side = side * dr.rcp(dr.maximum(dr.abs(direction[a]), 1e-7))
            d = side if d is None else dr.minimum(d, side)
        return d


@njit(cache=True)
def _mark_cells(off, bot, top, nx, ny, k, z0, c, rx, ry, rz):
    """Coarse cells touched by matter, and cells entirely solid."""
    occ = np.zeros((rz, ry, rx), dtype=np.bool_)
    # Occupied length of every column inside every coarse z-slab.
    fill = np.zeros((rz, ry, rx), dtype=np.float64)
    for j in range(ny):
        for i in range(nx):
            col = j * nx + i
            for q in range(off[col], off[col + 1]):
                a = int(np.floor((bot[q] - z0) / c))
                b = int(np.floor((top[q] - z0) / c))
                a = max(0, min(rz - 1, a))
                b = max(0, min(rz - 1, b))
                for z in range(a, b + 1):
                    occ[z, j // k, i // k] = True
                    lo = max(bot[q], z0 + z * c)
                    hi = min(top[q], z0 + (z + 1) * c)
                    if hi > lo:
                        fill[z, j // k, i // k] += (hi - lo)
    # Full: every one of the k x k columns (all inside the grid) filled over the slab.
    full = np.zeros((rz, ry, rx), dtype=np.bool_)
    for z in range(rz):
        for cj in range(ry):
            for ci in range(rx):
                if (ci + 1) * k <= nx and (cj + 1) * k <= ny and z0 + (z + 1) * c <= z0 + rz * c:
                    full[z, cj, ci] = fill[z, cj, ci] >= k * k * c * (1.0 - 1e-6)
    return occ, full


# ------------------------------------------------------------------ CPU version
def paper_field(stacks: MaterialStacks, points, sigma=None, materials=SOLID):
    """The paper's ``f = V_M / (4 sigma^3) - 1`` on numpy points (float64, CPU).

    Parameters
    ----------
    stacks : MaterialStacks
    points : numpy.ndarray
        ``(N, 3)`` positions.
    sigma : float, optional
        Kernel half-side (default half the cell size, as :class:`ConvolutionSurface`).
    materials : sequence of int

    Returns
    -------
    numpy.ndarray
        ``(N,)`` values in ``[-1, 1]``; :class:`ConvolutionSurface` returns ``sigma f``.
    """
    sigma = 0.5 * stacks.cell if sigma is None else float(sigma)
    off, bot, top, below = _prefix_arrays(stacks, materials)
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    x0, y0, _ = stacks.origin
    V = _volume_cpu(off, bot, top, below, stacks.nx, stacks.ny, x0, y0, stacks.cell, sigma, pts)
    return V / (4.0 * sigma ** 3) - 1.0


@njit(cache=True)
def _occupied_below_cpu(bot, top, below, a, b, z):
    lo, hi = a, b
    while lo < hi:
        mid = (lo + hi) >> 1
        if bot[mid] <= z:
            lo = mid + 1
        else:
            hi = mid
    if lo == a:
        return 0.0
    k = lo - 1
    return below[k] + min(z - bot[k], top[k] - bot[k])


@njit(cache=True)
def _volume_cpu(off, bot, top, below, nx, ny, x0, y0, s, sigma, pts):
    out = np.empty(len(pts))
    for n in range(len(pts)):
        x, y, z = pts[n, 0], pts[n, 1], pts[n, 2]
        xa, xb, ya, yb = x - sigma, x + sigma, y - sigma, y + sigma
        i0 = max(0, int(np.floor((xa - x0) / s)))
        i1 = min(nx - 1, int(np.floor((xb - x0) / s)))
        j0 = max(0, int(np.floor((ya - y0) / s)))
        j1 = min(ny - 1, int(np.floor((yb - y0) / s)))
        v = 0.0
        for j in range(j0, j1 + 1):
            wy = min(yb, y0 + (j + 1) * s) - max(ya, y0 + j * s)
            if wy <= 0:
                continue
            for i in range(i0, i1 + 1):
                wx = min(xb, x0 + (i + 1) * s) - max(xa, x0 + i * s)
                if wx <= 0:
                    continue
                c = j * nx + i
                a, b = off[c], off[c + 1]
                ln = (_occupied_below_cpu(bot, top, below, a, b, z + sigma)
                      - _occupied_below_cpu(bot, top, below, a, b, z - sigma))
                v += wx * wy * ln
        out[n] = v
    return out
