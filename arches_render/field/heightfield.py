"""Heightfield solid: the prism of ground under a bilinear 2-D elevation array.

The elevation ``h(x, y)`` is the bilinear interpolant of ``heights[j, i]`` sampled at
``x_i = x0 + i dx``, ``y_j = y0 + j dy`` (lookups outside the grid are clamped to
its edge). The solid is the ground between ``base`` and ``h`` over the extent:

    f(p) = min(h(x, y) - z, b(p)),

with ``b`` the exact signed distance of the box ``[x0, x1] x [y0, y1] x [base,
max h]`` (positive inside), so the solid is closed and bounded, like the prism
primitive of Paris et al. (2019).

Lipschitz bound: along x the bilinear interpolant's slope is a convex combination
of the slopes of the two bracketing grid rows, so ``|dh/dx| <= max |dH_x| / dx``
(likewise in y) and ``L = sqrt(1 + S_x^2 + S_y^2)``, exact for the discrete data.

Local distance bound (a sphere-tracing form of maximum mipmaps): ``M_w`` is the
maximum of the samples within ``w`` cells of each cell, so every ground point
within the horizontal radius ``R_w = w min(dx, dy)`` of ``p`` is at most ``M_w`` high.
A ball around ``p`` of radius ``min(R_w, z - M_w)`` is therefore free of ground, and

    d(p) = max(d_hart, max_w min(R_w, z - M_w(p)))

is a rigorous lower bound of the distance to the solid: a ray skimming high above
low ground steps far, where the global ``L`` alone would crawl. Along the line of
unit direction ``u`` the bound is better still: on both sides of ``p`` the line stays
inside the window for ``R_w / |u_xy|`` and above ``M_w`` for ``(z - M_w) / |u_z|``,
so the smaller of the two is free (the per-level form of maximum-mipmap
traversal, two-sided so that over-relaxed steps can be checked).

Local slopes (:meth:`Heightfield.eval_local`). In a cell the bilinear slope along x is
a convex combination of its two rows' slopes (likewise y), so ``|grad h| <= S_cell =
hypot(max_rows |dH_x| / dx, max_cols |dH_y| / dy)``; a ball of radius at most
``min(dx, dy)`` (:attr:`Heightfield.local_radius`) around a point of cell ``k`` lies in
the cells next to ``k`` (clamped lookups outside the grid repeat its edge cells), so
there ``|grad (h - z)| <= sqrt(1 + S_near^2)``, ``S_near`` the largest ``S_cell`` of the
3 x 3 cells around ``k``, and along a line of unit direction ``u`` its derivative is at
most ``S_near |u_xy| + |u_z|``. The box's distance is 1-Lipschitz, so ``f = min(h - z,
b)`` has slope at most the larger of the two. A difference that subtracts the
heightfield bounds the distance to its complement with them (a floating island's
underside: 3.35, the DEM's steepest cell, where the cells around are nearly flat).

Shading normals. The bilinear surface is only C0: its slope jumps
across every cell edge, so a normal taken from it (and every slope mask of a material:
grass below 28 degrees, scree, snow) changes abruptly there, and a few metres from the
camera the DEM's cells showed as squares of scree in the grass (Maunga Whau's
overview), where the mesh of the same field, shaded with interpolated vertex normals,
blends smoothly. Normals are therefore taken, inside a :func:`~.node.shading_normals`
block, from ``h~``, the bilinear elevation averaged over the square of
:data:`SMOOTH_WIDTH` (a quarter) of a cell centred on the point (a box filter): its gradient is the average of the bilinear gradient over
that square, continuous everywhere and within the range of the slopes around, so no
normal leans further than the surface does (a bicubic Catmull-Rom interpolant, tried
first, overshoots at the gorge's ledges: its normals turned from the camera and the
default scene's grass showed black streaks; a square of half a cell thinned the grass
on its ledges, one or two cells wide, towards their walls' slope). The square is cut by the grid lines into
at most four pieces on each of which the elevation is bilinear, and a bilinear
function's mean over a rectangle is its value at the centre: four lookups. ``|h~ - h|``
is at most an eighth of the square's edge times the largest change of slope across an
edge. Hits,
bounds and every value outside the block keep the bilinear surface.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5) (prism primitive).
Tevs, A., Ihrke, I., Seidel, H.-P. (2008). Maximum mipmaps for fast, accurate,
and scalable dynamic height field rendering. I3D '08.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .node import Node, cell_index, clip_index, jit_floats, opaque_float, shading_normals_traced
from .packed_columns import gather_columns, pack_columns
from .window_filters import window_max


#: Edge of the square over which shading normals average the bilinear slope, in cells
#: (module docstring, "Shading normals").
SMOOTH_WIDTH = 0.25

#: Largest height or extent coordinate (m), ten times Earth's radius: beyond it a value
#: is a unit error, and the slope bound computed from it would overflow float64.
MAX_COORDINATE = 6.4e7


def height_grid(heights, extent):
    """Validate the elevation grid of a heightfield node (shared by every heightfield type).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations in metres, ``ny, nx >= 2``, finite.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` in metres, ``x1 > x0``, ``y1 > y0``.

    Returns
    -------
    (numpy.ndarray, tuple)
        float64 heights and the extent as four floats.

    Raises
    ------
    ValueError
        For a grid that is not 2-D and at least 2x2, non-finite heights or an
        empty extent.
    """
    H = np.asarray(heights, dtype=np.float64)
    if H.ndim != 2 or min(H.shape) < 2:
        raise ValueError("heights must be a 2-D array of at least 2x2 samples")
    if not np.all(np.isfinite(H)):
        raise ValueError("heights contain NaN or infinite values")
    if np.abs(H).max() > MAX_COORDINATE:
        raise ValueError(f"heights must lie within +-{MAX_COORDINATE:g} m (got {np.abs(H).max():.3g})")
    x0, y0, x1, y1 = (float(v) for v in extent)
    if not all(abs(v) <= MAX_COORDINATE for v in (x0, y0, x1, y1)):
        raise ValueError(f"extent must lie within +-{MAX_COORDINATE:g} m")
    if not (x1 > x0 and y1 > y0):
        raise ValueError("extent must satisfy x1 > x0 and y1 > y0")
    return H, (x0, y0, x1, y1)


def line_factors(direction):
    """``(1 / |u_xy|, 1 / |u_z|)`` of a unit direction ``u`` (each at most 1e7), or ``None``
    without one: what :func:`window_reach` needs on a ray's line."""
    if direction is None:
        return None
    return (dr.rcp(dr.maximum(dr.sqrt(dr.square(direction.x) + dr.square(direction.y)), 1e-7)),
            dr.rcp(dr.maximum(dr.abs(direction.z), 1e-7)))


def window_reach(free, clearances, radii, line=None):
    """The free length ``free`` grown by window clearances (module docstring, "Local
    distance bound"): ``max(free, max_w min(R_w, C_w))`` for a ball, ``max(free, max_w
    min(R_w / |u_xy|, C_w / |u_z|))`` on a line (``line``: :func:`line_factors`).

    Parameters
    ----------
    free : mi.Float
        A free length already proven.
    clearances : sequence of mi.Float
        ``C_w``: how far above everything in window ``w`` the point is (less the level).
    radii : sequence
        ``R_w``: the horizontal radius each window holds around the point.
    line : (mi.Float, mi.Float), optional
        ``(1 / |u_xy|, 1 / |u_z|)`` of the ray's direction; None for a ball.

    Returns
    -------
    mi.Float
    """
    for clearance, radius in zip(clearances, radii):
        if line is None:
            reach = dr.minimum(radius, clearance)
        else:
            reach = dr.minimum(radius * line[0], clearance * line[1])
        free = dr.maximum(free, reach)
    return free


class Heightfield(Node):
    """Ground under a bilinear elevation grid (see module docstring).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations in metres, ``ny, nx >= 2``, finite.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` in metres, ``x1 > x0``, ``y1 > y0``.
    base : float, optional
        Bottom of the solid; default a skirt below the lowest sample.
    """

    kind = "heightfield"

    def __init__(self, heights, extent, base=None):
        H, (x0, y0, x1, y1) = height_grid(heights, extent)
        self.heights_np = H
        self.ny, self.nx = H.shape
        self.extent = (x0, y0, x1, y1)
        self.dx = (x1 - x0) / (self.nx - 1)
        self.dy = (y1 - y0) / (self.ny - 1)
        hmin, hmax = float(H.min()), float(H.max())
        self.base_np = float(base) if base is not None else hmin - max(1.0, 0.05 * (hmax - hmin))
        self.top_np = hmax
        sx = np.abs(np.diff(H, axis=1)).max() / self.dx
        sy = np.abs(np.diff(H, axis=0)).max() / self.dy
        self.slope_bound = float(np.hypot(sx, sy))
        self.windows = [w for w in (2, 8, 32, 128) if w < max(self.nx, self.ny)]
        # The window maxima of a sample side by side (padded to a power of two): one
        # packet gather reads them all (:func:`.packed_columns.gather_columns`).
        self._maxima, self._maxima_width = pack_columns([_window_max(H, w) for w in self.windows])
        self._radii = [opaque_float(w * min(self.dx, self.dy)) for w in self.windows]
        self._inv_L = opaque_float(1.0 / np.sqrt(1.0 + self.slope_bound ** 2))
        # Local slopes (module docstring): S_near of each cell, at its sample index.
        cell_sx = np.maximum(np.abs(np.diff(H[:-1], axis=1)), np.abs(np.diff(H[1:], axis=1))) / self.dx
        cell_sy = np.maximum(np.abs(np.diff(H[:, :-1], axis=0)), np.abs(np.diff(H[:, 1:], axis=0))) / self.dy
        near = np.zeros_like(H)
        near[:-1, :-1] = window_max(np.hypot(cell_sx, cell_sy), 3)
        self._near_slope = mi.Float(near.ravel().astype(np.float32) * np.float32(1.0 + 1e-6))
        self.local_radius = min(self.dx, self.dy)
        # Each cell's four corner samples side by side: a lookup is one packet gather
        # of 16 bytes instead of four scalar gathers (the heights, 4x).
        corners = (H[:-1, :-1], H[:-1, 1:], H[1:, :-1], H[1:, 1:])
        self._corners = jit_floats(np.stack(corners, axis=-1))
        self._x0, self._y0 = opaque_float(x0), opaque_float(y0)
        self._inv_dx, self._inv_dy = opaque_float(1.0 / self.dx), opaque_float(1.0 / self.dy)
        c = np.array([(x0 + x1) / 2, (y0 + y1) / 2, (self.base_np + hmax) / 2])
        h = np.array([(x1 - x0) / 2, (y1 - y0) / 2, (hmax - self.base_np) / 2])
        self._bc = [opaque_float(v) for v in c]
        self._bh = [opaque_float(v) for v in h]

    def patch(self, x, y):
        """The bilinear cell under ``(x, y)`` (``mi.Float`` each, clamped at the edges):
        its corner samples ``h00, h10, h01, h11`` and the local coordinates ``fu, fv``
        in ``[0, 1]``."""
        return self._patch_at((x - self._x0) * self._inv_dx, (y - self._y0) * self._inv_dy)

    def _patch_at(self, u, v):
        """:meth:`patch` at the grid coordinates ``(u, v)`` (in cells from the first sample)."""
        u = clip_index(u, 0.0, self.nx - 1.0)
        v = clip_index(v, 0.0, self.ny - 1.0)
        i = dr.minimum(mi.UInt32(u), self.nx - 2)
        j = dr.minimum(mi.UInt32(v), self.ny - 2)
        fu, fv = u - mi.Float(i), v - mi.Float(j)
        h00, h10, h01, h11 = dr.gather(mi.Vector4f, self._corners, j * (self.nx - 1) + i)
        return h00, h10, h01, h11, fu, fv

    def window_maxima(self, k):
        """The maxima ``M_w`` of every window (module docstring) at sample ``k``."""
        return gather_columns(self._maxima, k, self._maxima_width, len(self.windows))

    def height(self, x, y):
        """Bilinear elevation at ``(x, y)`` (``mi.Float`` each), clamped at the edges;
        inside a :func:`~.node.shading_normals` block the smooth elevation of
        :meth:`smooth_height` (module docstring, "Shading normals")."""
        if shading_normals_traced():
            return self.smooth_height(x, y)
        h00, h10, h01, h11, fu, fv = self.patch(x, y)
        return dr.lerp(dr.lerp(h00, h10, fu), dr.lerp(h01, h11, fu), fv)

    def smooth_height(self, x, y):
        """The bilinear elevation averaged over the square of ``SMOOTH_WIDTH`` cells
        centred on ``(x, y)`` (module docstring, "Shading normals"): C1, within the
        range of the bilinear slopes around."""
        u = (x - self._x0) * self._inv_dx - 0.5 * SMOOTH_WIDTH
        v = (y - self._y0) * self._inv_dy - 0.5 * SMOOTH_WIDTH
        h = mi.Float(0.0)
        for pu, wu in _box_pieces(u, SMOOTH_WIDTH):
            for pv, wv in _box_pieces(v, SMOOTH_WIDTH):
                h00, h10, h01, h11, fu, fv = self._patch_at(pu, pv)
                h += (wu * wv) * dr.lerp(dr.lerp(h00, h10, fu), dr.lerp(h01, h11, fu), fv)
        return h

    def smooth_slopes(self, x, y):
        """``(h_x, h_y)`` of :meth:`smooth_height`, by central differences a
        thousandth of a cell apart."""
        ex, ey = 1e-3 * self.dx, 1e-3 * self.dy
        hx = (self.smooth_height(x + ex, y) - self.smooth_height(x - ex, y)) * (0.5 / ex)
        hy = (self.smooth_height(x, y + ey) - self.smooth_height(x, y - ey)) * (0.5 / ey)
        return hx, hy

    def eval(self, p):
        return dr.minimum(self.height(p.x, p.y) - p.z, self._box(p))

    def _box(self, p):
        q = mi.Vector3f(dr.abs(p.x - self._bc[0]) - self._bh[0],
                        dr.abs(p.y - self._bc[1]) - self._bh[1],
                        dr.abs(p.z - self._bc[2]) - self._bh[2])
        return -(dr.norm(dr.maximum(q, 0.0)) + dr.minimum(dr.maximum(dr.maximum(q.x, q.y), q.z), 0.0))

    def _sample_index(self, p):
        """The sample index ``j nx + i`` of the cell under ``p`` (clamped at the edges)."""
        u = clip_index((p.x - self._x0) * self._inv_dx, 0.0, self.nx - 1.0)
        v = clip_index((p.y - self._y0) * self._inv_dy, 0.0, self.ny - 1.0)
        return dr.minimum(mi.UInt32(v), self.ny - 2) * self.nx + dr.minimum(mi.UInt32(u), self.nx - 2)

    def eval_local(self, p, levels, direction=None, footprint=None, radii=()):
        """``(f, ds, slopes)``: :meth:`eval_bounds` and, for each radius of ``radii``, a
        bound of ``|grad f|`` in the ball of that radius around ``p`` (along the line of
        ``direction`` where one is given): module docstring, "Local slopes"."""
        f, ds = self.eval_bounds(p, levels, direction, footprint)
        if not radii:
            return f, ds, ()
        S = dr.gather(mi.Float, self._near_slope, self._sample_index(p))
        if direction is None:
            near = dr.sqrt(1.0 + S * S)
        else:
            run = dr.sqrt(dr.square(direction.x) + dr.square(direction.y))
            near = dr.maximum(S * run + dr.abs(direction.z), 1.0) * (1.0 + 1e-6)
        return f, ds, tuple(dr.select(rad <= self.local_radius, near, self.lipschitz) for rad in radii)

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        # An intersection of the ground and the box: as far as the farther one.
        box = self._box(p)
        top = self.height(p.x, p.y) - p.z
        k = self._sample_index(p)
        above = [p.z - m for m in self.window_maxima(k)]
        line = line_factors(direction)
        ds = []
        for c in levels:
            d = dr.maximum(dr.maximum(-top - c, 0.0) * self._inv_L, dr.maximum(-box - c, 0.0))
            ds.append(window_reach(d, [a - c for a in above], self._radii, line))
        return dr.minimum(top, box), tuple(ds)

    def height_range(self, xlo, xhi, ylo, yhi):
        """``(h_min, h_max)`` of the bilinear elevation over the rectangles
        ``[xlo, xhi] x [ylo, yhi]`` (``mi.Float`` each), from the maximum and minimum
        pyramids (:class:`~.heightfield_mipmap.MaxMipmap`): the level whose cells
        are at least as wide as the rectangle's span of cells, where at most 2 x 2
        cells cover it (lookups outside the grid clamp to its edge, as ``height``)."""
        if getattr(self, "_pyramid", None) is None:
            from .heightfield_mipmap import MaxMipmap  # (that module imports this one)
            mm = MaxMipmap(self.heights_np)
            self._pyramid = (mm, mi.Float(mm.max_flat), mi.Float(mm.min_flat))
        mm, mx, mn = self._pyramid
        ncx, ncy = self.nx - 1, self.ny - 1

        def cell(v, v0, inv, n):
            return cell_index((v - v0) * inv, n, mi.Int32)

        i0, i1 = cell(xlo, self._x0, self._inv_dx, ncx), cell(xhi, self._x0, self._inv_dx, ncx)
        j0, j1 = cell(ylo, self._y0, self._inv_dy, ncy), cell(yhi, self._y0, self._inv_dy, ncy)
        span = dr.maximum(i1 - i0, j1 - j0)
        level = mi.Int32(0)
        for lvl in range(1, mm.levels):
            level = dr.select(span >= (1 << (lvl - 1)), lvl, level)
        offset, row = mi.UInt32(0), mi.Int32(mm.shapes[0][1])
        for lvl in range(1, mm.levels):
            offset = dr.select(level == lvl, int(mm.offsets[lvl]), offset)
            row = dr.select(level == lvl, mm.shapes[lvl][1], row)
        a0, a1, b0, b1 = i0 >> level, i1 >> level, j0 >> level, j1 >> level
        h_min, h_max = mi.Float(dr.inf), mi.Float(-dr.inf)
        for i, j in ((a0, b0), (a1, b0), (a0, b1), (a1, b1)):
            k = offset + mi.UInt32(j * row + i)
            h_min = dr.minimum(h_min, dr.gather(mi.Float, mn, k))
            h_max = dr.maximum(h_max, dr.gather(mi.Float, mx, k))
        return h_min, h_max

    def box_range(self, lo, hi):
        # min(h - z, box): h from the pyramids, the box's exact distance (1-Lipschitz)
        # at the centre plus or minus the half-diagonal.
        h_min, h_max = self.height_range(lo.x, hi.x, lo.y, hi.y)
        b = self._box((lo + hi) * 0.5)
        R = dr.norm(hi - lo) * 0.5
        return dr.minimum(h_min - hi.z, b - R), dr.minimum(h_max - lo.z, b + R)

    def bounds(self):
        x0, y0, x1, y1 = self.extent
        return np.array([x0, y0, self.base_np]), np.array([x1, y1, self.top_np])

    @property
    def lipschitz(self):
        return float(np.sqrt(1.0 + self.slope_bound ** 2))

    @property
    def cost(self):
        return 3.0

    def nbytes(self):
        return 64 + self.heights_np.size * 4 * (1 + len(self.windows))


def _box_pieces(a, width):
    """The parts of the interval ``[a, a + width]`` (grid coordinates, ``width <= 1``)
    either side of the integer ``s = floor(a) + 1``: their midpoints and their shares
    of the interval, ``((m0, w0), (m1, w1))``. On each part the clamped bilinear
    elevation is linear, so its mean is its value at the midpoint."""
    b = a + width
    e = dr.minimum(dr.floor(a) + 1.0, b)
    w0 = (e - a) * (1.0 / width)
    return ((a + e) * 0.5, w0), ((e + b) * 0.5, 1.0 - w0)


def _window_max(H: np.ndarray, w: int) -> np.ndarray:
    """Max of the samples a bilinear cell within ``w`` cells of each cell can touch.

    Cell ``(j, i)`` spans samples ``i..i+1``; cells within ``w`` span samples
    ``i-w..i+w+1``; a centred window of ``2w + 3`` samples covers them.
    """
    return window_max(H, 2 * w + 3)
