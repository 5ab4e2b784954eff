"""Shading normals of mesh hits face the ray (arches_render/render/shading_normals.py).

A coarse mesh with smooth vertex normals, seen under a sky: below its silhouettes the
interpolated normal turns away from the viewer while the face does not. Mitsuba's
BSDFs return nothing there, and the far field's hills showed black crescents along
every far ridge (issue 34). The integrator bends those normals towards the ray.
"""

from __future__ import annotations

import numpy as np

from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.render.plugins import ensure_registered  # noqa: E402
from arches_render.render.renderer import render_image  # noqa: E402
from arches_render.render.shading_normals import MIN_COSINE, facing_shading_frame  # noqa: E402

EYE = (0.0, -5.0, 0.5)


def _coarse_ball():
    """A UV sphere of 8 x 6 segments (radius 1 at the origin, diffuse grey) with smooth
    vertex normals: its faces lie up to 8 % inside the sphere their normals describe."""
    th, ph = np.meshgrid(np.linspace(0.0, np.pi, 7)[1:-1], np.linspace(0.0, 2.0 * np.pi, 9)[:-1], indexing="ij")
    ring = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    V = np.vstack([[0.0, 0.0, 1.0], ring, [0.0, 0.0, -1.0]])
    F = []
    for i in range(8):
        j = (i + 1) % 8
        F.append([0, 1 + i, 1 + j])
        for r in range(4):
            a, b, c, d = 1 + r * 8 + i, 1 + r * 8 + j, 1 + (r + 1) * 8 + i, 1 + (r + 1) * 8 + j
            F += [[a, c, d], [a, d, b]]
        F.append([len(V) - 1, 1 + 32 + j, 1 + 32 + i])
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}})
    mesh = mi.Mesh("ball", len(V), len(F), props, has_vertex_normals=True)
    p = mi.traverse(mesh)
    p["vertex_positions"] = mi.Float(V.astype(np.float32).ravel())
    p["vertex_normals"] = mi.Float(V.astype(np.float32).ravel())
    p["faces"] = mi.UInt32(np.asarray(F, np.uint32).ravel())
    p.update()
    return mesh


def _scene(width=96):
    ensure_registered()
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "implicit_path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at(origin=list(EYE), target=[0, 0, 0], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": width, "height": width, "rfilter": {"type": "box"}}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
        "ball": _coarse_ball(),
    })


def _rays(n=256):
    """Rays from the eye through a fine grid over the ball."""
    u, v = np.meshgrid(np.linspace(-1.1, 1.1, n), np.linspace(-1.1, 1.1, n))
    d = np.stack([u.ravel(), np.zeros(u.size), v.ravel()], -1) - np.array(EYE)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return mi.Ray3f(mi.Point3f(*(mi.Float(np.full(u.size, c, np.float32)) for c in EYE)),
                    mi.Vector3f(*(mi.Float(d[:, i].astype(np.float32)) for i in range(3))))


def test_a_mesh_hit_is_shaded_from_the_side_the_ray_sees():
    scene = _scene()
    ray = _rays()
    si = scene.ray_intersect(ray)
    hit = si.is_valid().numpy()
    cos_before = mi.Frame3f.cos_theta(si.wi).numpy()
    turned = hit & (cos_before < 0.0)
    assert turned.sum() > 100, turned.sum()  # the condition exists on this mesh
    n_before = np.stack([c.numpy() for c in si.sh_frame.n], -1)
    out = facing_shading_frame(si, ray.d)
    cos_after = mi.Frame3f.cos_theta(out.wi).numpy()
    n_after = np.stack([c.numpy() for c in out.sh_frame.n], -1)
    # Every hit now sees its shading normal from the front; those that needed no bend
    # keep it exactly, and the bent ones meet the ray at the least cosine's angle or less.
    assert np.all(cos_after[hit] > 0.0)
    kept = hit & (cos_before >= MIN_COSINE)
    assert np.array_equal(n_after[kept], n_before[kept])
    # The bent cosine is MIN_COSINE / |N + (MIN_COSINE - c) w_i| = MIN_COSINE / sqrt(1 +
    # MIN_COSINE^2 - c^2) (module docstring); rtol 1e-4: float32 normalisation and frame.
    bent = hit & (cos_before < MIN_COSINE)
    expect = MIN_COSINE / np.sqrt(1.0 + MIN_COSINE ** 2 - cos_before[bent].astype(np.float64) ** 2)
    assert np.allclose(cos_after[bent], expect, rtol=1e-4)
    # The shading frame stays orthonormal (wi is read in it). atol 1e-5: float32
    # normalisation of a unit vector (a few ulps of 1).
    assert np.allclose(np.linalg.norm(n_after[hit], axis=1), 1.0, atol=1e-5)


def test_a_smooth_coarse_mesh_under_a_sky_has_no_black_pixels():
    """Lit by a uniform sky, every pixel the ball covers fully reflects some light.
    Without the bend, a band of pixels below its silhouette came out black."""
    scene = _scene()
    img = np.asarray(render_image(scene, 4, seed=1))[..., :3].mean(-1)
    si = scene.ray_intersect(_rays(96))
    # Pixels whose centres hit the ball, and whose neighbours do too (no partial coverage).
    cover = si.is_valid().numpy().reshape(96, 96)[::-1]
    inner = cover.copy()
    inner[1:] &= cover[:-1]
    inner[:-1] &= cover[1:]
    inner[:, 1:] &= cover[:, :-1]
    inner[:, :-1] &= cover[:, 1:]
    assert inner.sum() > 1000
    assert img[inner].min() > 0.05, (img[inner] < 0.05).sum()
