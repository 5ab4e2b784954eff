"""Arbitrary output variables (AOVs) of the primary hit, as EXR layers.

The ``implicit_path`` integrator (with ``aovs = true``) returns, per sample, the
following values of the first surface the camera ray meets (mesh or field), and
the film averages them over the pixel like the beauty (box filter):

===============  ========================  ================================================
layer            channels                  value (0 where the ray escapes)
===============  ========================  ================================================
``albedo``       R, G, B                   diffuse reflectance ``rho`` of the BSDF at the hit
                                           (for ``triplanar``: ``sum_i w_i a_i``), linear
``normal``       X, Y, Z                   world-space shading normal (unit length where a
                                           pixel holds one surface)
``depth``        Z                         distance from the camera centre to the hit, metres
``position``     X, Y, Z                   world position of the hit, metres
``coverage``     field, mesh               1 where the hit is on the field / on a mesh
``steps``        N                         field evaluations (sphere steps) along the camera
                                           ray; a heightfield cast's cell visits are not
                                           steps (a pure cast takes none); misses have
                                           steps too: proving a way free takes them
``layers``       one per material layer    composite weight ``w_i`` of each layer of the
                                           field's triplanar material (sums to 1 on the field)
``transmittance`` R, G, B                  with an ``[atmosphere]``: transmittance ``Tr`` of
                                           the camera ray up to its hit (misses: up to where
                                           it leaves the scene box), 1 without fog
``beauty_clear`` R, G, B                   with an ``[atmosphere]``: the fog-free beauty of the
                                           same paths (no in-scatter, no extinction), for
                                           compositing; the same estimator as a render
                                           without ``[atmosphere]``, not the same bits
``exhausted``    primary, bounce, shadow   rays of the pixel's paths (per sample) that used up
                                           the field tracer's first step budget and took its
                                           second (:mod:`arches_render.render.march`);
                                           with a traced field only
``unresolved``   primary, bounce, shadow   rays that used up the second budget too, resolved
                                           conservatively (a hit at the last point, a shadow
                                           ray occluded): a bug to find, never a silent miss
``moment2``      R, G, B, Y, Z             with ``moments = true``: the mean of the squared
                                           samples of the beauty's channels, of its Rec.709
                                           luminance Y and of the depth; with the beauty and
                                           the depth layer they give each pixel's sample
                                           variance ``n / (n - 1) (E[x^2] - E[x]^2)``, which
                                           the golden tests need (:mod:`arches_render.imaging.welch`)
===============  ========================  ================================================

With an atmosphere a compositor can rebuild the fogged image from layers:
``beauty ~ beauty_clear * transmittance + in-scatter`` holds exactly for the
camera segment, and approximately for the whole path (bounce segments are fogged
too).

Pixels on a silhouette hold the average of the surfaces they see (a normal there
is shorter than 1, a depth between two distances): these are the usual
"filtered" AOVs that a compositor and a denoiser expect.

References
----------
Jakob, W. et al. (2022). Mitsuba 3 renderer, ``aov`` integrator (same definitions
of ``albedo``, ``sh_normal``, ``depth`` and ``position``).
Kainz, F. et al. "Technical Introduction to OpenEXR" (layer.channel naming).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..imaging.compare import LUMINANCE_WEIGHTS

__all__ = ["BASE_LAYERS", "MOMENT_CHANNELS", "DEPTH_CHANNEL", "second_moments", "RAY_COUNT_KINDS", "count_rays",
           "ray_count_header", "ATMOSPHERE_LAYERS", "aov_channel_names", "primary_aovs", "first_vertex_aovs",
           "split_channels", "layer_names_of"]

#: Kinds of rays counted in the ``exhausted`` and ``unresolved`` layers (their channels).
RAY_COUNT_KINDS = ("primary", "bounce", "shadow")

#: Layers of renders with an atmosphere, after the material layers (in this order).
ATMOSPHERE_LAYERS = (("transmittance", ("R", "G", "B")), ("beauty_clear", ("R", "G", "B")))

#: Layers every AOV render has, with their channel letters.
BASE_LAYERS = (("albedo", ("R", "G", "B")), ("normal", ("X", "Y", "Z")), ("depth", ("Z",)),
               ("position", ("X", "Y", "Z")), ("coverage", ("field", "mesh")), ("steps", ("N",)))


#: Channels of the ``moment2`` layer: squared beauty R, G, B, squared luminance, squared depth.
MOMENT_CHANNELS = ("R", "G", "B", "Y", "Z")

#: Index of ``depth.Z`` among the AOV channels (after albedo and normal).
DEPTH_CHANNEL = 6

def second_moments(L, depth) -> list:
    """Per-sample squares of the beauty ``L`` (R, G, B), its luminance and ``depth``,
    in the order of :data:`MOMENT_CHANNELS` (the film averages them into ``E[x^2]``)."""
    wr, wg, wb = LUMINANCE_WEIGHTS
    y = wr * L.x + wg * L.y + wb * L.z
    return [dr.square(L.x), dr.square(L.y), dr.square(L.z), dr.square(y), dr.square(depth)]


def layer_names_of(bsdf) -> list[str]:
    """Layer names of a triplanar BSDF (``[]`` for other BSDFs or ``None``)."""
    names = getattr(bsdf, "names", None) if bsdf is not None else None
    return list(names) if names and hasattr(bsdf, "layer_weights") else []


def aov_channel_names(field_bsdf=None, atmosphere: bool = False, field: bool = False,
                      moments: bool = False) -> list[str]:
    """Film channel names (``layer.channel``) in the order of :func:`primary_aovs`.

    Parameters
    ----------
    field_bsdf : mi.BSDF or None
        The field's BSDF; a triplanar one adds a ``layers.<name>`` channel per layer.
    atmosphere : bool
        Whether the render has an atmosphere (adds :data:`ATMOSPHERE_LAYERS`).
    field : bool
        Whether a field is traced (adds the ``exhausted`` and ``unresolved`` ray counts).
    moments : bool
        Whether the render returns second moments (adds ``moment2``, last).

    Returns
    -------
    list of str
    """
    out = [f"{layer}.{c}" for layer, letters in BASE_LAYERS for c in letters]
    out += [f"layers.{n}" for n in layer_names_of(field_bsdf)]
    if atmosphere:
        out += [f"{layer}.{c}" for layer, letters in ATMOSPHERE_LAYERS for c in letters]
    if field:
        out += [f"{layer}.{k}" for layer in ("exhausted", "unresolved") for k in RAY_COUNT_KINDS]
    if moments:
        out += [f"moment2.{c}" for c in MOMENT_CHANNELS]
    return out


def primary_aovs(si, field_hit, valid, bsdf, field_bsdf=None, depth=None, steps=None, field_albedo=None,
                 shaded=None) -> list:
    """AOV values of a primary hit, one ``mi.Float`` per channel of :func:`aov_channel_names`.

    Parameters
    ----------
    si : mi.SurfaceInteraction3f
        Nearest hit among meshes and field.
    field_hit : mi.Bool
        Whether the hit is on the field.
    valid : mi.Bool
        Active lanes that hit a surface.
    bsdf : mi.BSDFPtr
        BSDF at the hit.
    field_bsdf : mi.BSDF or None
        The field's BSDF (for the layer weights).
    depth : mi.Float, optional
        Distance from the camera centre (default ``si.t``, the distance from
        the ray origin, which a perspective camera puts on its near plane).
    steps : mi.Float, optional
        Steps the field tracer took on the ray (default 0).
    field_albedo : mi.Color3f, optional
        The albedo on the lanes ``shaded``, where the caller has it (else the BSDF's).
    shaded : mi.Bool, optional
        The lanes of ``field_albedo`` (default: ``field_hit``).

    Returns
    -------
    list of mi.Float
    """
    zero = mi.Float(0.0)
    if field_albedo is None:
        albedo = mi.Color3f(bsdf.eval_diffuse_reflectance(si, valid))
    else:
        shaded = field_hit if shaded is None else shaded
        rest = mi.Color3f(bsdf.eval_diffuse_reflectance(si, valid & ~shaded))
        albedo = dr.select(shaded, mi.Color3f(field_albedo), rest)
    albedo = dr.select(valid, albedo, mi.Color3f(0.0))
    n = dr.select(valid, si.sh_frame.n, mi.Vector3f(0.0))
    t = dr.select(valid, si.t if depth is None else depth, zero)
    p = dr.select(valid, si.p, mi.Point3f(0.0))
    on_field = valid & field_hit
    out = [albedo.x, albedo.y, albedo.z, n.x, n.y, n.z, t, p.x, p.y, p.z,
           dr.select(on_field, 1.0, zero), dr.select(valid & ~field_hit, 1.0, zero),
           zero if steps is None else mi.Float(steps)]
    if layer_names_of(field_bsdf):
        out += [dr.select(on_field, w, zero) for w in field_bsdf.layer_weights(si, on_field)]
    return out


def first_vertex_aovs(integ, scene, ray, si, field_hit, res, tr, first, old, shading=None, shaded=None):
    """The AOV values of the camera rays' hits (lanes ``first``), in the order of
    :func:`aov_channel_names`; ``old`` elsewhere (``()`` without AOVs).

    Recorded at the path's first vertex, so no second primary trace is needed; packets
    without a first-vertex lane skip the shading it takes.

    Parameters
    ----------
    integ : ImplicitPathIntegrator
        Its ``bsdf_at``, ``field_bsdf`` and ``tracer``.
    scene : mi.Scene
        The scene (its sensor: depth is measured from the camera's centre).
    ray, si, field_hit
        The camera rays, their hits and whether those are on the field.
    res : TraceResult or None
        The field query's result (its steps; None without a field).
    tr : mi.Color3f or None
        The camera segment's transmittance (None without an atmosphere).
    first : mi.Bool
        The lanes whose ray left the camera.
    old : tuple of mi.Float
        The channels so far.
    shading, shaded : optional
        The vertex's shading (``shade_vertex``) on the lanes ``shaded``, whose albedo
        it reuses.

    Returns
    -------
    tuple of mi.Float
    """
    if not old:
        return old
    steps = res.steps if res is not None else mi.UInt32(0)
    albedo = None if shading is None else shading[0]
    field_bsdf = integ.field_bsdf if integ.tracer else None
    # Perspective cameras start rays on the near plane: measure depth from the
    # camera centre instead, at the unlifted hit point.
    centre = scene.sensors()[0].world_transform().translation()
    extra = () if tr is None else (tr,)
    known = () if albedo is None else (albedo, field_hit if shaded is None else shaded)

    def compute(si, field_hit, steps, first, known, *extra):
        valid = first & si.is_valid()
        bsdf = integ.bsdf_at(si, ray, field_hit)
        depth = dr.norm(ray.o + ray.d * si.t - centre)
        out = primary_aovs(si, field_hit, valid, bsdf, field_bsdf, depth, mi.Float(steps), *known)
        if extra:
            out += [extra[0].x, extra[0].y, extra[0].z]
        return tuple(dr.select(first, v, o) for v, o in zip(out, old))

    return dr.if_stmt((si, field_hit, steps, first, known, *extra), first, compute,
                      lambda *args: tuple(mi.Float(o) for o in old), label="first_vertex_aovs")


def split_channels(image: np.ndarray, aov_names) -> tuple[np.ndarray, dict]:
    """Split a film's ``(H, W, 3 + len(aov_names))`` output into beauty and layers.

    Parameters
    ----------
    image : numpy.ndarray
        Developed film: R, G, B, then the AOV channels in ``aov_names`` order.
    aov_names : sequence of str
        ``layer.channel`` names (see :func:`aov_channel_names`).

    Returns
    -------
    (numpy.ndarray, dict)
        The ``(H, W, 3)`` beauty and ``{layer: (array (H, W, C), channel letters)}``,
        the form :func:`arches_render.imaging.exr.write_exr` takes.
    """
    image = np.asarray(image)
    if image.shape[2] != 3 + len(aov_names):
        raise ValueError(f"film has {image.shape[2]} channels, expected 3 + {len(aov_names)} AOVs")
    layers: dict[str, tuple[list, list]] = {}
    for i, name in enumerate(aov_names):
        layer, _, letter = name.partition(".")
        arrs, letters = layers.setdefault(layer, ([], []))
        arrs.append(image[..., 3 + i])
        letters.append(letter)
    return image[..., :3], {k: (np.stack(a, axis=-1), tuple(c)) for k, (a, c) in layers.items()}


def ray_count_header(layers: dict, spp: int) -> dict:
    """EXR header entries with the image's counts of exhausted and unresolved rays.

    Parameters
    ----------
    layers : dict
        AOV layers of a render (:func:`split_channels`); without ``exhausted`` and
        ``unresolved`` (no traced field, or no AOVs) nothing is counted.
    spp : int
        Samples per pixel (the layers hold per-sample means).

    Returns
    -------
    dict of str to int
        ``rays_exhausted_KIND`` (rays that needed the tracer's second pass) and
        ``rays_unresolved_KIND`` (rays left after it, resolved as hits), for each
        kind of :data:`RAY_COUNT_KINDS`; empty without those layers.
    """
    out = {}
    for layer in ("exhausted", "unresolved"):
        if layer not in layers:
            return {}
        arr, letters = layers[layer]
        arr = np.asarray(arr, np.float64).reshape(arr.shape[0], arr.shape[1], -1)
        for i, kind in enumerate(letters):
            out[f"rays_{layer}_{kind}"] = int(round(float(arr[..., i].sum()) * int(spp)))
    return out


def count_rays(counts, results, lanes, kinds):
    """Add the lanes ``lanes[i]`` of the queries ``results[i]`` to the ``exhausted`` and
    ``unresolved`` counters of ray kind ``kinds[i]`` (an index of ``RAY_COUNT_KINDS``);
    ``counts`` is ``()`` when nothing is counted."""
    if not counts:
        return counts
    n = len(RAY_COUNT_KINDS)
    out = list(counts)
    for res, lane, kind in zip(results, lanes, kinds):
        out[kind] = out[kind] + dr.select(lane & res.exhausted, 1.0, 0.0)
        out[n + kind] = out[n + kind] + dr.select(lane & res.unresolved, 1.0, 0.0)
    return tuple(out)
