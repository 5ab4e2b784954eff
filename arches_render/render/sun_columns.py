"""Sun columns: a map in the sun's frame that ends shadow rays towards the sun early.

A shadow ray towards the sun leaves a surface and must be proven free up to the
field's box, although past the last rock on its line it only crosses open air: on
the goblins, rays that reach the sky spend a quarter of their steps beyond it. All
these rays are nearly parallel, so one map in the sun's frame, built once per scene
and sun, answers for every one of them with a few lookups a ray (not a step).

Frame and columns
-----------------
With ``a`` the unit vector towards the sun and ``e1``, ``e2`` completing an
orthonormal frame, a point has coordinates ``u = p . e1``, ``v = p . e2`` and height
towards the sun ``w = p . a``. The projection of the field's box on the ``(u, v)``
plane is cut into square columns of edge ``s``; column ``c`` has the axis through its
centre along ``a`` and the *cylinder* of radius ``rho = h + delta`` around it
(``h = s / sqrt 2`` the half-diagonal, ``delta`` the drift allowance, below).

Tops (built by marching). ``W(c)`` is a height above which the cylinder holds no
point of ``{f >= -tol}`` (``tol`` the tracer's largest hit tolerance, ``eps`` times
the box's diagonal): the axis is marched down from the box's sun side with the free
balls of ``Node.eval_bounds`` at level ``tol`` (no direction: balls). A ball of
radius ``r >= rho`` centred on the axis holds the cylinder's slice of axial length
``sqrt(r^2 - rho^2)`` on either side, so advancing by that much keeps the cylinder
covered from the top; the march stops where the advance falls below ``rho / 20``
and ``W`` is where the covered part ends (``-inf`` where it left the box).

Rays. A ray ``o + t d`` with ``cos beta = d . a > 0`` rises at ``w(o) + t cos beta``
and drifts sideways by ``t sin beta`` (``sin beta = |d x a|``; at most the sun's
angular radius, 0.267 degrees, for a sun sample). At ``t`` it lies within
``D(t) = h + t sin beta`` of the axis of its origin's column ``c``. Where
``D(t) <= rho`` it is inside ``c``'s cylinder, so it is free wherever it is above
``W(c)``: on ``[(W(c) - w(o)) / cos beta, delta / sin beta]``. Farther it may be in a
neighbour's cylinder: with ``M_k(c)`` the maximum of ``W`` over the columns within
``m_k = 2^k`` columns (Chebyshev), a point within ``(m_k + 1/2) s`` of ``c``'s axis
lies in a column (its own, within ``h < rho`` of its axis) no farther than ``m_k``,
so the ray is free on ``I_k = [(M_k - w(o)) / cos beta, ((m_k + 1/2) s - h) / sin beta)``,
and on ``I_K = [(max W - w(o)) / cos beta, inf)`` for the last level. The union of
these intervals that reaches infinity starts at ``t_cap``: the march need not go
past it. (A directional light, ``sin beta = 0``, needs the column alone.)

Rock (occluded at once). Below ``W(c)`` the build looks, slice by slice (axial
length ``rho``, at most ``SOLID_SLICES``), for the first slice whose bounding box
the field proves rock (``Node.box_range``: ``f_min > 0``) and keeps its heights
``[S_lo(c), S_hi(c)]``. A ray whose origin lies below ``S_lo`` and that reaches
``S_hi`` inside the cylinder (``h + t sin beta <= rho`` there) passes through rock:
it is occluded without a step (arch bridge: 70 % of the blocked shadow rays, which
took 49 steps each).

Footprints. The map answers for the full-detail field: footprint level of detail
(:mod:`arches_render.field.lod`) is not applied past ``t_cap``, where a bump that
only a ray's coarse footprint field raises no longer shades; the steps before
``t_cap`` are the tracer's as before.

References
----------
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10) (free balls).
Williams, L. (1978). Casting curved shadows on curved surfaces. SIGGRAPH '78
(a map in the light's frame; here a conservative bound, not a depth test).
Tevs, A., Ihrke, I., Seidel, H.-P. (2008). Maximum mipmaps for fast, accurate, and
scalable dynamic height field rendering. I3D '08 (maxima over growing windows).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

__all__ = ["SUN_HALF_ANGLE", "SunColumns", "disk_directions", "scene_sun", "sun_frame"]

#: The sun's angular radius in Mitsuba's ``sunsky`` (half its 0.5338 degree aperture),
#: in radians; a ray within it of the sun's axis is a sun ray.
SUN_HALF_ANGLE = math.radians(0.5338 / 2.0)

#: Columns over the box's projection: their edge follows from this count.
COLUMNS = 1 << 18

#: Slices of axial length ``rho`` below a column's top searched for rock.
SOLID_SLICES = 12


def scene_sun(lights):
    """The sun of a scene's lights (``SceneDescription.lights``): ``(direction towards it,
    angular radius in radians)`` of its first ``sunsky`` (radius ``SUN_HALF_ANGLE``) or
    ``directional`` light (radius 0), or None when it has neither."""
    for light in lights:
        if light.get("type") == "sunsky":
            return np.asarray(light["sun_direction"], np.float64), SUN_HALF_ANGLE
        if light.get("type") == "directional":
            return -np.asarray(light["direction"], np.float64), 0.0
    return None


def sun_frame(a):
    """``(e1, e2)`` completing the unit ``a`` to an orthonormal frame (numpy 3-vectors)."""
    a = np.asarray(a, np.float64)
    helper = np.array([0.0, 0.0, 1.0]) if abs(a[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1)


def disk_directions(axis, radius, n, rng):
    """``n`` unit directions uniform in the cone of half-angle ``radius`` around ``axis``
    (the sun's disk as the emitter samples it), numpy ``(n, 3)``; ``rng`` a numpy Generator."""
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    e1, e2 = sun_frame(a)
    cos_t = 1.0 - rng.random(n) * (1.0 - math.cos(radius))
    sin_t = np.sqrt(np.maximum(1.0 - cos_t ** 2, 0.0))
    phi = 2.0 * np.pi * rng.random(n)
    return cos_t[:, None] * a + (sin_t * np.cos(phi))[:, None] * e1 + (sin_t * np.sin(phi))[:, None] * e2


class SunColumns:
    """Tops and rock slices of the columns of one field in one sun's frame (module docstring).

    Parameters
    ----------
    field : Node
        The tree the tracer traces (bounded).
    lo, hi : sequence of 3 floats
        The tracer's box.
    sun : sequence of 3 floats
        Direction towards the sun (normalized here).
    tolerance : float
        The tracer's largest hit tolerance for rays from inside the box (metres, ``eps``
        times its diagonal): ``W`` keeps this far from the surface; rays from outside
        it are not helped.
    half_angle : float
        Largest angle between a sun ray and ``sun`` (radians): rays farther off are not
        helped. 0 for a directional light.
    columns : int
        About how many columns cover the box's projection.
    """

    def __init__(self, field, lo, hi, sun, tolerance, half_angle=SUN_HALF_ANGLE, columns=COLUMNS):
        a = np.asarray(sun, np.float64)
        self.a = a / np.linalg.norm(a)
        self._lo = [dr.opaque(mi.Float, float(v)) for v in lo]
        self._hi = [dr.opaque(mi.Float, float(v)) for v in hi]
        self.e1, self.e2 = sun_frame(self.a)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        u, v, w = corners @ self.e1, corners @ self.e2, corners @ self.a
        self.s = float(math.sqrt((u.max() - u.min()) * (v.max() - v.min()) / columns))
        self.nu = max(int(math.ceil((u.max() - u.min()) / self.s)), 1)
        self.nv = max(int(math.ceil((v.max() - v.min()) / self.s)), 1)
        self.u0, self.v0 = float(u.min()), float(v.min())
        self.h = self.s / math.sqrt(2.0)
        self.delta = self.s
        self.rho = self.h + self.delta
        self.sin_max = math.sin(half_angle * 1.001 + 1e-6)
        self.cos_max = math.cos(half_angle * 1.001 + 1e-6)
        centres = self._centres()
        top = self._tops(field, centres, float(w.max()) + self.rho, float(w.min()) - self.rho, tolerance)
        self.solid_lo, self.solid_hi = self._rock(field, centres, top)
        self.levels = self._maxima(top)
        self._upload()

    # -- build --------------------------------------------------------------------

    def _centres(self):
        """``(nu nv, 2)`` column centres ``(u, v)``, column ``i nv + j``."""
        iu, iv = np.meshgrid(np.arange(self.nu), np.arange(self.nv), indexing="ij")
        return np.stack([self.u0 + (iu.ravel() + 0.5) * self.s, self.v0 + (iv.ravel() + 0.5) * self.s], 1)

    def _world(self, centres, w):
        return centres[:, :1] * self.e1 + centres[:, 1:] * self.e2 + np.asarray(w).reshape(-1, 1) * self.a

    def _tops(self, field, centres, w_start, w_stop, tolerance):
        """``W`` per column (module docstring, "Tops"): float64, ``-inf`` for empty columns."""
        start = self._world(centres, np.full(len(centres), w_start))
        o = mi.Point3f(*(mi.Float(start[:, k].astype(np.float32)) for k in range(3)))
        down = mi.Vector3f(*(float(-c) for c in self.a))
        t = _march_down(field, o, down, float(w_start - w_stop), self.rho, float(tolerance))
        t = t.numpy().astype(np.float64)
        return np.where(t >= w_start - w_stop, -np.inf, w_start - t)

    def _rock(self, field, centres, top):
        """``(S_lo, S_hi)`` per column (module docstring, "Rock"); ``-inf`` where none was found."""
        found = np.isfinite(top)
        start = self._world(centres, np.where(found, top, 0.0))
        o = mi.Point3f(*(mi.Float(start[:, k].astype(np.float32)) for k in range(3)))
        down = mi.Vector3f(*(float(-c) for c in self.a))
        k = _first_rock(field, o, down, mi.Bool(found), self.rho).numpy()
        rock = k < SOLID_SLICES
        w_hi = np.where(rock, top - k * self.rho, -np.inf)
        return np.where(rock, w_hi - self.rho, -np.inf), w_hi

    def _maxima(self, top):
        """``[(M_k, reach_k)]``: ``W`` and its maxima over growing windows, each with the
        lateral distance from a column's axis within which it holds (module docstring)."""
        from scipy.ndimage import maximum_filter  # on use: keeps the import light
        grid = top.reshape(self.nu, self.nv)
        levels = [(grid, self.rho)]
        m = 2
        while m < max(self.nu, self.nv):
            levels.append((maximum_filter(grid, size=2 * m + 1, mode="constant", cval=-np.inf),
                           (m + 0.5) * self.s * (1.0 - 1e-6)))
            m *= 2
        levels.append((np.full_like(grid, np.max(top)), math.inf))
        return levels

    def _upload(self):
        self._a = [dr.opaque(mi.Float, float(c)) for c in self.a]
        self._e1 = [dr.opaque(mi.Float, float(c)) for c in self.e1]
        self._e2 = [dr.opaque(mi.Float, float(c)) for c in self.e2]
        finite = [np.where(np.isfinite(g), g, -3e38).astype(np.float32).ravel() for g, _ in self.levels]
        self._tops_k = [mi.Float(g) for g in finite]
        self._reach = [r for _, r in self.levels]
        self._solid_lo = mi.Float(np.where(np.isfinite(self.solid_lo), self.solid_lo, -3e38).astype(np.float32))
        self._solid_hi = mi.Float(np.where(np.isfinite(self.solid_hi), self.solid_hi, -3e38).astype(np.float32))

    # -- queries ------------------------------------------------------------------

    def limits(self, o, d, tmax):
        """``(t_cap, rock)`` per lane for the rays ``o + t d``: past ``t_cap`` the ray is
        free (``inf`` where the map cannot tell), and ``rock`` rays pass through a rock
        slice before ``tmax`` (module docstring, "Rays" and "Rock").

        Parameters
        ----------
        o, d : mi.Point3f, mi.Vector3f
            Origins and unit directions.
        tmax : mi.Float
            The rays' far ends.

        Returns
        -------
        (mi.Float, mi.Bool)
        """
        a = mi.Vector3f(*self._a)
        cos_b = dr.dot(d, a)
        sin_b = dr.norm(dr.cross(d, a))
        wo = dr.dot(mi.Vector3f(o), a)
        fu = (dr.dot(mi.Vector3f(o), mi.Vector3f(*self._e1)) - self.u0) / self.s
        fv = (dr.dot(mi.Vector3f(o), mi.Vector3f(*self._e2)) - self.v0) / self.s
        sun_ray = (cos_b >= self.cos_max) & (sin_b <= self.sin_max)
        # Origins in the box only: there every point of the ray within it is closer than
        # the box's diagonal, so its hit tolerance is at most the one the tops keep clear of.
        in_box = dr.all((o >= mi.Point3f(*self._lo)) & (o <= mi.Point3f(*self._hi)))
        inside = sun_ray & in_box & (fu >= 0.0) & (fv >= 0.0) & (fu < self.nu) & (fv < self.nv)
        col = mi.UInt32(dr.clip(fu, 0.0, self.nu - 1.0)) * self.nv + mi.UInt32(dr.clip(fv, 0.0, self.nv - 1.0))
        inv_cos = dr.rcp(dr.maximum(cos_b, 1e-6))
        # Greedy union from the last level down: I_k extends [start, inf) when it reaches it.
        start = mi.Float(dr.inf)
        for tops, reach in reversed(list(zip(self._tops_k, self._reach))):
            enter = (dr.gather(mi.Float, tops, col, inside) - wo) * inv_cos
            leave = mi.Float(dr.inf) if math.isinf(reach) else (reach - self.h) / sin_b
            start = dr.select((leave >= start) & (enter < start), enter, start)
        t_cap = dr.select(inside, dr.maximum(start, 0.0), dr.inf)
        s_lo = dr.gather(mi.Float, self._solid_lo, col, inside)
        t_through = (dr.gather(mi.Float, self._solid_hi, col, inside) - wo) * inv_cos
        rock = inside & (wo < s_lo) & (t_through <= tmax) & (t_through * sin_b <= self.delta)
        return t_cap, rock

    def nbytes(self):
        """Bytes of the uploaded tables."""
        return 4 * (len(self._tops_k) + 2) * self.nu * self.nv


@dr.syntax
def _march_down(field, o, down, length, rho, tolerance):
    """Distance down each axis ``o + t down`` to where the cylinder of radius ``rho``
    stops being proven free of ``{f >= -tolerance}`` (``length``: none found)."""
    t = mi.Float(0.0)
    alive = mi.Bool(True)
    while dr.hint(alive, label="sun_columns"):
        _, (r,) = field.eval_bounds(o + down * t, (tolerance,))
        advance = dr.sqrt(dr.maximum(dr.square(r) - rho * rho, 0.0))
        # A NaN radius proves nothing: the column stops there.
        alive &= (advance >= 0.05 * rho) & ~dr.isnan(r)
        t = dr.select(alive, t + advance, t)
        alive &= t < length
    return dr.minimum(t, length)


@dr.syntax
def _first_rock(field, o, down, active, rho):
    """Index of the first slice ``[k rho, (k + 1) rho]`` down each axis ``o + t down``
    whose bounding box (grown by ``rho``) the field proves rock, ``SOLID_SLICES`` where none is."""
    k = mi.UInt32(0)
    alive = mi.Bool(active)
    pad = mi.Vector3f(rho, rho, rho)
    while dr.hint(alive & (k < SOLID_SLICES), label="sun_rock"):
        a = o + down * (mi.Float(k) * rho)
        b = a + down * rho
        f_min, _ = field.box_range(dr.minimum(a, b) - pad, dr.maximum(a, b) + pad)
        alive &= ~(f_min > 0.0)
        k = dr.select(alive, k + 1, k)
    return dr.select(mi.Bool(active), k, SOLID_SLICES)
