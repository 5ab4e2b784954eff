"""Issue 38: the AOVs of ``every_generator`` rendered as a mesh are right, and agree with the field render.

The scene crashed in mesh mode with AOVs (``tests/test_flat_fields.py`` pins the
cause). Rendered now, its ``position`` and ``depth`` layers must say the same as
the sphere-traced field's where both renders hit, within what marching cubes moves
the surface; and each render's ``depth`` must be the distance from the camera to
its own ``position``: the far field's sea ring, one band of triangles reaching
10,000 km, put Mitsuba's hit points by the shore 9 km off (float32 barycentrics),
40 m from the camera. The renders run in a child process
(:mod:`arches_render.render.isolated`), so that a crash fails this test instead of
killing the test session.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import REPO, variant

variant()

from arches_render.generators.terrain.far_field import sea_ring_mesh  # noqa: E402
from arches_render.mesh.polygonize import default_voxel  # noqa: E402
from arches_render.mesh.triangles import face_areas, face_normals  # noqa: E402
from arches_render.render.isolated import RenderProcess  # noqa: E402
from arches_render.render.jobs import RenderJob  # noqa: E402
from arches_render.render.sphere_tracer import CONE_TOLERANCE  # noqa: E402
from arches_render.scene import load_scene  # noqa: E402

EVERY = REPO / "scenes" / "gallery" / "every_generator.toml"
W, H = 48, 27


def test_sea_ring_triangles_by_the_shore_are_no_longer_than_the_tile():
    extent, reach = (-70.0, -60.0, 70.0, 60.0), 1e7
    mesh = sea_ring_mesh(extent, 0.0, reach)
    v, f = mesh.vertices, mesh.faces
    x0, y0, x1, y1 = extent
    area = face_areas(v, f).sum()
    assert np.isclose(area, (x1 - x0 + 2 * reach) * (y1 - y0 + 2 * reach) - (x1 - x0) * (y1 - y0), rtol=1e-9)
    assert (face_normals(v, f)[:, 2] > 0.999).all()  # flat, facing up
    assert np.allclose(mesh.normals, [0.0, 0.0, 1.0])
    on_shore = (np.abs(v[:, 0] - x0) < 1e-9) | (np.abs(v[:, 0] - x1) < 1e-9) \
        | (np.abs(v[:, 1] - y0) < 1e-9) | (np.abs(v[:, 1] - y1) < 1e-9)
    shore = on_shore[f].any(axis=1)
    edges = np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2).max(axis=1)
    assert shore.sum() >= 8 and edges[shore].max() <= 1.1 * np.hypot(x1 - x0, y1 - y0), edges[shore].max()


@pytest.fixture(scope="module")
def renders():
    """``{geometry: layers}`` of every_generator at 48x27, 1 spp, seed 0, with AOVs."""
    proc = RenderProcess()
    job = RenderJob(scene=str(EVERY), width=W, height=H, spp=1, aovs=True)
    try:
        return {g: proc.run(job.with_(geometry=g)) for g in ("field", "mesh")}
    finally:
        proc.close()


def _full(layers):
    return layers["coverage"][0].sum(axis=-1) == 1.0  # every sample of the pixel hit something


def test_every_layer_is_finite_in_both_renders(renders):
    for geometry, (rgb, layers) in renders.items():
        assert np.isfinite(rgb).all(), geometry
        for name, (arr, _) in layers.items():
            assert np.isfinite(arr).all(), (geometry, name)
        assert _full(layers).mean() > 0.75, geometry  # the view is mostly ground, cliff and sea


def test_depth_is_the_distance_to_position_in_both_renders(renders):
    """The mesh render's hit is its ray's point up to float32 rounding; the field render's
    is moved off the ray by at most its hit tolerance (``max(eps, CONE_TOLERANCE s) t``, ``s``
    the camera cone's spread, half a pixel's angle) and lifted off the surface by
    ``max(eps t / 10, 32 ulps)`` (:mod:`arches_render.render.sphere_tracer`, ``integrator``)."""
    desc = load_scene(EVERY)
    origin = np.asarray(desc.camera.origin, np.float64)
    eps, spread = desc.render.eps, np.tan(np.radians(desc.camera.fov) / 2.0) / W
    for geometry, (_, layers) in renders.items():
        full = _full(layers)
        depth = layers["depth"][0][..., 0][full]
        position = layers["position"][0][full]
        off = np.abs(np.linalg.norm(position - origin, axis=-1) - depth)
        ulps = 32.0 * np.spacing(np.abs(position).max(axis=-1).astype(np.float32))
        rounding = 1e-6 * depth + ulps
        if geometry == "field":
            bound = (max(eps, CONE_TOLERANCE * spread) + 0.1 * eps) * depth + ulps + rounding
        else:
            bound = rounding
        assert (off <= bound).all(), (geometry, off.max(), depth[np.argmax(off / bound)])


def test_mesh_position_and_depth_agree_with_the_field_render_where_both_hit(renders):
    """Same camera rays (same seed), two surfaces: the marching-cubes mesh lies within about a
    voxel of the field's surface, more along grazing rays and across silhouettes, where
    the two renders may see different surfaces."""
    field, mesh = renders["field"][1], renders["mesh"][1]
    both = _full(field) & _full(mesh)
    assert both.sum() > 0.7 * W * H
    voxel = default_voxel(load_scene(EVERY).field)
    moved = np.linalg.norm(field["position"][0] - mesh["position"][0], axis=-1)[both]
    depth = np.abs(field["depth"][0] - mesh["depth"][0])[..., 0][both]
    for name, d in (("position", moved), ("depth", depth)):
        assert np.median(d) <= 0.25 * voxel, (name, np.median(d), voxel)
        assert np.percentile(d, 95) <= voxel, (name, np.percentile(d, 95), voxel)
    # Misses agree too: the sky is the sky in both.
    assert ((field["coverage"][0].sum(axis=-1) == 0) == (mesh["coverage"][0].sum(axis=-1) == 0)).mean() > 0.98
