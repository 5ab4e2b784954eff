"""``implicit_path``: a unidirectional path tracer for meshes *and* an implicit field.

Each path vertex is the nearer of two hits: Mitsuba's ray query against the scene's
shapes (``scene.ray_intersect``) and the sphere tracer against the field, limited
to the mesh distance. Field hits get a hand-built ``SurfaceInteraction3f`` (position
lifted off the surface by a small offset, normal ``-grad f / |grad f|``) and the
field's BSDF, chosen per lane with ``BSDFPtr``.

The estimator is the one of Mitsuba's ``path`` plugin: radiance

    L = sum_k beta_k [ w_em L_e(sampled light) f cos / p_em  +  w_bsdf L_e(hit) ],

with next-event estimation (shadow rays test meshes with ``scene.ray_test`` and the
field with the sphere tracer), multiple importance sampling with the power
heuristic between emitter and BSDF sampling, and Russian roulette from depth
``rr_depth`` with continuation probability ``min(max(beta) eta^2, 0.95)``.

Mitsuba's query costs a few field steps a ray against a far field's skirt, so rays
that provably meet no mesh skip it (:mod:`.mesh_region`): the shapes inside the scene
are asked before the field (a hit there shortens the field's trace), the far field's
skirt after it, up to the field's hit.

Python cannot subclass ``mi.Shape`` (only meshes), so the field travels next to
the scene: :meth:`ImplicitPathIntegrator.attach` gives it to the integrator after
``mi.load_dict``. ``mi.SamplingIntegrator`` exists per variant, so the class is
bound to the variant chosen at run time (:func:`arches_render.backend.variant_class`),
as the ``triplanar`` BSDF is; this module imports without a variant.

With ``aovs = true`` the integrator also returns the arbitrary output variables of
the primary hit (:mod:`arches_render.render.aovs`): albedo, shading normal, depth,
world position, field/mesh coverage and the field material's layer weights. They
come from a separate primary ray query that consumes no random numbers, so the
beauty is the same with or without them up to float rounding (the film then
accumulates more channels in another kernel; measured: 1 ulp in a quarter of the
pixels).

With an atmosphere (:meth:`ImplicitPathIntegrator.attach_atmosphere`, see
:mod:`arches_render.render.atmosphere`) every traced segment, camera and bounce
rays alike, adds its closed-form in-scatter ``beta L_in`` and multiplies the
throughput by its transmittance ``Tr``; shadow rays carry ``Tr`` of their
segment. Meshes and field are fogged by the same code, so the mesh cross-check
renders with this integrator whenever the atmosphere is on. With AOVs, the
fog-free beauty of the same paths (``beauty_clear``) and the camera ray's
transmittance (``transmittance``) are returned as well. Without an atmosphere
none of this code is traced: the kernels are those of the fog-free integrator.

Footprint level of detail (``lod = true``, :mod:`arches_render.field.lod`): every
ray carries a cone ``(r0, s)``, radius ``r0 + s t`` at distance ``t``, and the field is
traced as that cone's footprint field (octaves finer than the cone skipped) with a
cone-tracing hit tolerance (:mod:`.sphere_tracer`). Camera rays start with ``r0 = 0``
and ``s`` = half the pixel's angle (:meth:`ImplicitPathIntegrator.camera_cone`). At a hit
the cone's radius there becomes the next rays' ``r0``; shadow rays keep ``s``,
BSDF-sampled rays widen it by ``lod_bounce_spread`` (a diffuse bounce averages
light over a wide solid angle, so its ray needs far less detail; Christensen et
al. 2003 widen diffuse rays' differentials for the same reason) unless the sampled
lobe is a delta.

References
----------
Christensen, P. H. et al. (2003). Ray differentials and multiresolution geometry
caching for distribution ray tracing in complex scenes. CGF 22(3).
Veach, E. (1997). Robust Monte Carlo methods for light transport simulation. PhD
thesis, Stanford (MIS, power heuristic).
Jakob, W. et al. (2022). Mitsuba 3 renderer, ``path`` integrator.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..backend import variant_class
from .aovs import (DEPTH_CHANNEL, MOMENT_CHANNELS, RAY_COUNT_KINDS, aov_channel_names, count_rays,
                   first_vertex_aovs, second_moments)
from .heightfield_caster import make_tracer
from .march import position_ulps
from .path_state import PathState
from .shading_normals import facing_shading_frame

__all__ = ["ImplicitPathIntegrator", "mis_weight", "register"]


def mis_weight(pdf_a, pdf_b):
    """Power heuristic (beta = 2) weight of strategy ``a``."""
    a2 = dr.square(pdf_a)
    return dr.detach(dr.select(pdf_a > 0, a2 / dr.fma(pdf_b, pdf_b, a2), 0.0))


class _ImplicitPathImpl:
    """Path tracer for scenes holding meshes and one implicit field (see module doc).

    The body of :class:`ImplicitPathIntegrator`, a ``mi.SamplingIntegrator`` of the
    active variant (:func:`integrator_class`).

    Properties: ``max_depth`` (default 6, -1 = unbounded), ``rr_depth`` (5),
    ``hide_emitters`` (false), ``eps`` (relative hit tolerance, 2e-4), ``omega``
    (over-relaxation, 1.6), ``max_steps`` (512), ``aovs`` (false: return the AOVs
    of :mod:`arches_render.render.aovs`), ``moments`` (false: with ``aovs``, also the
    per-sample squares of the beauty, its luminance and the depth, layer ``moment2``,
    from which a render's per-pixel sample variance follows), ``heightfield_cast`` (true: ray-cast
    heightfield trees, :mod:`arches_render.render.heightfield_caster`; false:
    sphere-trace every field, for comparisons), ``lod`` (true: footprint level of
    detail, see the module docstring), ``lod_bounce_spread`` (0.1 rad: the cone
    spread a non-delta bounce adds), ``surface_cells`` (false: trace fields that no
    heightfield cast answers through surface cells, :mod:`.cell_tracer`), ``sun_columns``
    (false: shadow rays towards the sun end where a map in its frame proves the rest
    free, :mod:`.sun_columns`), ``wavefront`` (false: the path loop depth by depth over
    compacted live paths, sphere-traced queries by persistent lanes; the same picture,
    :mod:`.wavefront`).
    """

    def __init__(self, props):
        mi.SamplingIntegrator.__init__(self, props)
        max_depth = props.get("max_depth", 6)
        self.max_depth = 0xFFFFFFFF if max_depth == -1 else int(max_depth)
        self.rr_depth = int(props.get("rr_depth", 5))
        self.hide_emitters = bool(props.get("hide_emitters", False))
        self.eps = float(props.get("eps", 2e-4))
        self.omega = float(props.get("omega", 1.6))
        self.max_steps = int(props.get("max_steps", 512))
        self.aovs = bool(props.get("aovs", False))
        self.moments = bool(props.get("moments", False)) and self.aovs
        self.heightfield_cast = bool(props.get("heightfield_cast", True))
        self.lod = bool(props.get("lod", True))
        self.lod_bounce_spread = float(props.get("lod_bounce_spread", 0.1))
        self.surface_cells = bool(props.get("surface_cells", False))
        self.sun_columns = bool(props.get("sun_columns", False))
        self.wavefront = bool(props.get("wavefront", False))
        self.tracer = None
        self.field_bsdf = None
        self.shaded_bsdf = None
        self.atmosphere = None
        self.mesh_region = None
        self.set_pixel_angle(0.0)

    def attach(self, field, bsdf, sun=None):
        """Give the integrator the field to trace and the BSDF that shades it (heightfield
        trees are ray-cast, others sphere-traced: :func:`make_tracer`); ``sun``, the
        scene's ``(direction, angular radius)`` (:func:`~.sun_columns.scene_sun`), gives a
        sphere tracer its sun map (:mod:`.sun_columns`) when ``sun_columns`` is on."""
        self.tracer = make_tracer(field, eps=self.eps, omega=self.omega, max_steps=self.max_steps,
                                  cast=self.heightfield_cast, cells=self.surface_cells)
        if sun is not None and self.sun_columns and hasattr(self.tracer, "aim_at_sun"):
            self.tracer.aim_at_sun(*sun)
        if self.wavefront and hasattr(self.tracer, "queued"):
            self.tracer.queued = True
        self.field_bsdf = bsdf
        self.shaded_bsdf = bsdf

    def attach_material(self, bsdf):
        """Shade the vertices whose BSDF is ``bsdf`` once per vertex, as the field's are.

        Mitsuba's ``path`` calls ``sample`` and ``eval_pdf`` separately, and each
        shades the vertex again (textures, detail and the cavity's march); here one
        :meth:`shade` serves the AOVs, the light sample and the BSDF sample, and the
        cavity term is computed at camera hits only.

        Parameters
        ----------
        bsdf : mi.BSDF or None
            A BSDF with ``shade`` (``triplanar``): in mesh mode the field's material
            on the field's mesh. ``None``: every BSDF is called as Mitsuba's are.
        """
        self.shaded_bsdf = bsdf

    def attach_mesh_region(self, region):
        """Skip the mesh queries of rays that provably meet no mesh: ``region``, a grown
        :class:`~.mesh_region.MeshRegion` holding the scene's shapes (None: query every ray)."""
        self.mesh_region = region

    def mesh_lanes(self, ray, active):
        """The lanes of ``active`` whose rays may meet a mesh before the field is traced:
        with a field, those that may meet the region's box (the shapes inside the scene:
        a mesh hit there spares the field's steps past it); the skirt (a far field, behind
        the tile's field) is asked after the field, with the ray cut at its hit
        (:meth:`skirt_lanes`). Without a field, any part of the region."""
        region = self.mesh_region
        if region is None:
            return active
        if self.tracer is None:
            return active & region.may_meet(ray.o, ray.d, ray.maxt)
        return active & region.may_meet_box(ray.o, ray.d, ray.maxt)

    def skirt_lanes(self, ray, tmax, active):
        """The lanes of ``active`` whose segments ``[0, tmax]`` may meet the region's skirt
        (None: no skirt to ask after the field)."""
        region = self.mesh_region
        if region is None or region.skirt is None or self.tracer is None:
            return None
        return active & region.may_meet_skirt(ray.o, ray.d, tmax)

    def attach_atmosphere(self, atmosphere):
        """Fog every path segment with an :class:`~arches_render.render.atmosphere.Atmosphere` (None: off)."""
        self.atmosphere = atmosphere

    # -- ray queries ------------------------------------------------------------
    def set_pixel_angle(self, angle):
        """The camera's pixel angle in radians (``2 tan(fov/2) / width``; 0: full detail),
        an opaque value: a new camera or film size compiles nothing."""
        self.pixel_angle = dr.opaque(mi.Float, float(angle))

    def camera_cone(self, sampler, ray):
        """``(r0, s)`` of camera rays (module docstring), or ``None`` without level of detail.

        ``s`` is half the pixel angle at the image's centre (:meth:`set_pixel_angle`;
        towards the edges a pixel subtends up to ``1 / cos`` of the half field of
        view less, so the cone is a little wide there: 10 % at 50 degrees). Not from
        the ray differentials: Mitsuba scales those by ``1/sqrt(spp)`` as a constant
        of the kernel, so every new pass size compiled the whole integrator again.
        """
        if not self.lod:
            return None
        return mi.Float(0.0), mi.Float(0.5 * self.pixel_angle)

    def intersect(self, scene, ray, active, cone=None, coherent=False, t_min=None):
        """Nearest hit among meshes and the field.

        Parameters
        ----------
        scene, ray, active
            The scene, the rays and their lanes.
        cone : (mi.Float, mi.Float), optional
            The rays' cones (module docstring).
        coherent : bool
            Camera rays (:meth:`.SphereTracer.query`).
        t_min : mi.Float, optional
            Where the field's query may start (:meth:`camera_starts`).

        Returns
        -------
        (mi.SurfaceInteraction3f, mi.Bool, TraceResult or None)
            The hit, whether it is on the field, and the field query's result
            (:class:`~.march.TraceResult`; None without a field).
        """
        asked = self.mesh_lanes(ray, active)
        si = scene.ray_intersect(ray, mi.RayFlags.All, coherent=False, active=asked)
        if self.tracer is None:
            return facing_shading_frame(si, ray.d), mi.Bool(False), None
        tmax = dr.select(si.is_valid(), si.t, ray.maxt)
        res = self.tracer.query(ray.o, ray.d, tmax, active, cone, coherent=coherent, t_min=t_min)
        hit, t = res.hit, res.t
        # Normals (four gradient taps and a value) only where the field was hit:
        # packets without such a lane skip them.
        def on_surface(o, d, t, cone):
            p, n = self.tracer.surface(o + d * t, t, d, cone or None)
            return mi.Point3f(p), mi.Vector3f(n)

        p, n = dr.if_stmt((ray.o, ray.d, t, cone or ()), hit, on_surface,
                          lambda o, d, t, cone: (mi.Point3f(o + d * t), mi.Vector3f(-d)), label="field_surface")
        # The skirt (a far field) is asked after the field, up to the field's projected
        # hit (the rule below), by the lanes not asked yet whose segment may reach it.
        t_end = dr.select(hit, dr.dot(p - ray.o, ray.d), tmax)
        late = self.skirt_lanes(ray, t_end, active & ~asked)
        if late is not None:
            cut = mi.Ray3f(ray.o, ray.d, t_end, ray.time, ray.wavelengths)
            si = dr.select(late, scene.ray_intersect(cut, mi.RayFlags.All, coherent=False, active=late), si)
        si = facing_shading_frame(si, ray.d)  # no black lines below a mesh's silhouettes
        # The field stops up to its hit tolerance off its surface, in front of a mesh lying
        # on it (a far field's frame, a few centimetres over the DEM's border band), and
        # its hit is then projected onto the surface: behind that mesh, which then blocked
        # every ray leaving the point (a black line along the tile's border). Where the
        # projected point lies behind the mesh's hit, the mesh is what the ray sees.
        hit &= ~(si.is_valid() & (dr.dot(p - ray.o, ray.d) > si.t))
        # Lift the point off the surface so that rays spawned here start in air: a
        # tenth of the hit tolerance, at least a few float32 ulps of the position (a
        # fixed fraction of the scene's size would be metres on a 1000 km tile).
        offset = dr.maximum(0.1 * self.tracer.eps * t, position_ulps(p, 32.0))
        sf = dr.zeros(mi.SurfaceInteraction3f)
        sf.t = t
        sf.p = p + n * offset
        sf.n = n
        sf.sh_frame = mi.Frame3f(n)
        sf.wi = sf.to_local(-ray.d)
        sf.time = ray.time
        sf.wavelengths = ray.wavelengths
        si = dr.select(hit, sf, si)
        return si, hit, res

    def occluded(self, scene, ray, active, cone=None):
        """Shadow-ray test against meshes and the field (``cone`` as for :meth:`intersect`);
        returns ``(blocked, TraceResult or None)``."""
        asked = self.mesh_lanes(ray, active)
        blocked = scene.ray_test(ray, asked)
        if self.tracer is None:
            return blocked, None
        res = self.tracer.query(ray.o, ray.d, ray.maxt, active & ~blocked, cone, any_hit=True)
        blocked |= res.hit
        late = self.skirt_lanes(ray, ray.maxt, active & ~asked & ~blocked)  # the far field last
        if late is not None:
            blocked |= scene.ray_test(ray, late)
        return blocked, res

    def bsdf_at(self, si, ray, field_hit):
        if self.tracer is None:
            return si.bsdf(ray)
        return dr.select(field_hit, mi.BSDFPtr(self.field_bsdf), si.bsdf(ray))

    # -- estimator ---------------------------------------------------------------
    def sample(self, scene, sampler, ray, medium=None, active=True):
        """One path per lane (module docstring): ``(L, valid, aovs)``, in Mitsuba's
        megakernel or, with ``wavefront``, depth by depth (:mod:`.wavefront`)."""
        if self.wavefront:
            from .wavefront import wavefront_sample
            return wavefront_sample(self, scene, sampler, ray, active)
        return self.sample_megakernel(scene, sampler, ray, active)

    def start_paths(self, sampler, ray, active, width=None):
        """The :class:`~.path_state.PathState` of paths about to trace camera rays ``ray``
        (``width``: as :meth:`.PathState.start`)."""
        aov = self.primary_aov_count() if self.aovs else 0
        ray = mi.Ray3f(ray)
        # The camera's time, which every vertex passes on unchanged, as an array: as a
        # width-1 literal it made Dr.Jit record the path loop twice (sample_megakernel).
        ray.time = ray.time + dr.zeros(mi.Float, dr.width(ray.d))
        return PathState.start(ray, active, self.camera_cone(sampler, ray) or (),
                               self.atmosphere is not None and self.aovs, aov,
                               2 * len(RAY_COUNT_KINDS) if aov and self.tracer else 0, width)

    def camera_starts(self, path):
        """Where the camera rays of ``path`` (a :class:`~.path_state.PathState` as
        :meth:`start_paths` made it) may start their field queries, marched in bundles
        (:mod:`.ray_bundles`); None when the tracer does not bundle (casts, meshes)."""
        if not hasattr(self.tracer, "bundle_starts"):
            return None
        ray = path.ray
        return self.tracer.bundle_starts(ray.o, ray.d, ray.maxt, path.active, path.cone or None)

    @dr.syntax
    def sample_megakernel(self, scene, sampler, ray, active=True):
        """:meth:`sample` as one symbolic loop over :meth:`path_vertex`.

        Python traces each loop's body once. Dr.Jit records a symbolic loop's body
        again when the loop's state holds a variable the body leaves unchanged: with
        ``OptimizeLoops`` (the default) to drop it from the loop, without it when it is
        a width-1 value. Loops in loops multiplied the recordings: a quarter to a third
        of a 160x90 render was tracing. So every loop keeps its read-only values out of
        its state (``dr.hint(..., exclude=...)``). This loop's state is the paths and
        the sampler; the camera rays' time, which the paths carry unchanged, stays in
        it with the optimisation off for this loop only (one phi), on again for the
        loops inside. ``tests/test_render.py`` checks that each body is traced once."""
        ctx = mi.BSDFContext()
        path = self.start_paths(sampler, ray, active)
        t_min = self.camera_starts(path)
        with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, False):
            while dr.hint(path.active, label="implicit_path", exclude=[self, scene, ctx, t_min]):
                with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, True):
                    path = self.path_vertex(scene, sampler, ctx, path, t_min=t_min)
        return path.L, path.valid, self.outputs(path.L, path.aov, path.clear, path.counts)

    def path_vertex(self, scene, sampler, ctx, path, coherent=False, t_min=None):
        """One vertex of the paths ``path`` (a :class:`~.path_state.PathState`): the ray's
        hit, its fog, emission reached by BSDF sampling, next-event estimation, the BSDF
        sample and Russian roulette; the state after it (``coherent``: every ray a
        camera ray, :meth:`intersect`; ``t_min``: the camera rays' starts,
        :meth:`camera_starts`)."""
        ray, cone, active, depth = path.ray, path.cone, path.active, path.depth
        L, beta, clear, aov, counts = path.L, path.beta, path.clear, path.aov, path.counts
        primary = depth == 0  # lanes whose ray left the camera (a miss ends a path)
        t_min = None if t_min is None else dr.select(primary, t_min, 0.0)
        si, field_hit, res = self.intersect(scene, ray, active, cone or None, coherent, t_min)
        # The cone at the hit: shadow rays keep its spread, bounces widen it.
        hit_cone = (cone[0] + cone[1] * dr.select(si.is_valid(), si.t, 0.0), cone[1]) if cone else ()
        L, beta, clear, tr = self.fog_segment(ray, si, L, beta, clear, active)
        bsdf = self.bsdf_at(si, ray, field_hit)
        # The field's material shaded once per vertex (on the field and on meshes that
        # carry it), for the AOVs, the light sample and the BSDF sample alike; its
        # cavity term at the camera ray's hit.
        shaded = self.shaded_lanes(bsdf, field_hit)
        shading = self.shade_vertex(si, shaded, active & (primary | (depth + 1 < self.max_depth)), primary,
                                    hit_cone)
        aov = first_vertex_aovs(self, scene, ray, si, field_hit, res, tr, active & primary, aov, shading, shaded)
        counts = count_rays(counts, (res, res), (active & primary, active & ~primary), (0, 1))

        # Emission reached by BSDF sampling (environment or area light), MIS-weighted.
        L, clear = self.emission_hit(scene, si, path.prev_si, path.prev_bsdf_pdf, path.prev_bsdf_delta, depth == 0,
                                     L, beta, clear, active)

        active_next = active & si.is_valid() & (depth + 1 < self.max_depth)
        # Next-event estimation and the BSDF sample, then the shadow rays: the vertex's
        # shading is not needed past them (:meth:`light_sample`).
        shadow, lanes, added, added_clear = self.light_sample(scene, sampler, si, bsdf, shading, shaded, ctx, beta,
                                                              clear, active_next)
        bs, bsdf_weight = self.sample_bsdf(bsdf, shading, shaded, ctx, si, sampler.next_1d(),
                                           sampler.next_2d(), active_next)
        # A wavefront's shadow query is a kernel of its own, and Dr.Jit evaluates only what
        # is scheduled: what the vertex reads past it (the hit's frame, the BSDF sample,
        # the shading they came from) would be computed again after it, the material and
        # the normal's four taps twice (goblins: 44k operations a depth, 31k once).
        if not dr.flag(dr.JitFlag.SymbolicScope):  # (a megakernel is one kernel)
            dr.schedule(si, shading, bs, bsdf_weight, shadow, lanes, added, added_clear, hit_cone, active_next,
                        L, beta, clear, aov, counts)
        L, clear, counts = self.shadow_test(scene, shadow, lanes, added, added_clear, hit_cone, L, clear, counts)
        valid = path.valid | (active & si.is_valid())
        beta = beta * bsdf_weight
        clear = (clear[0], clear[1] * bsdf_weight) if clear else ()
        delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        cone = (hit_cone[0], hit_cone[1] + dr.select(delta, 0.0, self.lod_bounce_spread)) if cone else ()
        depth = dr.select(si.is_valid(), depth + 1, depth)
        eta = path.eta * bs.eta
        beta, clear, active = self.roulette(sampler, beta, clear, eta, depth, active_next)
        return PathState(ray=si.spawn_ray(si.to_world(bs.wo)), L=L, beta=beta, eta=eta, depth=depth,
                         active=active, valid=valid, prev_si=dr.detach(si), prev_bsdf_pdf=bs.pdf,
                         prev_bsdf_delta=delta, cone=cone, clear=clear, aov=aov, counts=counts)

    # -- the parts of a path vertex ----------------------------------------------
    def fog_segment(self, ray, si, L, beta, clear, active):
        """``(L, beta, clear, tr)`` after the segment of ``ray`` up to ``si``: its
        in-scatter added and its transmittance ``tr`` applied (the fog-free path
        ``clear`` is left as it is; ``tr`` is None without an atmosphere)."""
        atm = self.atmosphere
        if atm is None:
            return L, beta, clear, None
        tr, L_in = atm.segment(ray.o, ray.d, atm.segment_length(ray, si))
        return dr.select(active, L + beta * L_in, L), dr.select(active, beta * tr, beta), clear, tr

    def shaded_lanes(self, bsdf, field_hit):
        """Lanes shaded once per vertex by :attr:`shaded_bsdf`.

        Parameters
        ----------
        bsdf : mi.BSDFPtr
            The vertices' BSDFs (:meth:`bsdf_at`).
        field_hit : mi.Bool
            Field hits.

        Returns
        -------
        mi.Bool
            Field hits and mesh hits that carry the same material (``field_hit``
            when no material shades once).
        """
        if not self.shades_once:
            return field_hit
        return bsdf == mi.BSDFPtr(self.shaded_bsdf)

    def shade_vertex(self, si, shaded, needed, primary, hit_cone):
        """The shading of the vertex by :attr:`shaded_bsdf` (None when it cannot shade once
        for all its queries): where ``needed`` on the lanes ``shaded``, with its cavity
        term on camera rays' hits."""
        if not self.shades_once:
            return None
        return self.shaded_bsdf.shade(si, needed & si.is_valid() & shaded, cavity=primary,
                                      cone_radius=hit_cone[0] if hit_cone else None)

    def emission_hit(self, scene, si, prev_si, prev_pdf, prev_delta, first, L, beta, clear, active):
        """``(L, clear)`` with the emission that BSDF sampling reached at ``si``, weighted by
        MIS against emitter sampling (``first``: camera rays, which ``hide_emitters`` hides)."""
        ds = mi.DirectionSample3f(scene, si, prev_si)
        em_pdf = mi.Float(0.0)
        em_pdf[~prev_delta] = scene.pdf_emitter_direction(prev_si, ds, ~prev_delta)
        visible = mi.Bool(active)
        if self.hide_emitters:
            visible &= ~(first & ~si.is_valid())
        Le = ds.emitter.eval(si, visible & (prev_pdf > 0))
        w = mis_weight(prev_pdf, em_pdf)
        L = dr.select(visible, L + beta * w * Le, L)
        if clear:
            clear = (dr.select(visible, clear[0] + clear[1] * w * Le, clear[0]), clear[1])
        return L, clear

    def light_sample(self, scene, sampler, si, bsdf, shading, shaded, ctx, beta, clear, active):
        """Next-event estimation at ``si`` before its shadow ray: ``(shadow, lanes, added,
        added_clear)``, one emitter sample's shadow ray, the lanes that trace it, and the
        MIS-weighted radiance it adds (to ``L`` and to the fog-free path's) where that ray
        is free. Why before: the shadow query then splits nothing a wavefront must keep
        in memory across it but these (:mod:`.wavefront`).

        A BSDF that reflects on its front side only (no transmission, no back side:
        Mitsuba's ``diffuse``, the ``triplanar`` material) is 0 unless both directions
        lie above its shading frame, so no shadow ray is traced where the light is
        below the surface: on a landscape at a low sun about half of them."""
        active_em = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
        ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), False, active_em)
        active_em &= ds.pdf != 0.0
        wo = si.to_local(ds.d)
        front_only = ~mi.has_flag(bsdf.flags(), mi.BSDFFlags.Transmission) & \
            ~mi.has_flag(bsdf.flags(), mi.BSDFFlags.BackSide)
        active_em &= ~front_only | ((mi.Frame3f.cos_theta(si.wi) > 0.0) & (mi.Frame3f.cos_theta(wo) > 0.0))
        shadow = si.spawn_ray_to(ds.p)
        shadow.maxt = dr.select(ds.delta | (ds.dist < dr.inf), shadow.maxt, dr.inf)
        bsdf_val, bsdf_pdf = self.eval_pdf(bsdf, shading, shaded, ctx, si, wo, active_em)
        mis = dr.select(ds.delta, 1.0, mis_weight(ds.pdf, bsdf_pdf))
        added_clear = clear[1] * mis * bsdf_val * em_weight if clear else None
        if self.atmosphere is not None:
            em_weight = em_weight * self.atmosphere.shadow_transmittance(si, ds)
        return shadow, active_em, beta * mis * bsdf_val * em_weight, added_clear

    def shadow_test(self, scene, shadow, lanes, added, added_clear, hit_cone, L, clear, counts):
        """``(L, clear, counts)`` after the shadow rays of :meth:`light_sample`: its
        radiance added where they are free, their exhausted and unresolved lanes counted."""
        blocked, res = self.occluded(scene, shadow, lanes, hit_cone or None)
        counts = count_rays(counts, (res,), (lanes,), (2,))
        lit = lanes & ~blocked
        if clear:
            clear = (dr.select(lit, clear[0] + added_clear, clear[0]), clear[1])
        return dr.select(lit, L + added, L), clear, counts

    def roulette(self, sampler, beta, clear, eta, depth, active):
        """Russian roulette from ``rr_depth``, continuation probability
        ``min(max(beta) eta^2, 0.95)``: ``(beta, clear, active)``."""
        beta_max = dr.max(beta)
        # A fog-free path goes on where dense fog has zeroed the fogged throughput.
        active = active & ((dr.max(clear[1]) if clear else beta_max) != 0.0)
        rr_prob = dr.minimum(beta_max * dr.square(eta), 0.95)
        rr_active = depth >= self.rr_depth
        beta = dr.select(rr_active, beta * dr.rcp(rr_prob), beta)
        if clear:
            clear = (clear[0], dr.select(rr_active, clear[1] * dr.rcp(rr_prob), clear[1]))
        rr_continue = sampler.next_1d() < rr_prob
        return beta, clear, active & (~rr_active | rr_continue)

    def outputs(self, L, aov, clear, counts):
        """The AOV channels of a finished path, in the order of :meth:`aov_names`."""
        if not self.aovs:
            return []
        out = list(aov)
        if self.atmosphere is not None:
            out += [clear[0].x, clear[0].y, clear[0].z]
        out += list(counts)
        if self.moments:
            out += second_moments(L, out[DEPTH_CHANNEL])
        return out

    def primary_aov_count(self):
        """Channels that :func:`~.aovs.first_vertex_aovs` fills (all but the ray counts, ``beauty_clear``
        and ``moment2``)."""
        counted = 2 * len(RAY_COUNT_KINDS) if self.tracer is not None else 0
        later = (3 if self.atmosphere is not None else 0) + (len(MOMENT_CHANNELS) if self.moments else 0)
        return len(self.aov_names()) - counted - later

    @property
    def shades_once(self):
        """Whether :attr:`shaded_bsdf` can shade a vertex once for all its queries (``shade``,
        and ``shaded_elsewhere`` for the calls on the other lanes)."""
        return hasattr(self.shaded_bsdf, "shade")

    def eval_pdf(self, bsdf, shading, shaded, ctx, si, wo, active):
        """``bsdf.eval_pdf``, with the ``shaded`` lanes from their ``shading``."""
        if shading is None:
            return bsdf.eval_pdf(ctx, si, wo, active)
        vf, pf = self.shaded_bsdf.eval_pdf(ctx, si, wo, active & shaded, shading)
        with self.shaded_bsdf.shaded_elsewhere():
            vm, pm = bsdf.eval_pdf(ctx, si, wo, active & ~shaded)
        return dr.select(shaded, vf, vm), dr.select(shaded, pf, pm)

    def sample_bsdf(self, bsdf, shading, shaded, ctx, si, sample1, sample2, active):
        """``bsdf.sample``, with the ``shaded`` lanes from their ``shading``."""
        if shading is None:
            return bsdf.sample(ctx, si, sample1, sample2, active)
        bf, wf = self.shaded_bsdf.sample(ctx, si, sample1, sample2, active & shaded, shading)
        with self.shaded_bsdf.shaded_elsewhere():
            bm, wm = bsdf.sample(ctx, si, sample1, sample2, active & ~shaded)
        return dr.select(shaded, bf, bm), dr.select(shaded, wf, wm)

    def aov_names(self):
        if not self.aovs:
            return []
        return aov_channel_names(self.field_bsdf if self.tracer else None, self.atmosphere is not None,
                                 self.tracer is not None, self.moments)

    def to_string(self):
        return (f"ImplicitPathIntegrator[max_depth={self.max_depth}, rr_depth={self.rr_depth}, "
                f"field={'attached' if self.tracer else 'none'}]")


def integrator_class():
    """:class:`ImplicitPathIntegrator` bound to the active variant's ``mi.SamplingIntegrator``."""
    return variant_class("ImplicitPathIntegrator", _ImplicitPathImpl, "SamplingIntegrator")


def __getattr__(name):
    # ``ImplicitPathIntegrator`` depends on the variant chosen at run time, hence lazy.
    if name == "ImplicitPathIntegrator":
        return integrator_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register() -> None:
    """Register ``implicit_path`` with Mitsuba for the active variant (idempotent)."""
    cls = integrator_class()
    mi.register_integrator("implicit_path", lambda props: cls(props))
