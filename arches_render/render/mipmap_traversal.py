"""Exact ray casting of a bilinear heightfield by maximum-mipmap traversal, in Dr.Jit.

**Traversal** (Tevs et al. 2008, hierarchical ray stepping): a lane holds a level
``l`` and a cell ``(i, j)`` of that level and, at each iteration of one loop,

* computes the cell's exit distance ``t_exit`` (the nearer of its x and y walls);
* if the ray's lowest point over ``[t, t_exit]`` is above the cell's maximum, steps
  to the neighbour cell through that wall and, when the step leaves the parent
  cell, goes up one level;
* otherwise goes down one level, first advancing ``t`` to where the ray sinks below
  the maximum, into the child cell holding the ray's point;
* at level 0 intersects the bilinear patch exactly (below).

Cells advance by integer steps, never by re-locating a point, so rounding cannot
make a lane revisit a cell; every iteration steps or descends, so a lane ends
after at most ``levels + 2 (levels + cells crossed)`` iterations. A lane that
reaches that guard anyway is reported *capped*: the caller resolves it
conservatively, never as a miss.

**Ray-patch intersection.** In cell ``(i, j)`` the field's height is
``lerp(lerp(h00, h10, u), lerp(h01, h11, u), v)`` with ``u = (x - x0) / dx - i`` (the
same samples, formula and float operations as
:meth:`~arches_render.field.Heightfield.height`). Along the segment
``s in [0, s_b]`` from the current point, ``g(s) = h - z`` is the quadratic
``C + B s + A s^2``, ``A = e du dv``, with ``C`` evaluated exactly as the field
evaluates ``h - z`` at that point. The first ``s`` with ``g >= 0`` lies in an
interval where ``g`` is monotone (``[0, s*]`` before a maximum, ``[s*, s_b]`` after a
minimum, else ``[0, s_b]``); it is the increasing root ``(-B + sqrt(D)) / (2A)``,
computed in the cancellation-free form ``-2C / (B + sqrt(D))`` when ``B >= 0``, and
clamped into that interval. Whether the patch is hit at all is decided from the
values of ``g`` at the segment's ends and at an interior maximum.

**Shadow rays** (``any_hit``) stop at the first *certain* hit: a cell whose minimum
the ray sinks below holds matter, whatever the finer levels say.

References
----------
Tevs, A., Ihrke, I., Seidel, H.-P. (2008). Maximum mipmaps for fast, accurate, and
scalable dynamic height field rendering. Proc. I3D 2008, 183-190.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from ..field.heightfield_mipmap import MaxMipmap
from ..field.node import cell_index, jit_floats


@dataclass
class CastOutcome:
    """What one cast over ``[t, t_hi]`` found, per lane.

    Attributes
    ----------
    found : mi.Bool
        The heightfield is hit, at ``t_hit``.
    t_hit : mi.Float
    ended : mi.Bool
        ``[t, t_hi]`` is proven free (the stretch ends in a cell, or the ray left the grid).
    capped : mi.Bool
        The lane reached the iteration guard without either (resolve it conservatively).
    t : mi.Float
        How far the cast proved the ray free.
    iterations : mi.UInt32
        Cells visited.
    """

    found: object
    t_hit: object
    ended: object
    capped: object
    t: object
    iterations: object


@dataclass
class _CellStep:
    """One traversal iteration's decisions (module docstring)."""

    hit: object       # a (certain) hit in this cell, at t_hit
    t_hit: object
    ends: object      # the stretch is done
    t: object         # the lane's next position, level and cell
    level: object
    ci: object
    cj: object


class MipmapTraversal:
    """Maximum-mipmap ray casts of one heightfield (module docstring).

    Parameters
    ----------
    heightfield : Heightfield
        The field whose samples, cell size and origin the patch test repeats.
    """

    def __init__(self, heightfield):
        hf = heightfield
        self.mipmap = MaxMipmap(hf.heights_np)
        self.top = self.mipmap.levels - 1
        self.ncx, self.ncy = hf.nx - 1, hf.ny - 1
        self._max = mi.Float(self.mipmap.max_flat)
        self._min = mi.Float(self.mipmap.min_flat)
        self._offsets = [int(v) for v in self.mipmap.offsets]
        self._corners = jit_floats(self.mipmap.corners)  # one packet gather per patch
        # The field's own arrays and parameters: the patch test repeats its arithmetic.
        self._x0, self._y0 = hf._x0, hf._y0
        self._inv_dx, self._inv_dy = hf._inv_dx, hf._inv_dy
        self._dx, self._dy = dr.opaque(mi.Float, hf.dx), dr.opaque(mi.Float, hf.dy)

    @property
    def max_iterations(self) -> int:
        """The iteration guard: at most ``top`` descents per ascent, ascents <= cells crossed."""
        return self.top + 2 * (self.top + 2 * (self.ncx + self.ncy)) + 16

    def first_cell(self, o, d, t, fine):
        """``(level, ci, cj)`` to start a cast at ``t``: the finest cell under the ray's
        point where ``fine`` (rays starting inside the box: secondary and shadow rays
        leave the surface), else the top cell (a descent finds the first cells of a
        ray entering from outside fastest)."""
        p = o + d * t
        # Clamp before converting: far (or NaN) points must not overflow the integers.
        ci = cell_index((p.x - self._x0) * self._inv_dx, self.ncx, mi.Int32)
        cj = cell_index((p.y - self._y0) * self._inv_dy, self.ncy, mi.Int32)
        return dr.select(fine, 0, mi.Int32(self.top)), dr.select(fine, ci, 0), dr.select(fine, cj, 0)

    @dr.syntax
    def cast(self, o, d, t, t_hi, active, fine, any_hit=False):
        """Cast the rays ``o + t d`` over ``[t, t_hi]`` (module docstring).

        Parameters
        ----------
        o, d : mi.Point3f, mi.Vector3f
            Ray origins and unit directions.
        t, t_hi : mi.Float
            The stretch to search.
        active : mi.Bool
            Lanes to cast.
        fine : mi.Bool
            Start in the finest cell under the ray's point (:meth:`first_cell`).
        any_hit : bool
            Stop at the first certain hit (shadow rays).

        Returns
        -------
        CastOutcome
        """
        ray = (o, d, *self._ray_constants(d))
        t = mi.Float(t)
        level, ci, cj = self.first_cell(o, d, t, fine)
        found = mi.Bool(False)
        t_hit = mi.Float(dr.inf)
        ended = mi.Bool(False)
        alive = mi.Bool(active)
        iterations = mi.UInt32(0)
        max_iter = self.max_iterations
        # Read-only values stay out of the loop's state: Dr.Jit records a loop's body
        # again to drop a variable it leaves unchanged (integrator.sample_megakernel).
        while dr.hint(alive, label="hf_cast", exclude=[self, ray, t_hi]):
            cell = self._visit(ray, t, t_hi, level, ci, cj, alive, any_hit)
            found |= cell.hit
            t_hit = dr.select(cell.hit, cell.t_hit, t_hit)
            ended |= cell.ends
            t, level, ci, cj = cell.t, cell.level, cell.ci, cell.cj
            iterations += 1
            # Termination follows from the integer steps; the guard holds it anyway.
            alive &= ~cell.hit & ~cell.ends & (iterations < max_iter)
        capped = ~found & ~ended & (iterations >= max_iter)
        return CastOutcome(found=found, t_hit=t_hit, ended=ended, capped=capped, t=t, iterations=iterations)

    @staticmethod
    def _ray_constants(d):
        """What every iteration needs of the directions ``d``: infinity, ``1 / d`` and
        the x and y cell steps."""
        inv = mi.Vector3f(dr.rcp(d.x), dr.rcp(d.y), dr.rcp(d.z))
        return (mi.Float(dr.inf), inv, dr.select(d.x >= 0.0, mi.Int32(1), mi.Int32(-1)),
                dr.select(d.y >= 0.0, mi.Int32(1), mi.Int32(-1)))

    def _cells(self, level):
        """Cells per row and column at ``level``: ``ceil(n / 2^level)``."""
        one = mi.Int32(1) << level
        return (self.ncx + one - 1) >> level, (self.ncy + one - 1) >> level

    def _visit(self, ray, t, t_hi, level, ci, cj, alive, any_hit):
        """One traversal iteration from cell ``(ci, cj)`` of ``level`` at ``t`` for the
        rays ``ray`` (:meth:`_ray_constants`)."""
        o, d, inf, inv, sx, sy = ray
        size = mi.Float(mi.Int32(1) << level)
        csx, csy = self._dx * size, self._dy * size
        ex = self._x0 + mi.Float(dr.select(d.x >= 0.0, ci + 1, ci)) * csx
        ey = self._y0 + mi.Float(dr.select(d.y >= 0.0, cj + 1, cj)) * csy
        tx = dr.select(d.x != 0.0, (ex - o.x) * inv.x, inf)
        ty = dr.select(d.y != 0.0, (ey - o.y) * inv.y, inf)
        t_wall = dr.minimum(tx, ty)
        t_exit = dr.minimum(t_wall, t_hi)
        row, _ = self._cells(level)
        offset = mi.UInt32(0)
        for lvl, start in enumerate(self._offsets[1:], 1):
            offset = dr.select(level == lvl, mi.UInt32(start), offset)
        k = offset + mi.UInt32(cj * row + ci)
        zmax = dr.gather(mi.Float, self._max, k, alive)
        za, zb = o.z + d.z * t, o.z + d.z * t_exit
        zlow = dr.minimum(za, zb)
        empty = t > t_hi
        touch = alive & ~empty & (zlow <= zmax)
        leaf = touch & (level == 0)

        # Exact ray-patch test on [t, t_exit], skipped by SIMD packets without a leaf lane.
        patch, s_hit = dr.if_stmt((t, t_exit, za, ci, cj, leaf), leaf, lambda *a: self._patch_test(o, d, *a),
                                  lambda *a: (mi.Bool(False), mi.Float(0.0)), label="hf_patch")
        hit = patch
        if any_hit:
            # Certain hit for shadow rays: the ray sinks below the cell's minimum.
            zmin = dr.gather(mi.Float, self._min, k, touch)
            hit = patch | (touch & (zlow <= zmin))
        t_hit = dr.select(patch, t + s_hit, t)

        # Descend: advance to where the ray sinks below the cell's maximum.
        down = touch & (level > 0) & ~hit
        t_down = dr.select(za > zmax, t + (zmax - za) * inv.z, t)
        t_down = dr.maximum(dr.minimum(t_down, t_exit), t)
        right = o.x + d.x * t_down >= self._x0 + mi.Float(2 * ci + 1) * (csx * 0.5)
        upper = o.y + d.y * t_down >= self._y0 + mi.Float(2 * cj + 1) * (csy * 0.5)
        cnx, cny = self._cells(dr.maximum(level - 1, 0))
        ci_down = dr.minimum(2 * ci + dr.select(right, mi.Int32(1), mi.Int32(0)), cnx - 1)
        cj_down = dr.minimum(2 * cj + dr.select(upper, mi.Int32(1), mi.Int32(0)), cny - 1)

        # Step through the exit wall; go up when leaving the parent cell.
        step = alive & ~hit & ~down
        go_x = tx <= ty
        ci_step = ci + dr.select(go_x, sx, 0)
        cj_step = cj + dr.select(go_x, 0, sy)
        up = (level < self.top) & (((ci_step >> 1) != (ci >> 1)) | ((cj_step >> 1) != (cj >> 1)))
        ci_step, cj_step = dr.select(up, ci_step >> 1, ci_step), dr.select(up, cj_step >> 1, cj_step)
        level_step = dr.select(up, level + 1, level)
        unx, uny = self._cells(level_step)
        out = (ci_step < 0) | (ci_step >= unx) | (cj_step < 0) | (cj_step >= uny)
        # The stretch is done: its end lies in this cell, or the ray left the grid.
        ends = step & (empty | (t_wall >= t_hi) | out)
        step = step & ~ends

        return _CellStep(hit=hit, t_hit=t_hit, ends=ends,
                         t=dr.select(down, t_down, dr.select(step, dr.maximum(t, t_exit), t)),
                         level=dr.select(down, level - 1, dr.select(step, level_step, level)),
                         ci=dr.select(down, ci_down, dr.select(step, ci_step, ci)),
                         cj=dr.select(down, cj_down, dr.select(step, cj_step, cj)))

    def _patch_test(self, o, d, t, t_exit, za, ci, cj, leaf):
        """``(hit, s)``: whether the ray meets cell ``(ci, cj)``'s bilinear patch on
        ``[t, t_exit]``, and where (module docstring)."""
        inf = mi.Float(dr.inf)
        h00, h10, h01, h11 = dr.gather(mi.Vector4f, self._corners, mi.UInt32(cj * self.ncx + ci), leaf)
        ua = (o.x + d.x * t - self._x0) * self._inv_dx - mi.Float(ci)
        va = (o.y + d.y * t - self._y0) * self._inv_dy - mi.Float(cj)
        C = dr.lerp(dr.lerp(h00, h10, ua), dr.lerp(h01, h11, ua), va) - za
        du, dv = d.x * self._inv_dx, d.y * self._inv_dy
        bu, bv, e = h10 - h00, h01 - h00, (h11 - h01) - (h10 - h00)
        B = bu * du + bv * dv + e * (ua * dv + va * du) - d.z
        A = e * du * dv
        sb = dr.maximum(t_exit - t, 0.0)
        g1 = C + sb * (B + A * sb)
        s_star = -B / (2.0 * A)
        inner = (A != 0.0) & (s_star > 0.0) & (s_star < sb)
        cap = inner & (A < 0.0)
        gmax = dr.select(cap, C + s_star * (B + A * s_star), -inf)
        patch = leaf & ((C >= 0.0) | (g1 >= 0.0) | (gmax >= 0.0))
        # The monotone bracket [lo, hi] holding the first root.
        lo = dr.select(inner & (A > 0.0), s_star, 0.0)
        hi = dr.select(cap & (gmax >= 0.0), s_star, sb)
        sq = dr.sqrt(dr.maximum(dr.fma(B, B, -4.0 * A * C), 0.0))
        root = dr.select(B >= 0.0, -2.0 * C / (B + sq), (sq - B) / (2.0 * A))
        root = dr.select(dr.isfinite(root), dr.clip(root, lo, hi), hi)
        return patch, dr.select(C >= 0.0, 0.0, root)
