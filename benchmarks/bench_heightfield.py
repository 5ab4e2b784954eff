"""Heightfield ray casting (maximum mipmaps) against sphere tracing and the mesh path.

``render_field_vs_mesh_heightfield``  the default scene's terrain heightfield alone
                                      (its arch removed), 320x180, 16 spp: time of
                                      ``implicit_path`` with the exact heightfield cast
                                      over time of stock ``path`` on the terrain's
                                      marching-cubes mesh, same camera, lights and
                                      materials, medians of ``repeat`` renders with
                                      warm kernels, all in one run. Baseline: the goal,
                                      1.2. Extra fields: the same render sphere-traced
                                      (``sphere_s``, ``sphere_ratio``), the machine's
                                      load average while it ran.
``render_default_cast_vs_sphere``     the default scene (terrain blended with the arch):
                                      time with the hybrid cast (exact cast away from
                                      the arch, sphere steps near it) over time with
                                      sphere tracing only, same run; extra fields: the
                                      mesh time and both ratios to it
                                      (``field_vs_mesh`` is ``render_field_vs_mesh``'s
                                      figure). Baseline: 1 (no gain).

Timings taken while other processes load the machine are inflated: compare the
ratios of one run, and read ``load`` beside them.
"""

from __future__ import annotations

import os

from arches_render.render.renderer import build_scene
from arches_render.scene import load_scene
from arches_render.timing import REPO, median_renders

SCENE = REPO / "scenes" / "default.toml"
W, H, SPP = 320, 180, 16


def _field_sphere_mesh(desc, repeat):
    """Median seconds of the cast field, the sphere-traced field and the mesh."""
    load0 = os.getloadavg()[0]
    cast, sphere = build_scene(desc, "field", W, H), build_scene(desc, "field", W, H)
    integ = sphere.integrator()
    integ.heightfield_cast = False
    integ.attach(desc.field, integ.field_bsdf)
    times = median_renders([cast, sphere, build_scene(desc, "mesh", W, H)], SPP, repeat)
    load = 0.5 * (load0 + os.getloadavg()[0])
    return (*times, dict(tracer=type(cast.integrator().tracer).__name__, resolution=f"{W}x{H}", spp=SPP,
                         load=round(load, 2)))


def bench_render_field_vs_mesh_heightfield(repeat):
    desc = load_scene(SCENE)
    desc.field = desc.field.children[0]  # the terrain heightfield of the blend
    field, sphere, mesh, extra = _field_sphere_mesh(desc, repeat)
    return dict(value=field / mesh, unit="x", baseline=1.2, baseline_is="goal", field_s=field,
                mesh_s=mesh, sphere_s=sphere, sphere_ratio=sphere / mesh, **extra)


def bench_render_default_cast_vs_sphere(repeat):
    desc = load_scene(SCENE)
    field, sphere, mesh, extra = _field_sphere_mesh(desc, repeat)
    return dict(value=field / sphere, unit="x", baseline=1.0, baseline_is="sphere tracing only",
                field_s=field, sphere_s=sphere, mesh_s=mesh, field_vs_mesh=field / mesh,
                sphere_vs_mesh=sphere / mesh, **extra)


BENCHMARKS = {
    "render_field_vs_mesh_heightfield": (bench_render_field_vs_mesh_heightfield, 3),
    "render_default_cast_vs_sphere": (bench_render_default_cast_vs_sphere, 3),
}
