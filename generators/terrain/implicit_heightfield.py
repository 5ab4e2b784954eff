"""Heightfield implicitization: the compact terrain primitive of Paris et al. (2019, Sec. 5.1).

Elevation. ``h(x, y)`` is the bilinear interpolant of a DEM grid (the lookup of
:class:`arches_render.field.Heightfield`, which this class extends), plus optional
*elevation primitives* with compact falloff and an optional fBm *amplification*:

    h(x, y) = H(x, y) + sum_i h_i g(|(x, y) - c_i| / R_i) + w(x, y) a fbm((x, y, 0) / lambda).

The fBm is the sub-cell detail of :mod:`.detail` (its octaves continue the DEM's
spectrum). ``w`` fades it out towards the tile's border: with ``e`` the distance to
the nearest side of ``Omega``, ``w = smoothstep((e - border) / taper)`` (``w = 1``
everywhere when ``taper = 0``), so that the surface meets the far field's frame
(:mod:`.far_field`), which holds the DEM alone, without a step.

The elevation primitives are a :class:`~.skeletal_set.SkeletalSet` of points in the
plane ``z = 0`` (so thousands of them stay one grid lookup), evaluated at ``(x, y, 0)``.

Field. With ``v(p) = h(p_xy) - p_z`` the signed vertical distance (positive below
the ground) and the odd cubic sigmoid ``s`` of :mod:`.falloff` (the paper's
``sigma = T + s``, shifted by ``-T`` so that the surface is ``f = 0`` as everywhere in
arches-render):

    f_T(p) = s(v(p))                          in [-T, T],
    f_P(p) = T (2 g(d(p, P) / R) - 1)         in [-T, T],
    f(p)   = min(f_T(p), f_P(p)).

``P = (Omega shrunk by R) x [base, max h]`` is the prism and ``d(p, P)`` the Euclidean
distance to it (0 inside). The paper says ``f_P`` "equals T inside the prism"; in
its units that would make ``f <= T`` everywhere and leave no interior, so we read
it as ``2T g`` (range ``[0, 2T]``, like ``f_T``): the surface of the prism then lies
``r0 = R sqrt(1 - 2^(-1/3)) ~= 0.454 R`` outside ``P``, within ``Omega``, and the
input heightfield is embedded exactly over ``Omega`` shrunk by ``R`` (the paper's
guarantee). Deep inside the terrain ``f = T``: a carving primitive must reach an
energy above ``T`` (see :func:`.falloff.energy_for_radius`).

Near the surface ``f ~ v`` (``s'(0) = 1``), so values are metres of vertical distance
there and other metre-valued nodes combine with it. The default ``T = R / 2`` makes
``s`` the quadratic ``x - x^2 / (2R)`` with slope at most 1.

How this relates to :class:`arches_render.field.Heightfield`: that node is the same
prism solid with distance-like values ``min(h - z, box)`` that grow without bound
inside; this one has the paper's *compact* range, which is what carving and
blending with energies need. Both share the DEM lookup, the slope bound and the
maximum-mipmap tables.

Lipschitz bound: ``L_h = sqrt(1 + S^2)`` with ``S`` the slope bound of ``h`` (grid slope
bound of the parent + the elevation primitives' bound + the fBm's; with the fade,
``|grad (w a fbm)| <= a L_fbm / lambda + 1.5 a N_fbm / taper``, ``N_fbm`` the fBm's
range bound), so
``L = max(S_SIGMA L_h, 2 T G_SLOPE / R)``.

Distance bounds (``eval_bounds``, level ``c``): ``{f >= -c}`` is inside both
``{f_T >= -c}`` and ``{f_P >= -c}``, so the bound is the larger of the two.
For ``0 <= c < T``, ``s(v) >= -c`` implies ``v >= -c / k`` (``k = min(1, T/R)``, see
:mod:`.falloff`), i.e. ``z <= h + c / k``: the parent's maximum-mipmap clearance
bounds apply to the shifted level. Below the surface (``c < 0``) ``s(v) <= S_SIGMA v``
gives ``v >= -c / S_SIGMA`` instead. ``f_P >= -c`` is the box ``P`` grown by
``r_c = R sqrt(1 - ((1 - c/T)/2)^(1/3))``, whose distance is ``d(p, P) - r_c``.

Local slopes (issue 21; ``eval_local``). In the ball ``B(p, rad)``, ``v`` stays in
``[v(p) - rad L_h, v(p) + rad L_h]`` and ``|grad f_T| <= L_h max s'`` over that interval,
``s'(x) = (1 - u)(1 + c u)``, ``u = |x| / R``, 0 beyond ``R`` (a concave quadratic in ``u``
for ``c > 0``, decreasing for ``c <= 0``): the saturated sigmoid deep in the rock or
high in the air has slope 0. Where ``rad`` is at most a DEM cell the ball's
footprint lies in the 3x3 cells around ``p``'s, and ``L_h`` uses their largest
bilinear slope (plus the elevation primitives' and the fBm's) instead of the DEM's
steepest cell anywhere. ``|grad f_P| <= (2T/R) max |g'|`` over ``d(q, P) / R`` in
``[(d - rad)/R, (d + rad)/R]``, and ``|grad f| <= max`` of the two. Given a ray's
direction, the slope along its line replaces ``L_h`` where ``rad`` is within the line
bound's reach: ``|dv/ds| <= min(B0 + K rad, B1)`` (:mod:`.elevation_line`), the rate
the ray climbs over the ground rather than the ground's steepest slope (Jacksboro
shadow steps 36 -> 28 a ray).

Footprint level of detail (:mod:`arches_render.field.lod`): with a ray's footprint
the fBm keeps the octaves the cone resolves (:class:`~arches_render.field.lod.OctaveLOD`);
its range is at most the full one (the mipmap clearance above holds) and its slope
at most ``1 + kappa s`` times the full one, which every slope and Hart bound of the
footprint field takes.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), Sec. 3.3, 5.1.
Génevaux, J.-D. et al. (2015). Terrain modelling from feature primitives. CGF 34(6)
(elevation primitives with compact support).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render.backend import variant
from arches_render.field import Heightfield
from arches_render.field.heightfield import height_grid, line_factors, window_reach
from arches_render.field.lod import OctaveLOD
from arches_render.field.node import (box_distance, box_gap, box_reach, clip_index, one_sided_lanes, opaque_float,
                                      refill)
from arches_render.field.noise import fbm, fbm_gradient, fbm_lipschitz, fbm_range
from arches_render.field.window_filters import window_max

from .elevation_line import ElevationLineBound
from .falloff import G_SLOPE, falloff_slope_max, g_dr, sigmoid_coefficients, sigmoid_dr, sigmoid_slope
from .skeletal_set import SkeletalSet

R0_FACTOR = math.sqrt(1.0 - 2.0 ** (-1.0 / 3.0))


class ImplicitHeightfield(Heightfield):
    """Compact implicit terrain ``min(f_T, f_P)`` over a DEM (see module docstring).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations (metres), finite, at least 2x2.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)``: the domain ``Omega``.
    R : float, optional
        Falloff radius (metres) of the sigmoid and of the prism; default 4 grid
        cells (at most a quarter of the shorter side); ``2R`` must be smaller than
        both sides of ``Omega``.
    T : float, optional
        Threshold ``T`` (field value deep inside), in ``[R/3, 2R]``; default ``R/2``.
    base : float, optional
        Bottom of the prism ``P``; default ``min h - max(R, 5 % of the relief)``.
    bumps : dict, optional
        Elevation primitives: ``center (N, 2)``, ``radius (N,)``, ``height (N,)``.
    amplification : dict, optional
        fBm added to the elevation: ``amplitude``, ``wavelength``, ``octaves`` (4),
        ``lacunarity`` (2), ``gain`` (0.5), ``seed`` (0), ``border`` (0) and
        ``taper`` (0, no fade) in metres (see the module docstring).
    """

    kind = "implicit_heightfield"

    def __init__(self, heights, extent, R=None, T=None, base=None, bumps=None, amplification=None):
        H, (x0, y0, x1, y1) = height_grid(heights, extent)
        cell = min((x1 - x0) / (H.shape[1] - 1), (y1 - y0) / (H.shape[0] - 1))
        R = float(R) if R is not None else min(4.0 * cell, 0.25 * min(x1 - x0, y1 - y0))
        if not R > 0:
            raise ValueError("R must be > 0")
        if not 2.0 * R < min(x1 - x0, y1 - y0):
            raise ValueError(f"R = {R:g} m is too large: 2R must be smaller than the extent's sides")
        T = float(T) if T is not None else 0.5 * R
        self.sig_a, self.sig_b = sigmoid_coefficients(R, T)  # validates T in [R/3, 2R]
        self.R_np, self.T_np = R, T

        # Optional extras of the elevation function.
        self.bumps = None
        extra_hi, extra_lo, extra_slope = 0.0, 0.0, 0.0
        if bumps is not None:
            try:
                c = np.asarray(bumps["center"], dtype=np.float64).reshape(-1, 2)
                pts = np.column_stack([c, np.zeros(len(c))])
                self.bumps = SkeletalSet(pts, None, bumps["radius"], bumps["height"])
            except (ValueError, KeyError, TypeError) as exc:
                raise ValueError(f"bumps: {exc} (need center (N, 2), radius (N,), height (N,))") from None
            extra_hi, extra_lo = self.bumps.value_max, self.bumps.value_min
            extra_slope += self.bumps.lipschitz
        self.amp = None
        if amplification is not None:
            p = dict(octaves=4, lacunarity=2.0, gain=0.5, seed=0, border=0.0, taper=0.0)
            p.update(amplification)
            if not p["wavelength"] > 0 or not 1 <= int(p["octaves"]) <= 12:
                raise ValueError("amplification needs wavelength > 0 and octaves in [1, 12]")
            if not (p["border"] >= 0 and p["taper"] >= 0):
                raise ValueError("amplification needs border >= 0 and taper >= 0")
            self.amp = p
            rng = abs(p["amplitude"]) * fbm_range(int(p["octaves"]), p["gain"])
            extra_hi, extra_lo = extra_hi + rng, extra_lo - rng
            extra_slope += abs(p["amplitude"]) * fbm_lipschitz(int(p["octaves"]), p["lacunarity"],
                                                               p["gain"]) / p["wavelength"]
            if p["taper"] > 0:
                extra_slope += 1.5 * rng / p["taper"]  # |smoothstep'| <= 1.5, |grad e| <= 1
                self._amp_border, self._amp_inv_taper = opaque_float(p["border"]), opaque_float(1.0 / p["taper"])
            self._amp_a = opaque_float(p["amplitude"])
            self._amp_inv_wl = opaque_float(1.0 / p["wavelength"])
            self._amp_lac, self._amp_gain = opaque_float(p["lacunarity"]), opaque_float(p["gain"])
            self._amp_seed = dr.opaque(mi.UInt32, int(p["seed"]) & 0xFFFFFFFF)
            # Footprint level of detail of the sub-cell fBm (module docstring).
            self._lod = OctaveLOD(p["octaves"], p["lacunarity"], p["gain"], p["amplitude"], p["wavelength"])
        self.extra_hi, self.extra_lo = extra_hi, extra_lo

        hmin, hmax = float(H.min()) + extra_lo, float(H.max()) + extra_hi
        if base is None:
            base = hmin - max(R, 0.05 * (hmax - hmin))
        base = float(base)
        if not base < hmax:
            raise ValueError(f"base ({base:g}) must lie below the highest elevation ({hmax:g})")
        super().__init__(H, (x0, y0, x1, y1), base=base)
        self._x1, self._y1 = opaque_float(x1), opaque_float(y1)
        self.grid_slope = self.slope_bound
        self.slope_bound = self.grid_slope + extra_slope
        self.extra_slope_np, self.cell_np = float(extra_slope), min(self.dx, self.dy)
        self._near_slope = mi.Float(_near_cell_slopes(H, self.dx, self.dy).astype(np.float32).ravel())
        self.top_np = hmax
        self.prism_lo = np.array([x0 + R, y0 + R, base])
        self.prism_hi = np.array([x1 - R, y1 - R, hmax])
        self._plo = [opaque_float(v) for v in self.prism_lo]
        self._phi = [opaque_float(v) for v in self.prism_hi]
        self._R, self._T = opaque_float(R), opaque_float(T)
        self._inv_R = opaque_float(1.0 / R)
        self._a, self._b = opaque_float(self.sig_a), opaque_float(self.sig_b)
        self._inv_k = opaque_float(1.0 / min(1.0, T / R))
        self._inv_S = opaque_float(1.0 / sigmoid_slope(R, T))
        self._extra = opaque_float(extra_hi)
        self._inv_Lh = opaque_float(1.0 / math.sqrt(1.0 + self.slope_bound ** 2))
        self._line = ElevationLineBound(self)

    # -- elevation ------------------------------------------------------------------
    def elevation(self, x, y, level=None, along=None):
        """``h(x, y)`` (``mi.Float`` each): grid + elevation primitives + fBm (``level``:
        the fBm's footprint level, :class:`~arches_render.field.lod.OctaveLOD`; None:
        every octave).

        With ``along`` (a direction, ``mi.Vector3f``): ``(h, a0)``, ``a0`` the faded fBm's
        derivative along it with the octave weights held (``A0`` of
        :mod:`.elevation_line`; ``None`` without amplification). ``h`` is bitwise the
        same."""
        h = self.height(x, y)
        a0 = None
        if self.bumps is not None:
            h = h + self.bumps.field(mi.Point3f(x, y, 0.0))
        if self.amp is not None:
            q = mi.Point3f(x, y, 0.0) * self._amp_inv_wl
            a = self._amp_a
            if self.amp["taper"] > 0:
                e = dr.minimum(dr.minimum(x - self._x0, self._x1 - x), dr.minimum(y - self._y0, self._y1 - y))
                u = dr.clip((e - self._amp_border) * self._amp_inv_taper, 0.0, 1.0)
                a = a * (u * u * (3.0 - 2.0 * u))
            lvl = () if level is None else (level,)
            args = (q, int(self.amp["octaves"]), self._amp_lac, self._amp_gain, self._amp_seed, *lvl)
            if along is None:
                h = h + a * fbm(*args)
            else:
                n, gn = fbm_gradient(*args)
                h = h + a * n
                a0 = (a * self._amp_inv_wl) * (gn.x * along.x + gn.y * along.y)
        return h if along is None else (h, a0)

    def elevation_np(self, x, y) -> np.ndarray:
        """``h`` on numpy coordinates (same code as the renderer's, through Dr.Jit)."""
        variant()
        x = np.asarray(x, dtype=np.float32)
        y = np.broadcast_to(np.asarray(y, dtype=np.float32), x.shape)
        h = self.elevation(mi.Float(x.ravel()), mi.Float(np.ascontiguousarray(y).ravel()))
        dr.eval(h)
        return h.numpy().reshape(x.shape)

    # -- field ----------------------------------------------------------------------
    def _prism(self, p):
        d = box_distance(p, self._plo, self._phi)
        return self._T * (2.0 * g_dr(dr.square(d / self._R)) - 1.0), d

    def eval(self, p):
        fT = sigmoid_dr(self.elevation(p.x, p.y) - p.z, self._R, self._a, self._b)
        return dr.minimum(fT, self._prism(p)[0])

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        return self.eval_local(p, levels, direction, footprint)[:2]

    def local_slopes(self, v, d_prism, k, radii, grow=1.0, line=None):
        """Bounds of ``|grad f|`` in the balls of radii ``radii`` around a point of DEM
        cell ``k`` where ``v = h - z`` and ``d(p, P) = d_prism`` (module docstring,
        "Local slopes"); ``grow``: ``1 + kappa s`` of a footprint field. With ``line``,
        the :meth:`.ElevationLineBound.derivative_terms` of a ray's line: bounds of the
        derivative along it where the radius lies within their reach."""
        S_near = dr.gather(mi.Float, self._near_slope, k) + self.extra_slope_np
        c = 6.0 * self.T_np / self.R_np - 3.0
        peak = (c - 1.0) / (2.0 * c) if c > 0.0 else 0.0  # of s'(u) = (1 - u)(1 + c u)
        out = []
        for rad in radii:
            # The cell's 3x3 neighbourhood holds a ball of one cell edge.
            # (rad may be a per-lane radius: a tracer's adaptive ball.)
            S = dr.select(rad <= self.cell_np, S_near, self.slope_bound)
            Lh = dr.sqrt(1.0 + S * S) * (1.0 + 1e-6) * grow
            if line is not None:
                # Along the line |dv/ds| <= min(B0 + K |s|, B1) within rho (the footprint
                # field's, grown already): the rate a ray climbs, not the ground's steepest.
                B0, B1, K, reach = line.B0, line.B1, line.K, line.rho
                Lh = dr.select(rad <= reach, dr.minimum(dr.minimum(B0 + K * rad, B1) * (1.0 + 1e-6), Lh), Lh)
            lo, hi = v - rad * Lh, v + rad * Lh
            ua = dr.select((lo <= 0.0) & (hi >= 0.0), 0.0, dr.minimum(dr.abs(lo), dr.abs(hi))) * self._inv_R
            ub = dr.maximum(dr.abs(lo), dr.abs(hi)) * self._inv_R
            u = dr.clip(dr.clip(mi.Float(peak), ua, ub), 0.0, 1.0)
            sig = dr.select(ua >= 1.0, 0.0, (1.0 - u) * (1.0 + c * u))
            prism = (2.0 * self._T * self._inv_R) * falloff_slope_max((d_prism - rad) * self._inv_R,
                                                                     (d_prism + rad) * self._inv_R)
            out.append(dr.maximum(Lh * sig, prism))
        return tuple(out)

    def eval_local(self, p, levels, direction=None, footprint=None, radii=()):
        """``(f, ds, slopes)``: :meth:`eval_bounds` and the :meth:`local_slopes` of ``radii``;
        with a ``footprint``, of the footprint field (the fBm's finer octaves skipped,
        slopes grown by ``1 + kappa s``)."""
        level = self._lod.level(footprint) if self.amp is not None else None
        grow = 1.0 + self.lod_kappa * footprint.rate if level is not None else 1.0
        a0 = None
        if direction is None or self._line.gentle:
            v = self.elevation(p.x, p.y, level) - p.z
        else:
            h, a0 = self.elevation(p.x, p.y, level, along=direction)
            v = h - p.z
        fP, dP = self._prism(p)
        f = dr.minimum(sigmoid_dr(v, self._R, self._a, self._b), fP)
        u = clip_index((p.x - self._x0) * self._inv_dx, 0.0, self.nx - 1.0)
        w = clip_index((p.y - self._y0) * self._inv_dy, 0.0, self.ny - 1.0)
        k = dr.minimum(mi.UInt32(w), self.ny - 2) * self.nx + dr.minimum(mi.UInt32(u), self.nx - 2)
        above = [p.z - m - self._extra for m in self.window_maxima(k)]
        line = line_factors(direction)
        # f_T >= -c  =>  v >= -c / k (0 <= c < T); nothing to bound when c >= T.
        # Below the surface (c < 0, asked by the sum's caps) s(v) >= -c > 0 only
        # gives v >= -c / S_SIGMA.
        # Levels known to lie at or above T (the sum's shift by a set's maximum: every
        # point is within them) are answered 0 without their bounds.
        whole = [isinstance(c, (int, float)) and c >= self.T_np * (1.0 + 1e-6) for c in levels]
        asked = [c for c, skip in zip(levels, whole) if not skip]
        shifts = [c * dr.select(mi.Bool(c >= 0.0), self._inv_k, self._inv_S) for c in asked]
        terms = None
        if direction is not None and (asked or radii):
            terms = self._line.derivative_terms(p, direction, k, a0, level, footprint)
        if direction is not None and asked:
            # Along the ray: second-order bounds of v on the ray's own line; ahead only
            # where the tracer allows it (arches_render.field.node, "Ahead").
            lines = self._line.free_lengths(p, direction, v, k, shifts, a0, level, footprint, terms)
            lanes = one_sided_lanes()
            if lanes is not None:
                ahead = self._line.ahead_lengths(v, shifts, terms)
                lines = [dr.select(lanes, dr.maximum(a, d), d) for a, d in zip(ahead, lines)]
        ds = []
        for i, (c, shift) in enumerate(zip(asked, shifts)):
            dT = dr.maximum(-v - shift, 0.0) * self._inv_Lh * (1.0 / grow)
            if direction is not None:
                dT = dr.maximum(dT, lines[i])
            dT = window_reach(dT, [a - shift for a in above], self._radii, line)
            wc = dr.clip((1.0 - c / self._T) * 0.5, 0.0, 1.0)
            rc = self._R * dr.sqrt(dr.maximum(1.0 - dr.cbrt(wc), 0.0))
            d = dr.maximum(dT, dr.maximum(dP - rc, 0.0))
            ds.append(dr.select(c >= self._T, 0.0, d))
        return f, tuple(refill(ds, whole)), self.local_slopes(v, dP, k, radii, grow, terms)

    def bounds(self):
        r0 = R0_FACTOR * self.R_np
        return self.prism_lo - np.array([r0, r0, r0]), self.prism_hi + np.array([r0, r0, 0.0])

    @property
    def lod_kappa(self):
        # Only the fBm has levels: the footprint field's slope is at most the full
        # one times 1 + kappa s (arches_render.field.lod), L included.
        return self._lod.kappa if self.amp is not None else 0.0

    def box_range(self, lo, hi):
        """``min(f_T, f_P)`` over the boxes: ``h`` from the DEM's pyramids widened by the
        elevation primitives' and the fBm's ranges, ``s`` increasing, ``f_P`` decreasing
        in the distance to the prism (convex: largest at a corner)."""
        h_min, h_max = self.height_range(lo.x, hi.x, lo.y, hi.y)
        t_lo = sigmoid_dr(h_min + self.extra_lo - hi.z, self._R, self._a, self._b)
        t_hi = sigmoid_dr(h_max + self.extra_hi - lo.z, self._R, self._a, self._b)
        d_min, d_max = box_gap(lo, hi, self._plo, self._phi), box_reach(lo, hi, self._plo, self._phi)
        prism = lambda d: self._T * (2.0 * g_dr(dr.square(d * self._inv_R)) - 1.0)  # noqa: E731
        return dr.minimum(t_lo, prism(d_max)), dr.minimum(t_hi, prism(d_min))

    def lod_error(self, radius):
        # The truncated fBm moves h by at most its error (the fade w <= 1), and the
        # sigmoid moves f_T by at most its slope times that; f_P has no octaves.
        if self.amp is None:
            return 0.0
        return sigmoid_slope(self.R_np, self.T_np) * self._lod.error_within(radius)

    @property
    def lipschitz(self):
        Lh = math.sqrt(1.0 + self.slope_bound ** 2)
        return max(sigmoid_slope(self.R_np, self.T_np) * Lh, 2.0 * self.T_np * G_SLOPE / self.R_np)

    # Saturates at -T in the air: no unit-rate falloff away from the box.
    unit_falloff = False

    @property
    def value_max(self):
        return self.T_np

    @property
    def value_min(self):
        return -self.T_np

    @property
    def cost(self):
        c = 4.0
        if self.bumps is not None:
            c += self.bumps.cost
        if self.amp is not None:
            c += 6.0 * int(self.amp["octaves"])
        return c

    def nbytes(self):
        own = super().nbytes() + self.heights_np.size * 4  # + the near-cell slopes
        return own + (self.bumps.nbytes() if self.bumps is not None else 0)


def _near_cell_slopes(H, dx, dy):
    """Per sample ``(j, i)``: a bound of the bilinear interpolant's slope over the 3x3
    cells around cell ``(j, i)`` (the last row and column repeat the cells before
    them, as the cell lookup clamps). A bilinear cell's slope is at most
    ``hypot(max |h10 - h00|, |h11 - h01|) / dx, max(|h01 - h00|, |h11 - h10|) / dy)``."""
    sx = np.maximum(np.abs(H[:-1, 1:] - H[:-1, :-1]), np.abs(H[1:, 1:] - H[1:, :-1])) / dx
    sy = np.maximum(np.abs(H[1:, :-1] - H[:-1, :-1]), np.abs(H[1:, 1:] - H[:-1, 1:])) / dy
    cells = window_max(np.hypot(sx, sy), 3)
    out = np.zeros_like(H, dtype=np.float64)
    out[:-1, :-1] = cells
    out[-1, :-1], out[:, -1] = out[-2, :-1], out[:, -2]
    return out * (1.0 + 1e-6)
