"""Orientation: what is where in an image, and where the light comes from.

* An object to the camera's right lands in the right half of the image, one above
  it in the top half (field and mesh alike).
* The position AOV is ``origin + depth * direction`` with ``direction`` inside the
  pixel's own frustum (one sample per pixel, so no averaging blurs it).
* The sun comes from ``(cos el cos az, cos el sin az, sin el)`` (azimuth from +X
  towards +Y, elevation above the XY plane), for ``directional`` and ``sunsky`` lights.
* An environment map is Z-up (its top rows light from above), its column ``u``
  lies at azimuth ``90 - 360 u`` degrees, and ``rotation`` turns it about +Z,
  counter-clockwise seen from above.

The light direction is measured, not assumed: a white diffuse ball lit by one
light has radiance ``k max(0, n . s)``, and a least-squares fit of ``n`` (normal
AOV) against the radiance gives ``s``.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

from helpers import variant

variant()

from arches_render.render.jobs import RenderJob, clear_cache, run_job  # noqa: E402

SIDE = textwrap.dedent("""
    [scene]
    name = "orient"
    [camera]
    origin = [0.0, -12.0, 0.0]
    target = [0.0, 0.0, 0.0]
    up = [0.0, 0.0, 1.0]
    fov = 50.0
    [[lights]]
    type = "constant"
    [materials.paint]
    type = "diffuse"
    color = [0.2, 0.4, 0.6]
    [materials.stone]
    type = "diffuse"
    color = [0.5, 0.5, 0.5]
    [[meshes]]
    shape = "sphere"
    translate = [0.0, 0.0, 3.0]
    material = "paint"
    [field]
    root = "ball"
    material = "stone"
    [nodes.ball]
    type = "sphere"
    center = [3.5, 0.0, 0.0]
    radius = 1.0
""")

# A white ball seen from above, lit by LIGHT only.
BALL = textwrap.dedent("""
    [scene]
    name = "lit"
    [render]
    max_depth = 2
    [camera]
    origin = [0.0, 0.0, 6.0]
    target = [0.0, 0.0, 0.0]
    up = [0.0, 1.0, 0.0]
    fov = 30.0
    LIGHT
    [materials.white]
    type = "diffuse"
    color = [0.8, 0.8, 0.8]
    [field]
    root = "ball"
    material = "white"
    [nodes.ball]
    type = "sphere"
    center = [0.0, 0.0, 0.0]
    radius = 1.0
""")


def _render(tmp_path, text, w, h, spp, name="s.toml"):
    path = tmp_path / name
    path.write_text(text)
    clear_cache()
    return run_job(RenderJob(scene=str(path), width=w, height=h, spp=spp, aovs=True))


def _layer(layers, name, channel=None):
    arr, letters = layers[name]
    return arr if channel is None else arr[..., letters.index(channel)]


def _camera_rays(origin, target, up, fov, w, h):
    """World directions through the pixel centres, with x to the image's right and row 0 at its top."""
    f = np.asarray(target, float) - origin
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    tx = math.tan(math.radians(fov) / 2)
    ty = tx * h / w
    x = ((np.arange(w) + 0.5) / w * 2 - 1) * tx
    y = (1 - (np.arange(h) + 0.5) / h * 2) * ty
    d = f + x[None, :, None] * r + y[:, None, None] * u
    return d / np.linalg.norm(d, axis=-1, keepdims=True), 2 * tx / w


def test_objects_land_on_their_side_and_the_right_way_up(tmp_path):
    w, h = 64, 36
    _, layers = _render(tmp_path, SIDE, w, h, 4)
    field, mesh = _layer(layers, "coverage", "field"), _layer(layers, "coverage", "mesh")
    ys, xs = np.nonzero(field > 0.5)
    # The field ball at +3.5 m along X (the camera's right, looking along +Y with Z up).
    assert len(xs) > 20 and xs.min() > w // 2 and abs(ys.mean() - (h - 1) / 2) < 2
    ys, xs = np.nonzero(mesh > 0.5)
    # The mesh sphere 3 m up: the top half, centred left to right.
    assert len(ys) > 20 and ys.max() < h // 2 and abs(xs.mean() - (w - 1) / 2) < 2
    # Where it is in the world agrees with where it is in the image.
    pos = _layer(layers, "position")
    assert pos[field > 0.99, 0].min() > 2.0 and pos[mesh > 0.99, 2].min() > 1.9


def test_position_is_origin_plus_depth_along_the_pixels_ray(tmp_path):
    w, h = 48, 27
    origin, target, up, fov = np.array([0.0, -12.0, 0.0]), [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 50.0
    _, layers = _render(tmp_path, SIDE, w, h, 1)
    pos, depth = _layer(layers, "position"), _layer(layers, "depth")
    depth = depth if depth.ndim == 2 else depth[..., 0]
    hit = (_layer(layers, "coverage", "field") + _layer(layers, "coverage", "mesh")) == 1.0
    assert hit.sum() > 60
    v = pos[hit] - origin
    t = np.linalg.norm(v, axis=1)
    # Depth is measured along the ray to where the tracer stopped; the position is that point
    # after its Newton step onto the surface, which moves it by at most the hit tolerance eps t
    # (SphereTracer.eps = 2e-4). Meshes agree to float precision.
    from arches_render.render.sphere_tracer import SphereTracer
    eps = SphereTracer.__init__.__defaults__[0]
    np.testing.assert_allclose(t, depth[hit], rtol=eps * 1.01)
    mesh = _layer(layers, "coverage", "mesh")[hit] == 1.0
    np.testing.assert_allclose(t[mesh], depth[hit][mesh], rtol=1e-6)
    # One sample per pixel: its direction lies within the pixel (half a diagonal of the centre ray).
    centre, pixel = _camera_rays(origin, target, up, fov, w, h)
    cosang = np.einsum("ij,ij->i", v / t[:, None], centre[hit])
    assert np.degrees(np.arccos(np.clip(cosang, -1, 1))).max() < np.degrees(pixel) * 0.75


def _fit(tmp_path, light, name):
    img, layers = _render(tmp_path, BALL.replace("LIGHT", light), 64, 64, 16, name)
    n = _layer(layers, "normal")
    cov = _layer(layers, "coverage", "field")
    L = img @ np.array([0.2126, 0.7152, 0.0722])
    lit = (cov == 1.0) & (L > 0.3 * L[cov == 1.0].max())
    assert lit.sum() > 100
    v, *_ = np.linalg.lstsq(n[lit], L[lit], rcond=None)
    return v / np.linalg.norm(v)


def _angle(a, b):
    return math.degrees(math.acos(float(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


@pytest.mark.parametrize("light", [
    'type = "directional"\nelevation = 40.0\nazimuth = 30.0\nirradiance = 3.0',
    'type = "sunsky"\nelevation = 35.0\nazimuth = 120.0\nsky_scale = 0.0',
    'type = "directional"\nelevation = 60.0\nazimuth = -100.0\nirradiance = 3.0',
])
def test_sun_azimuth_from_x_towards_y_and_elevation_above_the_ground(tmp_path, light):
    el = math.radians(float(light.split("elevation = ")[1].split("\n")[0]))
    az = math.radians(float(light.split("azimuth = ")[1].split("\n")[0]))
    want = [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
    got = _fit(tmp_path, "[[lights]]\n" + light, "sun.toml")
    assert _angle(got, want) < 6.0, (got, want)


def test_envmap_is_z_up_and_rotation_turns_it_about_z(tmp_path):
    from arches_render.imaging.exr import write_exr
    # Black everywhere but a bright 2 x 2 texel spot in the upper half of the map.
    env = np.zeros((32, 64, 3), np.float32)
    env[8:10, 40:42] = 400.0
    write_exr(tmp_path / "spot.exr", env, half=False)
    s = {}
    for rot in (0.0, 90.0):
        light = f'[[lights]]\ntype = "envmap"\nfile = "spot.exr"\nrotation = {rot}'
        s[rot] = _fit(tmp_path, light, f"env{int(rot)}.toml")
    # Rows 8-9 of 32: 45-56 degrees from the top, i.e. 34-45 degrees above the horizon.
    el0 = math.degrees(math.asin(s[0.0][2]))
    assert 30.0 < el0 < 50.0, s[0.0]
    # Column u (0 at the left edge) lies at azimuth 90 - 360 u degrees: u = 0 looks along +Y and
    # the map turns clockwise seen from above as u grows, as a panorama seen from inside does
    # (Mitsuba's Y-up map, stood up on +Z). Texels 40-41 of 64: u = 0.64, azimuth -141 degrees.
    az0 = math.degrees(math.atan2(s[0.0][1], s[0.0][0]))
    assert abs((az0 - (90.0 - 360.0 * 41 / 64) + 180) % 360 - 180) < 6.0, az0
    c, si = 0.0, 1.0  # +90 degrees about +Z: (x, y) -> (-y, x)
    turned = np.array([c * s[0.0][0] - si * s[0.0][1], si * s[0.0][0] + c * s[0.0][1], s[0.0][2]])
    assert _angle(s[90.0], turned) < 6.0, (s[0.0], s[90.0])
