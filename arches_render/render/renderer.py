"""From a scene description to pixels: Mitsuba scene assembly and pass-wise rendering.

``geometry = "field"`` renders with ``implicit_path`` and sphere-traces the field;
``geometry = "mesh"`` renders the marching-cubes mesh of the same field with the
same camera, lights and materials: with ``implicit_path`` without a field when the
field's material shades once per vertex (``triplanar``: shaded as on the field,
its cavity term at camera hits only), else with Mitsuba's built-in ``path``. This
mesh mode is the cross-check of the sphere tracer. ``geometry = "sdfgrid"``
(benchmarks only) renders the field sampled on the mesh's voxel grid as
Mitsuba's own ``sdfgrid`` shape, the yardstick of ``render_field_vs_sdfgrid``. A scene with an
``[atmosphere]`` renders with ``implicit_path`` in both modes (Mitsuba's ``path``
knows no fog), so the two are fogged by the same code.

Samples are taken in passes with distinct seeds (``seed * 4096 + pass``): LLVM
variants report no progress inside one launch, and a pass is the unit of the
progress bar. A ``box`` reconstruction filter makes every pass, hence every image,
bitwise reproducible for a given scene, seed and spp.
"""

from __future__ import annotations

import math
import weakref

import drjit as dr
import mitsuba as mi
import numpy as np

from ..imaging.pixel_moments import PixelMoments
from ..materials.detail import pixel_spread
from ..mesh.polygonize import polygonize
from ..scene.material_keys import FIELD_ROOT
from .aovs import split_channels
from .atmosphere import Atmosphere
from .mesh_region import scene_mesh_region
from .plugins import ensure_registered
from .sun_columns import scene_sun
from .wavefront import WAVEFRONT_LANES

PASS_SPP = 16
MAX_PASSES = 4096


def clip_planes(lo, hi) -> tuple[float, float]:
    """Near and far clip distances for cameras inside the box ``[lo, hi]``.

    Every point of the box is within its diagonal ``D`` of a camera inside it, so
    ``far = 2 D`` keeps the whole scene (tiles of 1000 km, far-field rings
    to the horizon) and ``near = min(1 cm, 1e-4 D)`` clips nothing of a small scene.
    The planes bound the camera rays only (``mint``/``maxt``), so their ratio costs
    no precision.

    Parameters
    ----------
    lo, hi : array_like
        Corners of the scene's box (geometry and camera positions), metres.

    Returns
    -------
    (float, float)
        ``(near, far)`` in metres.
    """
    D = float(np.linalg.norm(np.asarray(hi, np.float64) - np.asarray(lo, np.float64)))
    D = max(D, 1e-3) if math.isfinite(D) else 1e7
    return min(0.01, 1e-4 * D), 2.0 * D + 1.0


def scene_box(desc, bbox=None) -> tuple[np.ndarray, np.ndarray]:
    """Box of the field's bounds, every camera of ``desc`` and a Mitsuba ``bbox`` (meshes)."""
    cams = getattr(desc, "cameras", None) or {"camera": desc.camera}
    pts = [np.asarray(c.origin, np.float64) for c in cams.values()]
    pts += [np.asarray(c.target, np.float64) for c in cams.values()]
    lo, hi = np.min(pts, axis=0), np.max(pts, axis=0)
    if desc.field is not None:
        flo, fhi = (np.asarray(v, np.float64) for v in desc.field.bounds())
        ok = np.isfinite(flo) & np.isfinite(fhi)
        lo, hi = np.where(ok, np.minimum(lo, flo), lo), np.where(ok, np.maximum(hi, fhi), hi)
    if bbox is not None and bbox.valid():
        lo, hi = np.minimum(lo, np.array(bbox.min, np.float64)), np.maximum(hi, np.array(bbox.max, np.float64))
    return lo, hi


def tile_projection(fov, width, height, crop) -> tuple[float, float, float]:
    """``(x_fov, offset_x, offset_y)`` of a camera whose ``w x h`` film sees exactly the
    window ``crop = (x0, y0, w, h)`` of a ``width x height`` image of horizontal field
    of view ``fov`` (degrees).

    An off-axis sub-frustum: ``tan(x_fov / 2) = tan(fov / 2) w / width`` (the same angle
    a pixel), and the principal point moves to the window's centre, in units of the
    window (Mitsuba's ``principal_point_offset``):
    ``offset_x = (x0 + w/2 - width/2) / w``, ``offset_y = (y0 + h/2 - height/2) / h``.
    Why not the film's crop window: Mitsuba's render loop takes the crop offset as a
    constant, so every tile compiled its own kernel (11 s each on two cores); these are
    parameters (ray directions agree with the crop's to 6e-8).
    """
    x0, y0, w, h = (int(v) for v in crop)
    half = math.tan(math.radians(float(fov)) / 2.0) * w / int(width)
    return (2.0 * math.degrees(math.atan(half)), (x0 + 0.5 * w - 0.5 * int(width)) / w,
            (y0 + 0.5 * h - 0.5 * int(height)) / h)


def sensor_dict(desc, width, height, crop=None) -> dict:
    """Perspective camera of the scene; ``crop = (x0, y0, w, h)`` renders a window only
    (:func:`tile_projection`).

    Clip planes come from :func:`clip_planes` of the field and the cameras
    (:func:`build_scene` widens them to the meshes once they are loaded).
    """
    cam = desc.camera
    near, far = clip_planes(*scene_box(desc))
    fov, offset = cam.fov, (0.0, 0.0)
    if crop is not None:
        fov, *offset = tile_projection(cam.fov, width, height, crop)
        width, height = (int(v) for v in crop[2:])
    film = {"type": "hdrfilm", "width": int(width), "height": int(height),
            "pixel_format": "rgb", "rfilter": {"type": "box"}}
    return {
        "type": "perspective",
        "fov": fov,
        "fov_axis": "x",
        "principal_point_offset_x": float(offset[0]),
        "principal_point_offset_y": float(offset[1]),
        "near_clip": near,
        "far_clip": far,
        "to_world": mi.ScalarTransform4f().look_at(origin=cam.origin, target=cam.target, up=cam.up),
        "sampler": {"type": "independent"},
        "film": film,
    }


# Field tree -> {voxel: TriangleMesh}; weak, so a tree's meshes go with it.
_POLYGONS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def field_mesh_shape(desc, bsdf, voxel=None, progress=None):
    """A Mitsuba mesh of the field's marching-cubes surface, shaded by ``bsdf``.

    The triangles are kept per field tree and voxel while the tree lives, so the mesh
    modes of one loaded scene (with and without AOVs, other sizes) polygonize once."""
    voxel = voxel or desc.render.voxel or None
    by_voxel = _POLYGONS.setdefault(desc.field, {})
    if voxel not in by_voxel:
        by_voxel[voxel] = polygonize(desc.field, voxel, progress)
    tri = by_voxel[voxel]
    props = mi.Properties()
    props["bsdf"] = bsdf
    mesh = mi.Mesh("field", len(tri.vertices), len(tri.faces), props, has_vertex_normals=True)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(tri.vertices.ravel())
    params["faces"] = mi.UInt32(tri.faces.ravel())
    params["vertex_normals"] = mi.Float(tri.normals.ravel())
    params.update()
    dr.eval()
    return mesh, tri


def field_sdfgrid_shape(desc, bsdf, voxel=None):
    """The field sampled on the mesh's voxel grid as Mitsuba's ``sdfgrid`` shape.

    ``sdfgrid`` takes signed distances, negative inside, on a grid spanning the unit
    cube, and renders only with a uniform scale (a non-cubic grid renders nothing in
    ``llvm_ad_rgb``): the samples are padded with air into a cube of ``n`` samples a
    side, negated and divided by the cube's edge ``(n - 1) voxel``. The field's
    values are metres near its surface, which is what the shape's solver needs.
    """
    from ..mesh.polygonize import default_voxel, sample_grid
    voxel = voxel or desc.render.voxel or default_voxel(desc.field)
    vol, lo = sample_grid(desc.field, voxel)
    n = int(max(vol.shape))
    cube = np.full((n, n, n), -voxel, dtype=np.float32)
    cube[:vol.shape[0], :vol.shape[1], :vol.shape[2]] = vol
    edge = (n - 1) * voxel
    grid = np.ascontiguousarray((-cube / edge).transpose(2, 1, 0)[..., None])  # (z, y, x, 1)
    return {"type": "sdfgrid", "grid": mi.TensorXf(grid), "bsdf": bsdf,
            "to_world": mi.ScalarTransform4f().translate(mi.ScalarPoint3f(*map(float, lo))).scale(float(edge))}


def load_materials(desc) -> dict:
    """Mitsuba BSDF objects of the scene's materials, with their layer masks attached.

    Objects rather than dictionaries: a mask is a field node, which cannot travel
    through ``mi.load_dict``; meshes and the field then share the same BSDF. The
    nodes the lookdev terms read (strata, cavity) are attached here too; a
    cavity without a node of its own reads the scene's field.
    """
    ensure_registered()
    bsdfs = {}
    for name, mat in desc.materials.items():
        bsdfs[name] = mi.load_dict(mat)
        attach_material_nodes(bsdfs[name], desc, name)
    return bsdfs


def attach_material_nodes(bsdf, desc, name) -> None:
    """Give the BSDF of material ``name`` its layer masks and look nodes from ``desc``."""
    for layer, node, lo, hi, kind in desc.material_masks.get(name, ()):
        bsdf.set_layer_mask(layer, node, lo, hi, kind)
    for role, node in getattr(desc, "material_nodes", {}).get(name, {}).items():
        bsdf.set_node(role, desc.field if node == FIELD_ROOT else node)


def set_pixel_spread(scene, fov=None, width=None, integrator=None) -> None:
    """Tell every triplanar BSDF of a built scene, and the integrator, the camera's pixel size
    (the detail footprint and the camera rays' cones).

    Parameters
    ----------
    scene : mi.Scene
    fov : float, optional
        Horizontal field of view in degrees (default: the sensor's).
    width : int, optional
        Full image width in pixels (default: the film's).
    integrator : mi.Integrator, optional
        The integrator to tell (default: the scene's; see :func:`scene_integrator`).

    Notes
    -----
    An opaque parameter edit: no kernel is recompiled. The BSDFs are those of the
    shapes and the integrator's field BSDF.
    """
    sensor = scene.sensors()[0]
    if fov is None:
        fov = float(mi.traverse(sensor)["x_fov"][0])
    width = int(sensor.film().size()[0]) if width is None else int(width)
    spread = pixel_spread(fov, width)
    integrator = integrator or scene.integrator()
    if hasattr(integrator, "set_pixel_angle"):  # the field's ray cones (level of detail)
        integrator.set_pixel_angle(spread)
    bsdfs = [shape.bsdf() for shape in scene.shapes()]
    bsdfs.append(getattr(integrator, "field_bsdf", None))
    done = set()
    for bsdf in bsdfs:
        if bsdf is None or id(bsdf) in done or not hasattr(bsdf, "pixel_spread"):
            continue
        done.add(id(bsdf))
        params = mi.traverse(bsdf)
        params["pixel_spread"] = spread
        params.update()


def load_mesh_files(d: dict) -> dict:
    """``d`` with its PLY/OBJ mesh entries loaded, with Dr.Jit on one thread.

    Mitsuba sums the vertex normals of a mesh file without normals by atomic
    scatter-adds; on several threads their order, hence the last bits of a few
    normals, changed from one build to the next (a render of the same scene and seed
    then differed in its shading-normal layer). One thread keeps the order. Only the
    meshes load this way: loading a whole scene on one thread deadlocked OpenEXR's
    reading of an environment map, whose tasks run on the same thread pool.
    """
    threads = dr.thread_count()
    dr.set_thread_count(1)
    try:
        out = {k: (mi.load_dict(v) if isinstance(v, dict) and v.get("type") in ("ply", "obj") else v)
               for k, v in d.items()}
        dr.eval()
        dr.sync_thread()
    finally:
        dr.set_thread_count(threads)
    return out


def build_scene(desc, geometry=None, width=None, height=None, voxel=None, progress=None,
                aovs=False, crop=None, bsdfs=None, moments=False):
    """Assemble the Mitsuba scene of a :class:`SceneDescription`.

    Parameters
    ----------
    desc : SceneDescription
    geometry : {'field', 'mesh', 'sdfgrid'}, optional
        Override of ``render.geometry`` (``sdfgrid``: module docstring).
    width, height : int, optional
        Override of ``render.resolution``.
    voxel : float, optional
        Marching-cubes voxel in mesh mode.
    progress : callable, optional
        ``progress(done, total)`` while polygonizing.
    aovs : bool, optional
        Render the AOVs of :mod:`arches_render.render.aovs` besides the beauty
        (read them with :func:`render_layers`). Mesh mode then renders with
        ``implicit_path`` without a field, the same estimator as ``path``.
    crop : (x0, y0, w, h), optional
        Render only this window of the image (a tile).
    bsdfs : dict, optional
        The materials as built by :func:`load_materials` (shared with the caller,
        who may edit them later); default: built here.
    moments : bool, optional
        Also render the second moments (layer ``moment2``; implies ``aovs``), for
        :func:`render_moments`.

    Returns
    -------
    mi.Scene
    """
    ensure_registered()
    s = desc.render
    aovs = aovs or moments
    geometry = geometry or s.geometry
    d = {"type": "scene",
         "sensor": sensor_dict(desc, width or s.width, height or s.height, crop)}
    bsdfs = load_materials(desc) if bsdfs is None else bsdfs
    for i, light in enumerate(desc.lights):
        d[f"light{i}"] = light
    for i, mesh in enumerate(desc.meshes):
        d[f"mesh{i}"] = dict(mesh, bsdf=bsdfs[mesh["bsdf"]["id"]])
    d = load_mesh_files(d)
    # The generators' scene tables (rock piles: flat meshes with baked transforms).
    for items in desc.tables.values():
        for item in items:
            for k, shape in enumerate(item.shapes(bsdfs)):
                d[f"{item.name}_{k}"] = shape
    field_bsdf = bsdfs[desc.field_material] if desc.field is not None else None
    d["integrator"] = integrator_dict(desc, geometry, field_bsdf, aovs, moments)
    if desc.field is not None and geometry == "sdfgrid":
        d["field_sdf"] = field_sdfgrid_shape(desc, field_bsdf, voxel)
    elif desc.field is not None and geometry == "mesh":
        d["field_mesh"], _ = field_mesh_shape(desc, field_bsdf, voxel, progress)
    scene = mi.load_dict(d)
    attach_field(scene.integrator(), desc, geometry, field_bsdf)
    attach_mesh_region(scene, desc)
    # Clip planes for the whole scene, meshes included (a far-field ring reaches the
    # horizon): an edit before the first render compiles nothing more.
    near, far = clip_planes(*scene_box(desc, scene.bbox()))
    params = mi.traverse(scene)
    params["sensor.near_clip"], params["sensor.far_clip"] = near, far
    params.update()
    attach_atmosphere(scene, desc)
    set_pixel_spread(scene, desc.camera.fov, width or s.width)
    return scene


def integrator_dict(desc, geometry, field_bsdf=None, aovs=False, moments=False) -> dict:
    """The integrator :func:`build_scene` gives a scene of ``desc`` in mode ``geometry``.

    Field mode: ``implicit_path`` with the scene's tracer settings. Mesh mode (and a
    scene without a field): Mitsuba's ``path`` unless AOVs, an atmosphere or a field
    material that shades its mesh once per vertex (``field_bsdf.shade``: its cavity
    term at camera hits only, as on the field) need ``implicit_path`` (Mitsuba's
    ``path`` shades twice per vertex, the cavity's march included, and knows no fog).
    """
    s = desc.render
    aovs = aovs or moments
    if geometry in ("mesh", "sdfgrid") or desc.field is None:
        ours = aovs or getattr(desc, "atmosphere", None) is not None or hasattr(field_bsdf, "shade")
        d = {"type": "implicit_path" if ours else "path", "max_depth": s.max_depth, "rr_depth": s.rr_depth}
        if aovs:
            d.update(aovs=True, moments=bool(moments))
        return d
    return {"type": "implicit_path", "max_depth": s.max_depth, "rr_depth": s.rr_depth,
            "eps": s.eps, "omega": s.omega, "max_steps": s.max_steps,
            "surface_cells": s.surface_cells, "sun_columns": s.sun_columns, "wavefront": s.wavefront, "lod": s.lod,
            "aovs": bool(aovs), "moments": bool(moments)}


def attach_field(integrator, desc, geometry, field_bsdf) -> None:
    """Give an integrator of :func:`integrator_dict` the field (field mode) or the field
    material that shades its mesh (mesh mode, ``implicit_path`` only)."""
    if desc.field is None:
        return
    if geometry not in ("mesh", "sdfgrid"):
        integrator.attach(desc.field, field_bsdf, sun=scene_sun(desc.lights))
    elif hasattr(field_bsdf, "shade") and hasattr(integrator, "attach_material"):
        integrator.attach_material(field_bsdf)


def scene_integrator(scene, desc, geometry, bsdfs, aovs=False, moments=False, width=None):
    """Another integrator for a scene built by :func:`build_scene`: the one it would have
    had if built with ``aovs`` and ``moments``, for ``render_layers(scene, ...,
    integrator=...)``.

    The shapes of a scene do not depend on its AOVs (only the integrator does), so one
    built scene serves a job with AOVs and one without: building it again cost its
    meshes' BVH, a rock pile's meshes and, in mesh mode, the field's mesh upload (the
    scene sweep's builds besides polygonization: 60 -> 28 s on one core).

    Parameters
    ----------
    scene : mi.Scene
    desc : SceneDescription
        The description ``scene`` was built from.
    geometry : str
        The mode it was built in.
    bsdfs : dict
        The materials it was built with (:func:`load_materials`).
    aovs, moments : bool
        As for :func:`build_scene`.
    width : int, optional
        Full image width in pixels (the ray cones); default the film's.

    Returns
    -------
    mi.Integrator
    """
    ensure_registered()
    field_bsdf = bsdfs[desc.field_material] if desc.field is not None else None
    integrator = mi.load_dict(integrator_dict(desc, geometry, field_bsdf, aovs, moments))
    attach_field(integrator, desc, geometry, field_bsdf)
    attach_mesh_region(scene, desc, integrator)
    attach_atmosphere(scene, desc, integrator)
    set_pixel_spread(scene, desc.camera.fov, width, integrator)
    return integrator


def attach_mesh_region(scene, desc, integrator=None) -> None:
    """Tell a built scene's integrator (or ``integrator``) where its meshes lie, so that rays
    that cannot meet one skip Mitsuba's query (:mod:`.mesh_region`; ``implicit_path`` only)."""
    integrator = integrator or scene.integrator()
    if hasattr(integrator, "attach_mesh_region"):
        items = [item for items in desc.tables.values() for item in items]
        integrator.attach_mesh_region(scene_mesh_region(scene, items))


def attach_atmosphere(scene, desc, integrator=None) -> None:
    """Give a built scene's integrator (or ``integrator``) the atmosphere of ``desc`` (if it has one).

    The fogged box is the scene's bounding box (meshes) joined with the field's
    bounds, the same in field and mesh mode. Call again after editing lights or
    the ``[atmosphere]`` table: the new values are opaque and re-use the kernels.
    """
    settings = getattr(desc, "atmosphere", None)
    if settings is None:
        return
    bbox = scene.bbox()
    lo, hi = np.array(bbox.min, np.float64), np.array(bbox.max, np.float64)
    if desc.field is not None:
        flo, fhi = desc.field.bounds()
        lo = np.minimum(lo, flo) if bbox.valid() else np.asarray(flo, np.float64)
        hi = np.maximum(hi, fhi) if bbox.valid() else np.asarray(fhi, np.float64)
    (integrator or scene.integrator()).attach_atmosphere(Atmosphere.for_scene(settings, desc.lights, (lo, hi)))


def plan_passes(spp: int, passes: int = 0, most: int = 0) -> list[int]:
    """Split ``spp`` into passes of nearly equal size (``passes = 0``: about 16 spp each),
    of at most ``most`` spp each when ``most`` is given."""
    n = passes or math.ceil(spp / PASS_SPP)
    if most:
        n = max(n, math.ceil(spp / most))
    n = max(1, min(n, spp, MAX_PASSES))
    base, extra = divmod(spp, n)
    return [base + (1 if i < extra else 0) for i in range(n)]


def pass_limit(scene, integrator=None) -> int:
    """The most spp a pass may take (0: no limit): a wavefront integrator keeps its paths'
    state in memory, ``WAVEFRONT_LANES`` paths a pass at most (:mod:`.wavefront`)."""
    integ = integrator or scene.integrator()
    if not getattr(integ, "wavefront", False):
        return 0
    width, height = scene.sensors()[0].film().crop_size()
    return max(1, WAVEFRONT_LANES // (int(width) * int(height)))


def pass_seed(seed: int, i: int, stream: int = 0) -> int:
    """Sampler seed of pass ``i`` of sample stream ``stream``: ``seed * 4096 + i`` for stream 0.

    A stream is a turntable frame or an image tile. Other streams mix their
    index in with a Weyl step (golden-ratio constant), so that each draws its own
    sequence and the result does not depend on where or in which order frames
    and tiles were rendered.
    """
    base = int(seed) * MAX_PASSES + int(i)
    return base if stream == 0 else (base + int(stream) * 0x9E3779B9) & 0xFFFFFFFF


def render_layers(scene, spp: int, seed: int = 0, passes: int = 0, progress=None, stream: int = 0,
                  on_pass=None, integrator=None):
    """Render the beauty and the integrator's AOVs, averaged over passes.

    Parameters
    ----------
    scene : mi.Scene
        Built with ``aovs=True`` for AOVs (otherwise the layers are empty).
    spp, seed, passes, progress
        As for :func:`render_image`.
    stream : int, optional
        Sample stream (frame or tile index) mixed into the pass seeds (:func:`pass_seed`).
    on_pass : callable, optional
        ``on_pass(samples_done, beauty)`` after each pass, with the mean ``(H, W, 3)``
        beauty so far (a progressive preview).
    integrator : mi.Integrator, optional
        Render with this integrator instead of the scene's (:func:`scene_integrator`).

    Returns
    -------
    (numpy.ndarray, dict)
        ``(H, W, 3)`` float32 beauty and ``{layer: (array, channel letters)}``
        (see :func:`arches_render.render.aovs.split_channels`).
    """
    names = list((integrator or scene.integrator()).aov_names())
    acc, done = None, 0
    for i, n in enumerate(plan_passes(spp, passes, pass_limit(scene, integrator))):
        img = mi.render(scene, spp=n, seed=pass_seed(seed, i, stream), integrator=integrator)
        img = img.numpy().astype(np.float64)
        acc = img * n if acc is None else acc + img * n
        done += n
        if progress:
            progress(done, spp)
        if on_pass:
            on_pass(done, (acc[..., :3] / done).astype(np.float32))
    rgb, layers = split_channels((acc / spp).astype(np.float32), names)
    return rgb, layers


def render_image(scene, spp: int, seed: int = 0, passes: int = 0, progress=None) -> np.ndarray:
    """Render ``spp`` samples per pixel in passes and return the mean image.

    Parameters
    ----------
    scene : mi.Scene
    spp : int
    seed : int
        Base seed; pass ``i`` uses ``seed * 4096 + i``.
    passes : int
        Number of passes (0: automatic).
    progress : callable, optional
        ``progress(samples_done, spp)`` after each pass.

    Returns
    -------
    numpy.ndarray
        ``(H, W, 3)`` float32 linear Rec.709 radiance.
    """
    plan = plan_passes(spp, passes, pass_limit(scene))
    acc = None
    done = 0
    for i, n in enumerate(plan):
        img = mi.render(scene, spp=n, seed=pass_seed(seed, i)).numpy().astype(np.float64)
        acc = img * n if acc is None else acc + img * n
        done += n
        if progress:
            progress(done, spp)
    return (acc / spp)[..., :3].astype(np.float32)


def render_moments(scene, spp: int, seed: int = 0, passes: int = 0, progress=None):
    """Render the per-pixel sample statistics that the golden tests compare.

    Parameters
    ----------
    scene : mi.Scene
        Built with ``moments=True``.
    spp, seed, passes, progress
        As for :func:`render_image`.

    Returns
    -------
    arches_render.imaging.welch.PixelMoments
        Beauty, second moments of R, G, B, luminance and depth, coverage and depth.
    """
    return moments_of(*render_layers(scene, spp, seed, passes, progress), spp)


def moments_of(rgb, layers: dict, spp: int):
    """The :class:`~arches_render.imaging.welch.PixelMoments` of a render's beauty and
    layers (:func:`render_layers` of a scene built with ``moments=True``)."""
    if "moment2" not in layers:
        raise ValueError("the render has no moment2 layer: build the scene with moments=True")
    m2 = layers["moment2"][0]
    return PixelMoments(n=spp, mean=rgb, m2=m2[..., :4], coverage=layers["coverage"][0].sum(axis=-1),
                        depth=layers["depth"][0][..., 0], depth_m2=m2[..., 4])
