"""The ``triplanar`` BSDF: layered, triplanar-textured Oren–Nayar terrain material.

Terrains of arbitrary topology (arches, overhangs, caves) have no usable
``(u, v)`` parameterisation, so every layer is textured by three axis-aligned
projections blended by the shading normal (Peytavie et al. 2009, section 6,
after Geiss 2007). Layers stack like paint: layer 0 is the base, each later
layer covers what lies below it where its height, slope and field-mask rules
hold.

Shading model, per shading point ``p`` with normal ``n``:

* projection weights ``b_k = |n_k|^s / sum_j |n_j|^s`` (``s = sharpness``),
* layer texel ``T_i = sum_k b_k tex_i(uv_k / scale_i)`` with
  ``uv_x = (p.y, p.z)``, ``uv_y = (p.x, p.z)``, ``uv_z = (p.x, p.y)``; projections
  with ``b_k < 10^-4`` are dropped and the rest renormalised (error < ``2 10^-4`` of
  the texture's range, :mod:`~arches_render.materials.weights`), and ``tex_i`` is
  looked up on the MIP level of the pixel footprint
  (:mod:`~arches_render.materials.mipmap`),
* layer albedo ``a_i = clamp(tint_i T_i, 0, 1)``,
* coverage ``c_i = coverage_i * H_i(p.z) * S_i(slope) * M_i(p)`` (``c_0 = 1``),
  composite weight ``w_i = c_i prod_{j>i} (1 - c_j)``,
* BRDF: the weighted sum of the layers' qualitative Oren–Nayar lobes.

Cost: a layer whose weight is 0 in every lane of a SIMD packet, and a projection
dropped in every lane, are symbolic branches that the packet skips; so flat ground
under one layer costs one projection of one texture, not three of each layer.

Parameters that change between renders live in opaque Dr.Jit arrays
(editable through :func:`mitsuba.traverse`), so editing them re-uses the
compiled kernels.

Besides the layer stack (each module's docstring holds its math):

* textures tile without visible repetition (``layer{i}_tiling = "histogram"``, the
  default: Heitz and Neyret 2018, :mod:`~arches_render.materials.textures`;
  ``"repeat"`` is the plain repeat, an opt-out);
* a procedural detail layer (``detail_*``): multi-scale noise on albedo and
  roughness and a bump from the same noise, cut off by the pixel footprint
  ``si.t * pixel_spread`` (:mod:`~arches_render.materials.detail`);
* terms read from the terrain (:mod:`~arches_render.materials.masks`): a palette
  of stratum colours indexed by the geology's layer function (``strata_*`` and a
  resistance node), cavity/occlusion from the field (``cavity``), wetness near a
  water level (``wetness``); cavity and wetness also serve as layer masks.

The BRDF of layer ``i`` is evaluated about the bumped normal ``n'`` (cosines
``n' . w``), zero below the geometric shading hemisphere; sampling is cosine
about ``n'``, so ``sample`` and ``eval / pdf`` agree.

References
----------
Peytavie A., Galin E., Grosjean J., Merillou S. (2009). Arches: a framework
for modeling complex terrains. Computer Graphics Forum 28(2), 457–467.

Oren M., Nayar S. K. (1994). Generalization of Lambert's reflectance model.
Proceedings of SIGGRAPH 94, 239–246.
"""

from __future__ import annotations

import contextlib

import drjit as dr
import mitsuba as mi

from ..backend import variant_class
from . import masks as M
from .detail import Detail, footprint
from .mipmap import position_hash
from .textures import TEXTURE_DIR, load_texture, texture_path
from .triplanar_layers import (LAYER_FLOATS, MAX_LAYERS, SPACES, Layer, check_layer_values, colour, finite,
                               layer_count, triplanar_dict)
from .weights import band, blend_projections, composite_weights, projection_slots, smoothstep01, triplanar_weights

__all__ = ["MAX_LAYERS", "TEXTURE_DIR", "STRUCTURAL", "Layer", "triplanar_dict", "texture_path", "register",
           "TriplanarBSDF"]

OBJP_ATTRIBUTE = "vertex_objp"
#: Integer properties that shape the kernels (an edit needs a new plugin, not a parameter edit).
STRUCTURAL = ("layer_count", "detail_octaves", "strata_count", "strata_layer", "cavity_samples")


def _opaque(value, kind):
    v = kind(value)
    dr.make_opaque(v)
    return v


def _object_position(shape, si):
    """Per-shape body of the ``vertex_objp`` lookup (run through ``dr.dispatch``)."""
    try:
        found = shape.has_attribute(OBJP_ATTRIBUTE)
        return mi.Point3f(shape.eval_attribute_3(OBJP_ATTRIBUTE, si)), mi.Bool(found)
    except Exception:  # shapes other than meshes, or meshes without the attribute
        return mi.Point3f(0.0), mi.Bool(False)


class _TriplanarImpl:
    """Variant-independent body of :class:`TriplanarBSDF` (see the module docstring)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        count = layer_count(props, M.look_keys)
        self.space = str(props.get("space", "world"))
        if self.space not in SPACES:
            raise ValueError(f"triplanar: unknown space '{self.space}', allowed: "
                             f"{', '.join(SPACES)}")
        self.sharpness = _opaque(float(props.get("sharpness", 8.0)), mi.Float)
        self.pixel_spread = _opaque(float(props.get("pixel_spread", 0.0)), mi.Float)
        self.layer_count = count
        self.names, self.textures, self.tint, self.masks = [], [], [], [None] * count
        self.params = {k: [] for k in LAYER_FLOATS}
        for i in range(count):
            get = lambda k, d: props.get(f"layer{i}_{k}", d)  # noqa: E731
            vals = {k: float(get(k, d)) for k, d in LAYER_FLOATS.items()}
            check_layer_values(i, vals["roughness"], vals["scale"], vals["coverage"],
                                vals["height_soft"], vals["slope_soft"])
            for k, v in vals.items():
                self.params[k].append(_opaque(finite(v), mi.Float))
            self.tint.append(_opaque(colour(get("tint", (1.0, 1.0, 1.0)), f"layer{i}_tint"),
                                     mi.Color3f))
            name, srgb, norm = str(get("texture", "")), get("srgb", True), get("normalize", True)
            tiling = str(get("tiling", "histogram"))
            # Each layer draws its own tiles (seed i) even where layers share a texture.
            self.textures.append(load_texture(name, bool(srgb), bool(norm), tiling, seed=i) if name else None)
            self.names.append(str(get("name", "")) or f"layer{i}")
        self.detail = Detail.from_props(props)
        self.look = M.Look(props, count)
        self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        self.m_components = [self.m_flags]
        self._elsewhere = False  # (shaded_elsewhere)

    # ----------------------------------------------------------------- public
    def set_layer_mask(self, i: int, node, lo: float = 0.0, hi: float = 1.0, kind: str = "node") -> None:
        """Multiply layer ``i``'s coverage by ``smoothstep(lo, hi, m(p))``.

        Parameters
        ----------
        i : int
            Layer index, ``1 <= i < layer_count`` (layer 0 is always covered).
        node : object or None
            For ``kind = 'node'``: anything with ``eval(p: mi.Point3f) -> mi.Float``
            (a field node, a noise, a resistance); ``m = node.eval(p)`` at the
            shading position (object space when ``space == 'object'``). ``None``
            with ``kind = 'node'`` removes the mask.
        lo, hi : float
            Values mapped to coverage 0 and 1 (``hi < lo`` inverts).
        kind : str
            ``'node'``, ``'cavity'`` (``m`` = the occlusion ``o``) or ``'wetness'``
            (``m`` = the wetness ``w``), see :mod:`~arches_render.materials.masks`.

        Notes
        -----
        A new node changes the kernel code, so the next render compiles;
        ``lo``/``hi`` are opaque (keys ``layer{i}_mask_lo``/``_hi``).
        """
        if not 1 <= i < self.layer_count:
            raise ValueError(f"triplanar: mask layer {i} is outside 1..{self.layer_count - 1} "
                             "(layer 0, the base, is always fully covered)")
        if kind not in M.MASK_KINDS:
            raise ValueError(f"triplanar: mask kind '{kind}' is not one of {', '.join(M.MASK_KINDS)}")
        remove = node is None and kind == "node"
        self.masks[i] = None if remove else (
            node, _opaque(float(lo), mi.Float), _opaque(float(hi), mi.Float), kind)

    def set_node(self, role: str, node) -> None:
        """Attach the node a look term reads.

        Parameters
        ----------
        role : str
            ``'strata'`` (a resistance node: its value ``rho`` indexes the palette)
            or ``'cavity'`` (the field whose occlusion darkens cavities).
        node : object or None
            Anything with ``eval(p)``; ``None`` detaches.
        """
        self.look.set_node(role, node)

    def position(self, si, active=True):
        """Shading position: ``si.p``, or ``vertex_objp`` in object space where a mesh has it.

        Parameters
        ----------
        si : mi.SurfaceInteraction3f
        active : mi.Bool

        Returns
        -------
        mi.Point3f
        """
        if self.space != "object":
            return mi.Point3f(si.p)
        objp, found = dr.dispatch(si.shape, _object_position, si)
        return dr.select(mi.Bool(active) & found, objp, si.p)

    def layer_weights(self, si, active=True):
        """Composite weight of every layer at ``si`` (they sum to 1).

        Parameters
        ----------
        si : mi.SurfaceInteraction3f
            Needs ``p``, ``sh_frame`` (and ``shape``/``prim_index`` in object space).
        active : mi.Bool

        Returns
        -------
        list of mi.Float
        """
        active = mi.Bool(active)
        occ, wet = self._terrain_terms(si, active)
        return self._weights(si, self.position(si, active), occ, wet, {})

    def albedo(self, si, active=True):
        """Blended diffuse albedo ``sum_i w_i a_i`` at ``si`` (linear RGB), with detail and look terms.

        Parameters
        ----------
        si : mi.SurfaceInteraction3f
        active : mi.Bool

        Returns
        -------
        mi.Color3f
        """
        return self.shade(si, active)[0]

    # ------------------------------------------------------------ internals
    def _terrain_terms(self, si, active, cavity=True):
        """Occlusion and wetness at ``si`` (zeros where the material has neither);
        the occlusion only on the lanes ``cavity`` (0 elsewhere)."""
        if not (self.look.cavity or self.look.wetness):
            return mi.Float(0.0), mi.Float(0.0)
        occ = self.look.occlusion(mi.Point3f(si.p), mi.Vector3f(si.sh_frame.n), mi.Bool(active) & cavity)
        return occ, self.look.wet(si.p, occ)

    def _weights(self, si, p, occ, wet, values):
        """Composite weights; ``values`` caches the mask nodes' values (:func:`.masks.node_value`)."""
        n = si.sh_frame.n
        slope = dr.acos(dr.clip(n.z, -1.0, 1.0)) * (180.0 / dr.pi)
        cov = [None]
        P = self.params
        for i in range(1, self.layer_count):
            c = P["coverage"][i] * band(p.z, P["height_min"][i], P["height_max"][i],
                                         P["height_soft"][i]) \
                * band(slope, P["slope_min"][i], P["slope_max"][i], P["slope_soft"][i])
            if self.masks[i] is not None:
                node, lo, hi, kind = self.masks[i]
                span = hi - lo
                m = {"cavity": occ, "wetness": wet}.get(kind)
                m = M.node_value(values, node, p) if m is None else m
                t = (m - lo) / dr.select(span == 0.0, 1e-20, span)
                c = c * smoothstep01(t)
            cov.append(dr.clip(c, 0.0, 1.0))
        return composite_weights(cov)

    def _texel(self, i, slots, fp, xi):
        """Triplanar texture value of layer ``i`` (a Color3f, 1 where untextured): the blend of
        its projections (``slots``, :func:`~.weights.blend_projections`), each looked up at the
        MIP level of the footprint ``fp`` (metres) chosen by ``xi``."""
        tex = self.textures[i]
        if tex is None:
            return mi.Color3f(1.0)
        inv = dr.rcp(self.params["scale"][i])
        texels = fp * inv * tex.texels  # the footprint in texels
        return blend_projections(lambda uv, on: tex.eval(uv * inv, texels, on, xi), slots)

    def shade(self, si, active=True, cavity=True, cone_radius=None):
        """The shading of ``si``, computed once and shared by :meth:`sample` and
        :meth:`eval_pdf` (their ``shading`` argument).

        A layer whose weight ``w_i`` is 0 in every lane of a SIMD packet is not
        evaluated there (a symbolic branch): its texture lookups and, for the
        strata layer, the resistance node are skipped. Untextured layers other
        than the strata layer cost a few multiplies and take no branch.

        Parameters
        ----------
        si : mi.SurfaceInteraction3f
        active : mi.Bool
        cavity : mi.Bool or bool
            Lanes that compute the cavity term (a march of field evaluations; the
            integrator asks for it at the camera ray's hit only).
        cone_radius : mi.Float, optional
            The integrator's ray-cone radius at ``si``, for the footprint
            (:func:`~arches_render.materials.detail.footprint`) that picks the MIP
            level and fades the detail.

        Returns
        -------
        tuple
            ``(albedo, ca, cb, n_local)``: the albedo ``sum w a``, the two Oren-Nayar
            colour terms ``sum w a A`` and ``sum w a B`` (``mi.Color3f``), and the
            bumped normal in the local frame (``mi.Vector3f``). Inactive lanes hold zeros.
        """
        active = mi.Bool(active)
        p = self.position(si, active)
        occ, wet = self._terrain_terms(si, active, cavity)
        values = {}
        w = self._weights(si, p, occ, wet, values)
        gate = M.node_value(values, self.look.nodes["strata_blocks_gate"], p) if self.look.blocks else None
        n = mi.Vector3f(si.sh_frame.n)
        slots = projection_slots(p, triplanar_weights(n, self.sharpness))
        fp = footprint(si, self.pixel_spread, cone_radius)
        xi = position_hash(p)  # the MIP level choice (materials/mipmap.py)
        a_fac, r_fac, n_local = mi.Float(1.0), mi.Float(1.0), mi.Vector3f(0.0, 0.0, 1.0)
        if self.detail is not None:
            a_fac, r_fac, n_bumped = self.detail.eval(p, n, fp, active)
            n_local = dr.normalize(si.sh_frame.to_local(n_bumped))
        if self.look.wetness or self.look.cavity:
            r_fac = r_fac * self.look.roughness_factor(wet)
        state = (mi.Color3f(0.0), mi.Color3f(0.0), mi.Color3f(0.0))
        for i in range(self.layer_count):
            strata = self.look.strata and i == self.look.strata_layer

            def layer(albedo, ca, cb, i=i, strata=strata):
                tint = self.look.strata_color(si.p) if strata else self.tint[i]
                if strata and gate is not None:  # fallen blocks: the beds of their cliff
                    tint = self.look.blocks_color(si.p, tint, gate)
                a = tint * self._texel(i, slots, fp, xi) * a_fac
                a = self.look.albedo_factor(dr.clip(a, 0.0, 1.0), occ, wet) * w[i]
                s2 = dr.square(dr.clip(self.params["roughness"][i] * r_fac, 0.0, 1.0))
                one_minus_a = 0.5 * s2 / (s2 + 0.33)
                # The directional albedo is A + B G(theta_i) with G < 1/2 (G -> 1/2
                # at grazing), so for sigma < 0.35 the qualitative model reflects
                # more than the albedo near grazing; capping B at 2 (1 - A) keeps
                # the energy <= albedo and leaves rougher layers untouched.
                b_term = dr.minimum(0.45 * s2 / (s2 + 0.09), 2.0 * one_minus_a)
                return albedo + a, ca + a * (1.0 - one_minus_a), cb + a * b_term

            if self.textures[i] is None and not strata:  # a few multiplies: no branch
                state = layer(*state)
            else:
                state = dr.if_stmt(state, active & (w[i] > 0.0), layer, lambda *s: s, label="triplanar_layer")
        albedo, ca, cb = state
        return albedo, ca, cb, n_local

    @contextlib.contextmanager
    def shaded_elsewhere(self):
        """While the integrator, having shaded this material's lanes once (:meth:`shade`),
        calls every BSDF of the scene on the other lanes: none reaches this one, so its
        :meth:`sample` and :meth:`eval_pdf` return zeros without tracing the shading
        (which was half the Python tracing of a small render)."""
        self._elsewhere = True
        try:
            yield
        finally:
            self._elsewhere = False

    def _brdf_cos(self, si, wo, active, shading=None):
        """``f * cos(theta_o') * pi / cos(theta_o')`` (the cosine-sampling weight about the bumped
        normal), the validity mask and the bumped local normal."""
        cos_gi, cos_go = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
        valid = mi.Bool(active) & (cos_gi > 0.0) & (cos_go > 0.0)
        _, ca, cb, nl = self.shade(si, valid) if shading is None else shading
        cos_i, cos_o = dr.dot(si.wi, nl), dr.dot(wo, nl)
        valid &= (cos_i > 0.0) & (cos_o > 0.0)
        # sin(a) tan(b) max(0, cos(dphi)) written without trigonometry:
        # dot(wi, wo) - cos_i cos_o = sin_i sin_o cos(dphi).
        s = dr.dot(si.wi, wo) - cos_i * cos_o
        g = dr.maximum(s, 0.0) / dr.maximum(dr.maximum(cos_i, cos_o), 1e-8)
        return dr.select(valid, ca + cb * g, 0.0), valid, dr.maximum(cos_o, 0.0)

    # ---------------------------------------------------------- BSDF interface
    def sample(self, ctx, si, sample1, sample2, active=True, shading=None):
        """Cosine sample about the bumped normal; the weight is ``eval / pdf``
        (``shading``: :meth:`shade` of ``si``, if the caller has it)."""
        bs = dr.zeros(mi.BSDFSample3f)
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection) or self._elsewhere:
            return bs, mi.Color3f(0.0)
        active = mi.Bool(active)
        if shading is None:
            shading = self.shade(si, active & (mi.Frame3f.cos_theta(si.wi) > 0.0))
        wo = mi.Frame3f(shading[3]).to_world(mi.warp.square_to_cosine_hemisphere(sample2))
        weight, valid, cos_o = self._brdf_cos(si, wo, active, shading)
        bs.wo = wo
        bs.pdf = dr.select(valid, cos_o * dr.inv_pi, 0.0)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
        bs.sampled_component = mi.UInt32(0)
        return bs, weight

    def eval(self, ctx, si, wo, active=True):
        """BRDF times ``cos(theta_o')`` about the bumped normal; zero below the surface on either side."""
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection):
            return mi.Color3f(0.0)
        value, _, cos_o = self._brdf_cos(si, wo, active)
        return value * dr.inv_pi * cos_o

    def pdf(self, ctx, si, wo, active=True):
        """Cosine density of ``wo`` about the bumped normal."""
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection):
            return mi.Float(0.0)
        _, valid, cos_o = self._brdf_cos(si, wo, active)
        return dr.select(valid, cos_o * dr.inv_pi, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True, shading=None):
        """``(eval, pdf)`` sharing one shading evaluation (``shading``: as for :meth:`sample`)."""
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection) or self._elsewhere:
            return mi.Color3f(0.0), mi.Float(0.0)
        value, valid, cos_o = self._brdf_cos(si, wo, active, shading)
        return value * dr.inv_pi * cos_o, dr.select(valid, cos_o * dr.inv_pi, 0.0)

    def eval_diffuse_reflectance(self, si, active=True):
        """Blended albedo (used by Mitsuba's AOV integrator and denoiser guides)."""
        return self.albedo(si, active)

    def traverse(self, callback):
        """Expose the opaque parameters: ``sharpness``, ``pixel_spread``, ``layer{i}_tint``,
        ``layer{i}_<rule>``, ``layer{i}_mask_lo/hi`` and those of the detail and look terms."""
        callback.put("sharpness", self.sharpness, mi.ParamFlags.NonDifferentiable)
        callback.put("pixel_spread", self.pixel_spread, mi.ParamFlags.NonDifferentiable)
        differentiable = ("roughness", "coverage")
        for i in range(self.layer_count):
            callback.put(f"layer{i}_tint", self.tint[i], 0)
            for k in LAYER_FLOATS:
                flags = 0 if k in differentiable else mi.ParamFlags.NonDifferentiable
                callback.put(f"layer{i}_{k}", self.params[k][i], flags)
            if self.masks[i] is not None:
                callback.put(f"layer{i}_mask_lo", self.masks[i][1], mi.ParamFlags.NonDifferentiable)
                callback.put(f"layer{i}_mask_hi", self.masks[i][2], mi.ParamFlags.NonDifferentiable)
        if self.detail is not None:
            self.detail.traverse(callback)
        self.look.traverse(callback)

    def parameters_changed(self, keys=None):
        """Make edited values opaque again: written literals would otherwise bake into kernels."""
        dr.make_opaque(self.sharpness, self.pixel_spread, self.tint, self.params,
                       [m[1:3] for m in self.masks if m is not None], self.look.opaque(),
                       self.detail.params if self.detail is not None else [])

    def to_string(self):
        return (f"TriplanarBSDF[space={self.space}, layers={self.names}, "
                f"textured={[t is not None for t in self.textures]}, detail={self.detail is not None}, "
                f"strata={self.look.strata}, cavity={self.look.cavity}, wetness={self.look.wetness}]")


def _bsdf_class():
    """:class:`TriplanarBSDF` bound to the active variant's ``mi.BSDF``."""
    return variant_class("TriplanarBSDF", _TriplanarImpl, "BSDF")


def __getattr__(name):
    # ``TriplanarBSDF`` depends on the variant chosen at run time, hence lazy.
    if name == "TriplanarBSDF":
        return _bsdf_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register() -> None:
    """Register the ``triplanar`` BSDF plugin for the active variant (idempotent).

    Raises
    ------
    RuntimeError
        When no Mitsuba variant is selected.
    """
    cls = _bsdf_class()
    mi.register_bsdf("triplanar", lambda props: cls(props))
