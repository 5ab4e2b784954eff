"""From a scene description to pixels: Mitsuba scene assembly and pass-wise rendering.

``geometry = "field"`` renders with ``implicit_path`` and sphere-traces the field;
``geometry = "mesh"`` renders the marching-cubes mesh of the same field with
Mitsuba's built-in ``path`` integrator and the same camera, lights and materials.
This mesh mode is the cross-check of the sphere tracer.

Samples are taken in passes with distinct seeds (``seed * 4096 + pass``): LLVM
variants report no progress inside one launch, and a pass is the unit of the
progress bar. A ``box`` reconstruction filter makes every pass, hence every image,
bitwise reproducible for a given scene, seed and spp.
"""

from __future__ import annotations

import math
import numpy as np

from ..backend import variant

PASS_SPP = 16
MAX_PASSES = 4096


def sensor_dict(desc, width, height) -> dict:
    import mitsuba as mi
    cam = desc.camera
    return {
        "type": "perspective",
        "fov": cam.fov,
        "fov_axis": "x",
        "near_clip": 0.01,
        "far_clip": 1e5,
        "to_world": mi.ScalarTransform4f().look_at(origin=cam.origin, target=cam.target, up=cam.up),
        "sampler": {"type": "independent"},
        "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                 "pixel_format": "rgb", "rfilter": {"type": "box"}},
    }


def field_mesh_shape(desc, bsdf, voxel=None, progress=None):
    """A Mitsuba mesh of the field's marching-cubes surface, shaded by ``bsdf``."""
    import drjit as dr
    import mitsuba as mi

    from ..mesh.polygonize import polygonize
    tri = polygonize(desc.field, voxel or desc.render.voxel or None, progress)
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


def load_materials(desc) -> dict:
    """Mitsuba BSDF objects of the scene's materials, with their layer masks attached.

    Objects rather than dictionaries: a mask is a field node, which cannot travel
    through ``mi.load_dict``; meshes and the field then share the same BSDF.
    """
    import mitsuba as mi
    bsdfs = {}
    for name, mat in desc.materials.items():
        bsdfs[name] = mi.load_dict(mat)
        for layer, node, lo, hi in desc.material_masks.get(name, ()):
            bsdfs[name].set_layer_mask(layer, node, lo, hi)
    return bsdfs


def build_scene(desc, geometry=None, width=None, height=None, voxel=None, progress=None):
    """Assemble the Mitsuba scene of a :class:`SceneDescription`.

    Parameters
    ----------
    desc : SceneDescription
    geometry : {'field', 'mesh'}, optional
        Override of ``render.geometry``.
    width, height : int, optional
        Override of ``render.resolution``.
    voxel : float, optional
        Marching-cubes voxel in mesh mode.
    progress : callable, optional
        ``progress(done, total)`` while polygonizing.

    Returns
    -------
    mi.Scene
    """
    variant()
    import mitsuba as mi
    s = desc.render
    geometry = geometry or s.geometry
    d = {"type": "scene",
         "sensor": sensor_dict(desc, width or s.width, height or s.height)}
    bsdfs = load_materials(desc)
    for i, light in enumerate(desc.lights):
        d[f"light{i}"] = light
    for i, mesh in enumerate(desc.meshes):
        d[f"mesh{i}"] = dict(mesh, bsdf=bsdfs[mesh["bsdf"]["id"]])
    field_bsdf = bsdfs[desc.field_material] if desc.field is not None else None
    if geometry == "mesh" or desc.field is None:
        d["integrator"] = {"type": "path", "max_depth": s.max_depth, "rr_depth": s.rr_depth}
        if desc.field is not None:
            d["field_mesh"], _ = field_mesh_shape(desc, field_bsdf, voxel, progress)
        return mi.load_dict(d)
    d["integrator"] = {"type": "implicit_path", "max_depth": s.max_depth, "rr_depth": s.rr_depth,
                       "eps": s.eps, "omega": s.omega}
    scene = mi.load_dict(d)
    scene.integrator().attach(desc.field, field_bsdf)
    return scene


def plan_passes(spp: int, passes: int = 0) -> list[int]:
    """Split ``spp`` into passes of nearly equal size (``passes = 0``: about 16 spp each)."""
    n = passes or math.ceil(spp / PASS_SPP)
    n = max(1, min(n, spp, MAX_PASSES))
    base, extra = divmod(spp, n)
    return [base + (1 if i < extra else 0) for i in range(n)]


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
    import mitsuba as mi
    plan = plan_passes(spp, passes)
    acc = None
    done = 0
    for i, n in enumerate(plan):
        img = mi.render(scene, spp=n, seed=seed * MAX_PASSES + i).numpy().astype(np.float64)
        acc = img * n if acc is None else acc + img * n
        done += n
        if progress:
            progress(done, spp)
    return (acc / spp)[..., :3].astype(np.float32)


def render_scene(desc, spp=None, seed=None, geometry=None, width=None, height=None, passes=None,
                 voxel=None, progress=None) -> np.ndarray:
    """Load, assemble and render a scene description; the one-call API."""
    s = desc.render
    scene = build_scene(desc, geometry, width, height, voxel)
    return render_image(scene, spp or s.spp, s.seed if seed is None else seed,
                        s.passes if passes is None else passes, progress)
