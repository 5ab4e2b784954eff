"""Second-order free lengths along a ray above an implicit heightfield's elevation.

Why. A ray that leaves the ground (a shadow or bounce ray, a camera ray grazing a
slope) sees ``v = h(x, y) - z`` grow at the rate it climbs, ``sin`` of its angle to
the ground, often a few tenths. Hart's bound ``-v / L_h`` divides by the slope bound of
the whole elevation, grid plus fBm (``L_h ~ 4`` on an amplified canyon), so every step
grows the clearance by a few per cent and a ray crawls for a hundred steps before
it is a metre off the ground. Here the bound follows what the elevation does along
*this* line, from its derivative at the point and how fast that derivative can
change, so a ray that climbs away steps in proportion to how fast it climbs.

The bound. On the line ``p + s u`` (``|u| = 1``, horizontal part ``u_xy``) let
``g(s) = h(p_xy + s u_xy) - p_z - s u_z``, so ``g(0) = v``. With
``h = H + B + w_t a F`` (bilinear grid, elevation primitives, the fBm ``F`` faded by the
taper ``w_t`` towards the tile's border; :mod:`.implicit_heightfield`), for ``|s| <= rho``:

* grid: ``H' = grad H . u_xy`` lies in ``u_x [Hx_lo, Hx_hi] + u_y [Hy_lo, Hy_hi]``, the
  range of the bilinear patches' partial derivatives over the 3x3 cells around
  ``p``'s (a patch's ``dH/dx`` is a convex combination of its two row differences);
  the 3x3 cells hold the horizontal disc of one cell edge, so
  ``rho <= cell / |u_xy|``; cells on the grid's border widen their range to 0, the
  derivative of the clamped lookup outside;
* elevation primitives: ``|B'| <= L_B |u_xy|`` (their slope bound);
* fBm: ``(w_t a F)' = w_t' a F + w_t (Phi + Fw)``, with ``Fw = sum_k w_k o_k'`` (octave
  weights ``w_k`` of the footprint, :mod:`arches_render.field.lod`) and ``Phi = sum_k
  w_k' o_k`` the fade of the weights. At ``s = 0`` the code evaluates
  ``A0 = w_t(0) Fw(0)`` exactly (:func:`~arches_render.field.noise.fbm_gradient`).
  Then ``|w_t' a F| <= 1.5 |u_xy| N_a / taper`` (``N_a`` the fBm's range in metres;
  0 where the horizontal disc of the ball misses the fade band, ``w_t`` constant there),
  ``|Phi| <= r Q_n`` (the fade's slope, ``r`` the cone's rate), and

      |w_t(s) Fw(s) - A0| <= |s| (1.5 |u_xy| / taper) S_n |u_xy| + |Fw(s) - Fw(0)|,
      |Fw(s) - Fw(0)| <= |s| (a C_n |u_xy|^2 / lambda^2 + S_n |u_xy| r l / (fp ln l)),

  ``S_n`` the slope bound of the first ``n`` octaves (all that can act within
  ``rho_lod = fp (1 - 1/l) / r``, where the footprint stays above ``fp / l``: so the
  level moves by at most ``r |s| l / (fp ln l)``, bounding the weights' change) and
  ``C_n`` their curvature bound along a horizontal line
  (:func:`~arches_render.field.noise.fbm_curvature`). So ``rho <= rho_lod``.

Together ``g'(s)`` lies in ``[D_lo - K |s|, D_hi + K |s|]`` (the exact derivative at
``p``, widened by the first-order slack ``m0``, and the growth ``K`` above) and in the
first-order range ``[E_lo, E_hi]`` (the grid's range plus the extras' slope bounds).
Both sides of the line are then bounded by ``|g(s) - v| <= G(|s|)`` with

    G(s) = int_0^s min(B0 + K x, B1) dx,   B0 = max(D_hi, -D_lo),  B1 = max(E_hi, -E_lo),

and ``g < -c'`` on ``|s| < min(rho, G^-1(-v - c'))``: a two-sided free length, as the
over-relaxed march needs (:mod:`arches_render.render.march`). ``G^-1`` is the root
of a quadratic while ``B0 + K s < B1`` and linear after.

Ahead. On the ray's own side (``0 <= s <= rho``) only the upper ends count:
``g'(s) <= min(D + K s, E)`` with ``D = min(D_hi, E_hi)``, ``E = E_hi``, so
``g(s) <= v + G+(s)``, ``G+(s) = int_0^s min(D + K x, E) dx``, and ``g < -c'`` on
``0 < s < min(rho, d)`` with ``d`` the first root of ``G+(s) = gap = -v - c' > 0``: the
positive root of ``K s^2 / 2 + D s = gap`` while ``s <= s1 = (E - D) / K``, else
``s1 + (gap - G+(s1)) / E`` (none when ``E <= 0``). For a ray that climbs away from the
ground ``D < 0``, and ``d >= 2 |D| / K`` however small the gap: the two-sided length,
bounded by ``max(D_hi, -D_lo) >= |D_lo|``, is ~``gap / |g'|``, ~0 where the ray starts.
:func:`arches_render.field.node.one_sided` says when a tracer may use it.

Within the cell. The grid's range over 3x3 cells is what a wall next to the point
costs every ray near it: a ray grazing a flat ledge one cell from a cliff takes the
cliff's slope (coastal cliff: ``B0 = 20`` where ``g' = 0.3``, 20 times too short a
step). Inside the bilinear cell under ``p`` the grid is exact along the line: with local
coordinates ``(fu, fv)``, corners ``h00 .. h11`` and ``c = h11 - h10 - h01 + h00``,

    H(p + s u) = H(p) + H1 s + H2 s^2,
    H1 = u_x Hx(p) + u_y Hy(p),   H2 = u_x u_y c / (dx dy),

(a bilinear function is quadratic along a line), so on the part of the line inside that
cell, ``|s| <= knee_c`` (``0 <= s <= knee_c_ahead`` ahead), ``g'(s)`` lies in
``[Dc_lo - Kc |s|, Dc_hi + Kc |s|]``, with the exact ``H1`` in place of the grid's range and
``Kc = K + 2 |H2|``; beyond the cell's side, up to ``rho``, the first-order ranges
``B1`` and ``E`` still hold. So ``G`` is the integral of ``B0c + Kc x`` up to the knee and of
``B1`` after it. Both bounds hold, and a free length is the larger of the two; points
outside the grid (the clamped lookup) have ``knee_c = 0``.

References
----------
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
Galin, E., Guérin, E., Paris, A., Peytavie, A. (2020). Segment tracing using local
Lipschitz bounds. Computer Graphics Forum 39(2) (bounds along the ray's own segment
instead of a ball).
"""

from __future__ import annotations

from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render.field.lod import select_table
from arches_render.field.noise import fbm_curvature, fbm_lipschitz, fbm_range
from arches_render.field.packed_columns import gather_columns, pack_columns
from arches_render.field.window_filters import window_max, window_min

#: ``max |d/du smoothstep(u)|``: the taper weight is ``1.5 / taper``-Lipschitz.
TAPER_SLOPE = 1.5

#: An fBm whose slope bound is at most this is *gentle*: lines take its derivative at
#: that bound instead of the exact one at the point (``A0``), which costs a gradient of
#: every octave (the step's evaluation 48 -> 23 ns a point on 2 cores). Measured
#: (field/mesh, 160x90, 8 spp, gentle or not): sea cliffs (slope bound 0.03) and the NM
#: canyon (0.33) the same steps, 10-17 % faster; floating islands (0.37) even; the arch
#: bridge (0.80) and Jacksboro (2.6) 6 and 20 % slower (up to 25 % more steps), the
#: canyon overhangs (2.3) even. The bound lies between those.
GENTLE_FBM_SLOPE = 0.5


class LineTerms(NamedTuple):
    """Bounds of ``dv/ds`` on a ray's line within ``|s| <= rho`` (module docstring).

    Both sides: ``|dv/ds| <= min(B0 + K |s|, B1)``. Ahead (``s >= 0``):
    ``dv/ds <= min(D + K s, E)``, ``D <= E``.
    """

    B0: object
    B1: object
    K: object
    rho: object
    D: object
    E: object
    #: Within the bilinear cell under the point (module docstring, "Within the cell"):
    #: ``|dv/ds| <= B0c + Kc |s|`` for ``|s| <= knee_c`` and ``dv/ds <= Dc + Kc s`` for
    #: ``0 <= s <= knee_c_ahead``; ``B1`` and ``E`` hold beyond, up to ``rho``.
    B0c: object = None
    Kc: object = None
    knee_c: object = None
    Dc: object = None
    knee_c_ahead: object = None


def grid_derivative_ranges(H: np.ndarray, dx: float, dy: float) -> list[np.ndarray]:
    """``(Hx_lo, Hx_hi, Hy_lo, Hy_hi)`` per sample ``(j, i)``: the range of the bilinear
    interpolant's partial derivatives over the 3x3 cells around cell ``(j, i)``
    (module docstring; cells on the border include 0), flattened like the heights
    (the last row and column repeat the ones before, as the cell lookup clamps).

    Parameters
    ----------
    H : numpy.ndarray
        ``(ny, nx)`` elevations.
    dx, dy : float
        Sample spacing.

    Returns
    -------
    list of numpy.ndarray
        Four float32 arrays of ``ny * nx``, rounded outwards.
    """
    H = np.asarray(H, dtype=np.float64)
    rows = (np.diff(H[:-1], axis=1) / dx, np.diff(H[1:], axis=1) / dx)      # dH/dx, bottom and top
    cols = (np.diff(H[:, :-1], axis=0) / dy, np.diff(H[:, 1:], axis=0) / dy)  # dH/dy, left and right
    out = []
    for a, b in (rows, cols):
        lo = window_min(np.minimum(a, b), 3)
        hi = window_max(np.maximum(a, b), 3)
        for arr, op in ((lo, np.minimum), (hi, np.maximum)):
            for sl in ((0, slice(None)), (-1, slice(None)), (slice(None), 0), (slice(None), -1)):
                arr[sl] = op(arr[sl], 0.0)
            full = np.zeros_like(H)
            full[:-1, :-1] = arr
            full[-1, :-1], full[:, -1] = full[-2, :-1], full[:, -2]
            # float32 storage must not narrow the range.
            f32 = full.astype(np.float32)
            f32 = np.where(f32 < full, np.nextafter(f32, np.float32(np.inf)), f32) if op is np.maximum else \
                np.where(f32 > full, np.nextafter(f32, np.float32(-np.inf)), f32)
            out.append(f32.ravel())
    return out


class ElevationLineBound:
    """Free lengths along lines above an implicit heightfield (module docstring).

    Parameters
    ----------
    hf : ImplicitHeightfield
        The terrain; its grid, elevation primitives and amplification are read once.
    """

    def __init__(self, hf):
        self.hf = hf
        self.cell = float(min(hf.dx, hf.dy))
        # A sample's four ranges side by side: one packet gather.
        self._ranges, _ = pack_columns(grid_derivative_ranges(hf.heights_np, hf.dx, hf.dy))
        self.bump_slope = float(hf.bumps.lipschitz) if hf.bumps is not None else 0.0
        amp = hf.amp
        self.amp = amp
        self.gentle = False
        if amp is None:
            return
        # Slope and fade tables of the acting octaves: the fBm's OctaveLOD's.
        self.lod = hf._lod
        a, lam = abs(float(amp["amplitude"])), float(amp["wavelength"])
        lac, gain, octaves = float(amp["lacunarity"]), float(amp["gain"]), int(amp["octaves"])
        #: Curvature bound of the first n = 0..octaves octaves along a horizontal line (1/m).
        self._C = [a / lam ** 2 * c for c in fbm_curvature(octaves, lac, gain)]
        self.range_m = a * fbm_range(octaves, gain)
        self.slope_full = a * fbm_lipschitz(octaves, lac, gain) / lam
        self.inv_taper = 1.0 / amp["taper"] if amp["taper"] > 0 else 0.0
        # The fade band, grown by the ball's reach: elsewhere w_t is constant.
        x0, y0, x1, y1 = hf.extent
        self.sides = tuple(float(v) for v in (x0, y0, x1, y1))
        self.band = (float(amp["border"]) - self.cell, float(amp["border"] + amp["taper"]) + self.cell)
        self.lac_over_log = lac / self.lod.log_l
        #: The fBm's slope bound is at most GENTLE_FBM_SLOPE: callers pass ``a0 = None``.
        self.gentle = self.slope_full <= GENTLE_FBM_SLOPE

    def free_lengths(self, p, u, v, k, shifts, a0, level, footprint, terms=None):
        """Two-sided free lengths of the line through the point with ``v = h - z`` along
        ``u``, to each level ``{v >= -shift}`` (``terms``: :meth:`derivative_terms` of
        the same arguments, if already computed).

        Parameters
        ----------
        p : mi.Point3f
            The point.
        u : mi.Vector3f
            Unit direction of the line.
        v : mi.Float
            ``h(p_xy) - p_z`` (the footprint field's, with a footprint).
        k : mi.UInt32
            ``p``'s cell (sample index of its lower-left corner).
        shifts : sequence of mi.Float or float
            The levels, as clearances of ``v``.
        a0 : mi.Float or None
            The fBm's exact derivative along ``u`` at ``p`` with the octave weights
            held (``A0`` of the module docstring); ``None`` without amplification.
        level : mi.Float or None
            The fBm's footprint level at ``p`` (``None``: every octave), and
        footprint : Footprint or None
            the ray's cone there.

        Returns
        -------
        list of mi.Float
        """
        terms = terms if terms is not None else self.derivative_terms(p, u, k, a0, level, footprint)
        near = _two_sided(v, shifts, terms.B0, terms.B1, terms.K, terms.rho)
        cell = _two_sided(v, shifts, terms.B0c, terms.B1, terms.Kc, terms.rho, terms.knee_c)
        return [dr.maximum(a, b) for a, b in zip(near, cell)]

    @staticmethod
    def ahead_lengths(v, shifts, terms):
        """Free lengths *ahead* on the line (``0 < s < d``; module docstring, "Ahead") to
        each level ``{v >= -shift}``, from the :class:`LineTerms` of the same line.

        Parameters
        ----------
        v : mi.Float
            ``h(p_xy) - p_z``.
        shifts : sequence of mi.Float or float
            The levels, as clearances of ``v``.
        terms : LineTerms

        Returns
        -------
        list of mi.Float
        """
        near = _ahead(v, shifts, terms.D, terms.E, terms.K, terms.rho)
        cell = _ahead(v, shifts, terms.Dc, terms.E, terms.Kc, terms.rho, terms.knee_c_ahead)
        # (dr.maximum keeps a NaN of either: it proves nothing.)
        return [dr.maximum(a, b) for a, b in zip(near, cell)]

    def derivative_terms(self, p, u, k, a0, level, footprint):
        """The :class:`LineTerms` of the line through ``p`` along ``u`` (module docstring;
        arguments as :meth:`free_lengths`)."""
        run = dr.sqrt(dr.square(u.x) + dr.square(u.y))
        xlo, xhi, ylo, yhi = gather_columns(self._ranges, k, 4, 4)
        h_lo = dr.minimum(u.x * xlo, u.x * xhi) + dr.minimum(u.y * ylo, u.y * yhi)
        h_hi = dr.maximum(u.x * xlo, u.x * xhi) + dr.maximum(u.y * ylo, u.y * yhi)
        rho = self.cell * dr.rcp(dr.maximum(run, 1e-7))
        slack = self.bump_slope * run          # first order, in both ranges
        first = mi.Float(slack)                # first-order range of the extras
        K = mi.Float(0.0)
        centre = -u.z
        if self.amp is not None:
            n = mi.Float(self.lod.octaves)
            rate = mi.Float(0.0)
            if level is not None:
                n = self.lod.acting(level)
                rate = footprint.rate
                rho = dr.minimum(rho, self.lod.ball(footprint))
            S, Q = self.lod.slope_parts(n)
            C = select_table(self._C, n)
            fade = rate * Q
            taper = TAPER_SLOPE * self.inv_taper * run
            if self.inv_taper:
                x0, y0, x1, y1 = self.sides
                edge = dr.minimum(dr.minimum(p.x - x0, x1 - p.x), dr.minimum(p.y - y0, y1 - p.y))
                taper = dr.select((edge > self.band[0]) & (edge < self.band[1]), taper, 0.0)
            first = first + S * run + taper * self.range_m + fade
            if a0 is None:
                # A gentle fBm (``gentle``): its derivative is anywhere within its first-order
                # bound, the exact one at p not worth its cost; no curvature term.
                slack = mi.Float(first)
            else:
                slack = slack + taper * self.range_m + fade
                K = C * dr.square(run) + taper * S * run
                if level is not None:
                    K = K + S * run * rate * self.lac_over_log * dr.rcp(dr.maximum(footprint.radius, 1e-30))
                centre = centre + a0
        D_lo, D_hi = h_lo + centre - slack, h_hi + centre + slack
        E_lo, E_hi = h_lo - u.z - first, h_hi - u.z + first
        B1 = dr.maximum(E_hi, -E_lo)
        B0 = dr.minimum(dr.maximum(D_hi, -D_lo), B1)
        # Within the cell (module docstring): the grid's exact derivative and curvature.
        H1, H2, back, ahead = self._cell_line(p, u)
        Dc_lo, Dc_hi = H1 + centre - slack, H1 + centre + slack
        Kc = dr.maximum(K + 2.0 * dr.abs(H2), 1e-30)
        return LineTerms(B0, B1, dr.maximum(K, 1e-30), rho, dr.minimum(D_hi, E_hi), E_hi,
                         B0c=dr.minimum(dr.maximum(Dc_hi, -Dc_lo), B1), Kc=Kc,
                         knee_c=dr.minimum(back, ahead), Dc=dr.minimum(Dc_hi, E_hi), knee_c_ahead=ahead)

    def _cell_line(self, p, u):
        """``(H1, H2, back, ahead)``: the grid along the line ``p + s u`` inside the
        bilinear cell under ``p``, ``H(p + s u) = H(p) + H1 s + H2 s^2`` (module docstring,
        "Within the cell"), for ``-back <= s <= ahead`` (both 0 outside the grid)."""
        hf = self.hf
        gx, gy = (p.x - hf._x0) * hf._inv_dx, (p.y - hf._y0) * hf._inv_dy
        inside = (gx >= 0.0) & (gx <= hf.nx - 1.0) & (gy >= 0.0) & (gy <= hf.ny - 1.0)
        h00, h10, h01, h11, fu, fv = hf.patch(p.x, p.y)
        hx = dr.lerp(h10 - h00, h11 - h01, fv) * hf._inv_dx
        hy = dr.lerp(h01 - h00, h11 - h10, fu) * hf._inv_dy
        H1 = u.x * hx + u.y * hy
        H2 = (u.x * u.y) * ((h11 - h10) - (h01 - h00)) * (hf._inv_dx * hf._inv_dy)
        # Distances along the line to the cell's sides, in grid units per metre.
        ru, rv = u.x * hf._inv_dx, u.y * hf._inv_dy

        def along(room, rate):
            # A line parallel to the side never meets it (and 0 * inf would be NaN).
            return dr.select(rate != 0.0, room * dr.rcp(dr.abs(rate)), dr.inf)

        fwd = dr.minimum(along(dr.select(ru >= 0.0, 1.0 - fu, fu), ru), along(dr.select(rv >= 0.0, 1.0 - fv, fv), rv))
        bwd = dr.minimum(along(dr.select(ru >= 0.0, fu, 1.0 - fu), ru), along(dr.select(rv >= 0.0, fv, 1.0 - fv), rv))
        # A hair inside (the float32 cell coordinates round): never past the side.
        shrink = 1.0 - 1e-4
        return (H1, H2, dr.select(inside, bwd * shrink, 0.0), dr.select(inside, fwd * shrink, 0.0))


def _two_sided(v, shifts, B0, B1, K, rho, knee=None):
    """Two-sided free lengths to each level ``{v >= -shift}`` under
    ``|dv/ds| <= min(B0 + K |s|, B1)`` on ``|s| <= rho`` (module docstring, "The bound"),
    or with a ``knee``, the first term only for ``|s| <= knee`` (and ``B1`` beyond)."""
    s1 = (B1 - B0) * dr.rcp(K)
    if knee is not None:
        s1 = dr.minimum(s1, knee)
    G1 = s1 * (B0 + 0.5 * K * s1)
    out = []
    for shift in shifts:
        gap = dr.maximum(-v - shift, 0.0)
        quad = 2.0 * gap * dr.rcp(B0 + dr.sqrt(dr.square(B0) + 2.0 * K * gap))
        lin = s1 + (gap - G1) * dr.rcp(dr.maximum(B1, 1e-30))
        d = dr.select(gap <= G1, quad, lin)
        # (A NaN proves nothing: keep it, the march treats it as such.)
        out.append(dr.minimum(d, rho))
    return out


def _ahead(v, shifts, D, E, K, rho, knee=None):
    """Free lengths ahead (``0 < s < d``) to each level ``{v >= -shift}`` under
    ``dv/ds <= min(D + K s, E)`` on ``0 <= s <= rho`` (module docstring, "Ahead"), or with
    a ``knee``, the first term only for ``s <= knee`` (and ``E`` beyond)."""
    s1 = (E - D) * dr.rcp(K)            # where D + K s meets E
    if knee is not None:
        s1 = dr.minimum(s1, knee)
    G1 = s1 * (D + 0.5 * K * s1)        # G(s1)
    out = []
    for shift in shifts:
        gap = -v - shift
        root = dr.sqrt(dr.square(D) + 2.0 * K * dr.maximum(gap, 0.0))
        # The positive root of K s^2 / 2 + D s = gap, in the form without cancellation.
        quad = dr.select(D < 0.0, (root - D) * dr.rcp(K), 2.0 * gap * dr.rcp(D + root))
        lin = dr.select(E > 0.0, s1 + (gap - G1) * dr.rcp(dr.maximum(E, 1e-30)), dr.inf)
        d = dr.select(quad <= s1, quad, lin)
        # (gap <= 0: the point is in the level set. A NaN proves nothing: kept.)
        out.append(dr.select(gap > 0.0, dr.minimum(d, rho), dr.select(dr.isnan(gap), gap, 0.0)))
    return out
