"""The state a path carries from vertex to vertex, by name.

One :class:`PathState` holds, per lane, what :meth:`ImplicitPathIntegrator.path_vertex
<arches_render.render.integrator>` reads and returns: the megakernel's symbolic loop
and the wavefront's depth-by-depth loop (:mod:`.wavefront`) carry the same state and
run the same vertex. The optional parts (the cone, the fog-free path, the first
vertex's AOVs, the ray counts) are empty tuples when off, so that their code is not
traced.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

__all__ = ["PathState"]


@dataclass
class PathState:
    """The paths' state, per lane.

    Attributes
    ----------
    ray : mi.Ray3f
        The ray to trace next.
    L, beta : mi.Spectrum
        Radiance gathered so far and the path's throughput.
    eta : mi.Float
        Product of the relative indices of refraction (Russian roulette).
    depth : mi.UInt32
        Vertices found so far.
    active : mi.Bool
        The path goes on.
    valid : mi.Bool
        The path hit something (Mitsuba's ``valid`` output).
    prev_si : mi.SurfaceInteraction3f
        The last vertex (for the MIS weight of emission reached by BSDF sampling).
    prev_bsdf_pdf : mi.Float
        The pdf of the BSDF sample that left it.
    prev_bsdf_delta : mi.Bool
        Whether that sample was a delta lobe.
    cone : tuple
        ``(r0, s)``: the ray's cone (footprint level of detail), or ``()``.
    clear : tuple
        ``(L, beta)`` of the same path without fog (AOV ``beauty_clear``), or ``()``.
    aov : tuple
        The first vertex's AOV channels, or ``()``.
    counts : tuple
        Exhausted and unresolved rays by kind, or ``()``.
    """

    ray: object
    L: object
    beta: object
    eta: object
    depth: object
    active: object
    valid: object
    prev_si: object
    prev_bsdf_pdf: object
    prev_bsdf_delta: object
    cone: tuple = ()
    clear: tuple = ()
    aov: tuple = ()
    counts: tuple = ()

    @classmethod
    def start(cls, ray, active, cone, fog_free, aov_channels, count_channels, width=None):
        """Paths about to trace ``ray`` on the lanes ``active``: nothing gathered, unit
        throughput. ``width``: arrays of that many lanes (the wavefront's), else
        literals (the megakernel's).

        Parameters
        ----------
        ray : mi.Ray3f
        active : mi.Bool
        cone : tuple
            ``(r0, s)`` or ``()``.
        fog_free : bool
            Carry the fog-free path.
        aov_channels, count_channels : int
            AOV and ray-count channels.
        width : int, optional
        """
        def full(tp, value):
            return tp(value) if width is None else dr.full(tp, value, width)

        return cls(ray=ray, L=full(mi.Spectrum, 0.0), beta=full(mi.Spectrum, 1.0), eta=full(mi.Float, 1.0),
                   depth=full(mi.UInt32, 0), active=mi.Bool(active), valid=full(mi.Bool, False),
                   prev_si=dr.zeros(mi.SurfaceInteraction3f, 1 if width is None else width),
                   prev_bsdf_pdf=full(mi.Float, 1.0), prev_bsdf_delta=full(mi.Bool, True),
                   cone=tuple(c if width is None else c + dr.zeros(mi.Float, width) for c in cone),
                   clear=(full(mi.Spectrum, 0.0), full(mi.Spectrum, 1.0)) if fog_free else (),
                   aov=tuple(full(mi.Float, 0.0) for _ in range(aov_channels)),
                   counts=tuple(full(mi.Float, 0.0) for _ in range(count_channels)))
