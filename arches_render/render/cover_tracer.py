"""Sphere tracing inside a cover: a ray tracer finds where a ray may meet the surface, the field decides.

The surface cells of a field (:class:`~arches_render.field.surface_cells.SurfaceCells`)
prove every leaf cell that is *air* for all footprint classes free of the surface
(within the tracers' largest hit tolerance). The boundary of the other cells is a
closed set of axis-aligned faces (:func:`~arches_render.mesh.cover_faces.boundary_quads`):
the *cover*. Mitsuba's ray tracer (Embree on the CPU, OptiX on the GPU) answers
where a ray next crosses the cover and whether it enters or leaves it there, in
one call and without evaluating the field. So a ray

1. casts against the cover from its verified point ``t``: a miss proves the rest of
   the ray free; a face it *enters* proves ``[t, t_in]`` free, and a second cast from
   just inside gives where it leaves again, ``t_out``; a face it *leaves* means the
   ray is already inside, and ``t_out`` is that face;
2. sphere-traces the field (the steps of :mod:`.march`, as
   :class:`~.sphere_tracer.SphereTracer` takes them) over ``[t_in, t_out]`` only, and
   casts again from ``t_out`` if it found nothing there.

What the field costs a ray is then the steps inside the cells where its surface may
be, not the approach to them, nor the crawl past rock it only grazes (Mitsuba's
``sdfgrid`` shape does the same with its voxels and an exact solve in each).

Conservativeness. Every hit of the sphere tracer lies in a covered cell, so the
cast's free stretches hold no hit. A cast starts ``NUDGE`` leaf edges past ``t``
(from exactly on a face, the ray tracer may meet that face again at distance 0 and
the ray would never move); the stretch skipped so is outside the cover unless the
ray enters and leaves it again within that length, which needs a cover thinner than
``NUDGE`` leaves along the ray: only at a cell's edge or corner, where the field is
within the tolerance plus ``L NUDGE h`` of an air cell's value. A ray's state is
read from the face it meets (entering or leaving), so a ray tracer that missed a
face could take the inside for the outside; each face therefore reaches ``GROW``
leaf edges past its edges, so that faces meeting at an edge (or at a T-junction of
merged rectangles) overlap and no ray slips between them. A face met in that
overlap only makes the ray trace more.

Footprints. The cover holds for the footprint fields of every class of the cells
(radius up to ``rho_K``); a ray whose cone outgrows that (a wide bounce far from its
origin) sphere-traces the rest of its segment as :class:`~.sphere_tracer.SphereTracer`
would.

Why it is not the renderer's tracer (measured on 2 CPU cores, ``llvm_ad_rgb``, against
:class:`~.sphere_tracer.SphereTracer`; issue 32 asked for this measurement): it finds
the same hits and takes fewer steps (``fig23_goblins`` camera / shadow / bounce 40.0 /
38.3 / 34.9 -> 31.9 / 31.6 / 33.1 a ray at 256 leaves along the box), but renders
slower (``render_cover_vs_sphere``: goblins, arch bridge and every_generator 1.10,
1.10 and 1.15 times the sphere tracer's time). A cast costs about what a field step
costs (~100 ns a ray), a packet casts whenever one of its lanes does, the cover is
thick where the cells' bounds are loose (goblins: 16 candidate leaves of 4 m a column
at the median) and shadow and bounce rays spend their steps leaving the surface they
start on, inside the cover. Finer leaves cut camera steps further (arch bridge
camera / shadow / bounce 26.1 / 22.6 / 20.1 -> 21.1 / 20.3 / 17.9 at 256 leaves, 13.0
/ 18.2 / 17.8 at 512) but hardly shadow or bounce steps, and take 8.7 s to build at
512. Where a ray tracer is cheap beside the field's arithmetic (a GPU's
RT cores) the balance may differ: the benchmark measures it.

References
----------
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
Wald, I., Woop, S., Benthin, C., Johnson, G. S., Ernst, M. (2014). Embree: a kernel
framework for efficient CPU ray tracing. ACM TOG 33(4).
"""

from __future__ import annotations

import time

import drjit as dr
import mitsuba as mi
import numpy as np

from ..mesh.cover_faces import boundary_quads, quads_to_triangles
from ..field.surface_cells import SurfaceCells
from .cell_tracer import LEAVES_ALONG
from .march import SECOND_PASS_FACTOR, March, ShadowProbe, march_result
from .sphere_tracer import SphereTracer

__all__ = ["CoverTracer"]

#: How far past its point a ray casts against the cover, in leaf edges (module docstring).
NUDGE = 1e-4
#: How far each cover face reaches past its edges, in leaf edges (no ray slips between faces).
GROW = 1e-3
#: Casts a ray may take before it is unresolved (each proves a stretch of the ray).
MAX_CASTS = 4096


class CoverTracer(SphereTracer):
    """Sphere tracing restricted to a cover of the surface cells (module docstring); the
    interface of :class:`~.sphere_tracer.SphereTracer`.

    Parameters
    ----------
    field : Node
        The construction tree (bounded).
    eps, omega, max_steps
        As for :class:`~.sphere_tracer.SphereTracer`.
    leaf : float, optional
        Leaf edge of the cells (default: the box's longest side / ``LEAVES_ALONG``).
    """

    def __init__(self, field, eps=2e-4, omega=1.6, max_steps=512, leaf=None):
        super().__init__(field, eps=eps, omega=omega, max_steps=max_steps)
        t0 = time.perf_counter()
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        leaf = float(np.max(hi - lo)) / LEAVES_ALONG if leaf is None else float(leaf)
        cells = SurfaceCells(self.field, lo, hi, leaf, slack=float(eps) * self.scale, keep_not_air=True)
        corners, outward = boundary_quads(cells.not_air, cells.grid_lo, leaf, grow=GROW * leaf)
        vertices, faces = quads_to_triangles(corners)
        mesh = mi.Mesh("field_cover", len(vertices), len(faces))
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(vertices.reshape(-1))
        params["faces"] = mi.UInt32(faces.reshape(-1))
        params.update()
        self.cover = mi.load_dict({"type": "scene", "cover": mesh})
        # Per triangle: 2 axis + (outward normal along +axis).
        self._outward = mi.UInt32(np.repeat(outward, 2).astype(np.uint32))
        self._nudge = dr.opaque(mi.Float, NUDGE * leaf)
        self._rho = dr.opaque(mi.Float, cells.radii[-1])
        self.stats = dict(cells.stats, cover_triangles=len(faces), cover_s=time.perf_counter() - t0)

    # -- implementation ----------------------------------------------------------------
    def _cover_end(self, t_start, cone):
        """Where the rays' cones outgrow the cover's largest footprint class."""
        if cone is None:
            return mi.Float(dr.inf) + 0.0 * t_start
        r0, s = cone
        limit = dr.select(s > 0.0, t_start + dr.maximum(self._rho - (r0 + s * t_start), 0.0) * dr.rcp(s), dr.inf)
        return dr.select(r0 + s * t_start <= self._rho, limit, t_start)

    def _cast(self, o, d, t, active):
        """Where the rays from ``t + NUDGE`` next cross the cover: ``(t_face, entering)``
        (``t_face`` infinite where they do not)."""
        o2 = o + d * (t + self._nudge)
        pi = self.cover.ray_intersect_preliminary(mi.Ray3f(o2, d), coherent=False, active=active)
        valid = active & pi.is_valid()
        code = dr.gather(mi.UInt32, self._outward, pi.prim_index, valid)
        axis = code >> 1
        d_axis = dr.select(axis == 0, d.x, dr.select(axis == 1, d.y, d.z))
        entering = valid & ((d_axis < 0.0) == ((code & 1) == 1))
        return dr.select(valid, t + self._nudge + pi.t, dr.inf), entering

    @dr.syntax
    def _march(self, o, d, t_start, t_end, active, cone, any_hit=False):
        """The loop over ``[t_start, t_end]``: casts where a ray's stretch is proven, sphere
        steps inside the cover."""
        budget = self.max_steps * (1 + SECOND_PASS_FACTOR)
        march = March.start(t_start, self.omega)
        shadow = ShadowProbe.start(dr.width(t_start)) if any_hit else None
        t_cover = self._cover_end(t_start, cone)
        # The end of the stretch the march proves before it casts again, and whether it
        # has: a ray casts at its start and once its march reports the stretch done (a
        # point a relaxed step or a probe reached at the stretch's end is checked first).
        seg_end = mi.Float(t_start)
        proven = mi.Bool(True)
        hit = mi.Bool(False)
        invalid = mi.Bool(False)
        alive = mi.Bool(active)
        steps = mi.UInt32(0)
        casts = mi.UInt32(0)
        while dr.hint(alive & (steps < budget) & (casts < MAX_CASTS), label="cover_trace"):
            casting = alive & proven & (march.t < t_cover)
            if casting:
                t0 = mi.Float(march.t)
                t_face, entering = self._cast(o, d, t0, casting)
                t_out, _ = self._cast(o, d, t_face, casting & entering)
                start = dr.select(entering, t_face, dr.select(dr.isfinite(t_face), t0, dr.inf))
                stop = dr.select(entering, t_out, t_face)
                # Past the cover's footprints the march goes on to the end unaided.
                over = start >= t_cover
                start = dr.minimum(start, t_cover)
                stop = dr.select(over | (stop > t_cover), t_end, dr.minimum(stop, t_end))
                alive &= start < t_end
                march = dr.select(start > t0, March.start(start, self.omega), march)
                seg_end = dr.select(casting, stop, seg_end)
                casts += 1
            seg_end = dr.select(march.t >= t_cover, t_end, seg_end)
            if dr.hint(any_hit, mode="scalar"):
                new, out, _, shadow = self.step(o, d, march, seg_end, cone, shadow)
            else:
                new, out, _ = self.step(o, d, march, seg_end, cone)
            march = dr.select(alive, new, march)
            hit |= alive & out.hit
            invalid |= alive & out.invalid
            alive &= ~(out.hit | out.invalid | (out.done & (seg_end >= t_end)))
            proven = out.done
            steps += 1
        return march_result(march, hit, alive, invalid, steps, active, self.max_steps, casts)
