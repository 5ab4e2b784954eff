"""Compositing metadata: every render EXR carries the OpenEXR standard ``worldToCamera``,
``worldToNDC``, screen window and clip planes, as OpenImageIO reads them, and the
``position`` and ``depth`` AOVs agree with them (arches_render.render.output).

Only the first test needs OpenImageIO (it is skipped without it): it reads the typed
attributes as a compositor would and checks that they are the ones the OpenEXR bindings
(the project's own reader's library, a dependency) read. The geometric checks read the
matrices through those bindings, so they run wherever the project does.

The geometric check: each pixel's ``position`` (the mean world point of its primary
hits) pushed through ``worldToNDC`` (row vector times matrix, then the divide by
``w``) lands on that pixel's centre ``((i + 1/2) / W, (j + 1/2) / H)`` in NDC, ``y``
down. A pixel's samples are spread uniformly over it, so on a smooth surface the
mean hit projects within ``1 / sqrt(12 spp)`` pixel (rms, per axis) of the centre
plus the surface's curvature across a pixel; 0.5 pixel is the goal's bound, and the
mean offset over all pixels (0 for the right convention, 1/2 pixel for a
corner-versus-centre mistake) is checked to 0.1 pixel. A transposed matrix, a
flipped axis or the wrong field of view moves the points by many pixels.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import variant
from production_helpers import write_scene

variant()

from arches_render.cli import main  # noqa: E402
from arches_render.imaging.exr import read_exr  # noqa: E402
from arches_render.render.turntable import FIRST_FRAME  # noqa: E402

W, H, SPP = 64, 36, 16

# A ground slab that fills the frame (every ray hits it) and a sphere on it: one
# surface per pixel except along the sphere's silhouette. The camera is off-axis
# and its up is tilted so that no matrix entry is trivially 0 or 1.
SCENE = """
[scene]
name = "slab"
[render]
resolution = [64, 36]
spp = 4
max_depth = 1
[camera]
origin = [1.5, -6.0, 4.0]
target = [0.2, 0.0, 0.5]
up = [0.15, 0.0, 1.0]
fov = 50.0
[[lights]]
type = "constant"
radiance = 1.0
[materials.stone]
type = "diffuse"
color = [0.5, 0.5, 0.5]
[field]
root = "slab"
material = "stone"
[nodes.slab]
type = "union"
children = [{ type = "box", center = [0.0, 0.0, -0.5], size = [60.0, 60.0, 1.0] },
            { type = "sphere", center = [0.0, 0.0, 0.8], radius = 0.8 }]
"""

CAMERA_ATTRS = ("worldToCamera", "worldToNDC", "screenWindowWidth", "screenWindowCenter", "nearClip",
                "farClip")


@pytest.fixture(scope="module")
def slab(tmp_path_factory):
    folder = tmp_path_factory.mktemp("slab")
    scene = write_scene(folder, SCENE, "slab")
    out = folder / "slab.exr"
    assert main(["render", str(scene), "-o", str(out), "--resolution", f"{W}x{H}", "--spp", str(SPP),
                 "-q"]) == 0
    return scene, out


def oiio_attributes(path) -> dict:
    """The attributes OpenImageIO reads from an EXR: ``{name: (type name, value)}``."""
    oiio = pytest.importorskip("OpenImageIO")
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    try:
        return {a.name: (str(a.type), a.value) for a in inp.spec().extra_attribs}
    finally:
        inp.close()


def exr_attributes(path) -> dict:
    """The typed header attributes as the OpenEXR bindings read them (the library behind
    :func:`~arches_render.imaging.exr.read_exr`): ``{name: value}``, an M44f as a float32
    ``(4, 4)`` array, a V2f as a ``(2,)`` array, a float as a float."""
    import OpenEXR
    return dict(OpenEXR.File(str(path)).header())


def matrix(path, name) -> np.ndarray:
    """An M44f attribute of the EXR at ``path`` as Imath stores it (row-vector layout), float64."""
    value = exr_attributes(path)[name]
    assert isinstance(value, np.ndarray) and value.shape == (4, 4) and value.dtype == np.float32, \
        f"{name} is read as {type(value).__name__} {np.shape(value)}, not an M44f"
    return value.astype(np.float64)


def project(points, m) -> np.ndarray:
    """Row-vector transform ``(P, 1) M`` with the perspective divide: the first two coordinates."""
    ph = np.concatenate([points, np.ones(points.shape[:-1] + (1,))], axis=-1) @ m
    return ph[..., :2] / ph[..., 3:4]


def single_surface_pixels(img) -> np.ndarray:
    """Pixels every sample of which hit the field, away from depth discontinuities.

    A silhouette pixel averages points of two surfaces (its mean position lies on
    neither); such a pixel, or a neighbour of one, has a depth far from the mean
    of its 4-neighbours. Interior pixels of a smooth surface differ from it by
    the depth's second difference, a few millimetres here.
    """
    cov = img.layers["coverage"][..., 0]
    d = img.layers["depth"]
    d = d[..., 0] if d.ndim == 3 else d
    ok = np.zeros(d.shape, bool)
    core = d[1:-1, 1:-1]
    nb = (d[:-2, 1:-1] + d[2:, 1:-1] + d[1:-1, :-2] + d[1:-1, 2:]) / 4.0
    ok[1:-1, 1:-1] = (np.abs(core - nb) < 0.01 * core) & (cov[1:-1, 1:-1] == 1.0)
    return ok


def test_oiio_reads_the_standard_camera_attributes(slab):
    _, out = slab
    attrs = oiio_attributes(out)
    for name in CAMERA_ATTRS:
        assert name in attrs, f"{name} missing; OIIO reads {sorted(attrs)}"
    # The matrices OpenImageIO reads are those the geometric tests below check.
    for name in ("worldToCamera", "worldToNDC"):
        assert attrs[name][0] == "matrix", f"{name} is read as {attrs[name][0]}, not a matrix"
        assert np.array_equal(np.asarray(attrs[name][1], np.float64).reshape(4, 4), matrix(out, name)), name
    assert attrs["screenWindowCenter"][0] == "float2" and np.allclose(attrs["screenWindowCenter"][1], 0.0)
    assert attrs["screenWindowWidth"][0] == "float"
    assert attrs["screenWindowWidth"][1] == pytest.approx(2 * math.tan(math.radians(50.0) / 2), rel=1e-6)
    near, far = attrs["nearClip"][1], attrs["farClip"][1]
    assert attrs["nearClip"][0] == attrs["farClip"][0] == "float" and 0 < near < far
    # The arches: strings are still there, and read_exr still reports only them.
    assert attrs["arches:scene_name"] == ("string", "slab")
    assert "worldToCamera" not in read_exr(out).header
    # oiiotool (shipped with the wheel) lists the matrices too.
    import shutil
    import subprocess
    tool = shutil.which("oiiotool")
    if tool:
        info = subprocess.run([tool, "--info", "-v", str(out)], capture_output=True, text=True, check=True).stdout
        assert "worldToCamera:" in info and "worldToNDC:" in info


def test_position_projects_to_its_pixel_centre(slab):
    _, out = slab
    img = read_exr(out)
    m = matrix(out, "worldToNDC")
    ok = single_surface_pixels(img)
    assert ok.sum() > 0.8 * W * H  # the slab fills the frame: most pixels qualify
    ndc = project(img.layers["position"].astype(np.float64), m)
    j, i = np.mgrid[0:H, 0:W]
    centre = np.stack([(i + 0.5) / W, (j + 0.5) / H], axis=-1)  # NDC: x right, y down
    err_px = (ndc - centre) * np.array([W, H])
    dist = np.linalg.norm(err_px, axis=-1)[ok]
    assert dist.max() <= 0.5, f"worst pixel {dist.max():.3f} px from its centre"
    bias = err_px[ok].mean(axis=0)
    assert np.all(np.abs(bias) < 0.1), f"mean offset {bias} px"


def test_depth_is_distance_in_camera_space(slab):
    _, out = slab
    img = read_exr(out)
    w2c = matrix(out, "worldToCamera")
    ok = single_surface_pixels(img)
    p = img.layers["position"].astype(np.float64)
    pc = np.concatenate([p, np.ones(p.shape[:-1] + (1,))], axis=-1) @ w2c
    assert np.allclose(pc[..., 3], 1.0)  # affine: the translation is in the last row
    depth = img.layers["depth"]
    depth = (depth[..., 0] if depth.ndim == 3 else depth).astype(np.float64)
    # depth is the distance from the camera centre, |P_cam|, not z_cam (they differ
    # by 1/cos of the angle off the axis: up to 11 % at this frame's corners).
    rel = np.abs(np.linalg.norm(pc[..., :3], axis=-1) - depth) / depth
    assert rel[ok].max() < 1e-3, f"|p_cam| vs depth: {rel[ok].max():.2e}"
    # Camera space as OpenEXR/RenderMan define it: in front is +z, image up is +y,
    # image right is +x (left-handed).
    assert np.all(pc[..., 2][ok] > 0)
    top, bottom = pc[1, :, 1] / pc[1, :, 2], pc[-2, :, 1] / pc[-2, :, 2]
    left, right = pc[:, 1, 0] / pc[:, 1, 2], pc[:, -2, 0] / pc[:, -2, 2]
    assert np.all(top > bottom) and np.all(right > left)
    # Rigid, and a mirror: world space is right-handed, camera space left-handed,
    # so the rotation part is orthogonal with determinant -1.
    R = w2c[:3, :3]
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.linalg.det(R) == pytest.approx(-1.0, abs=1e-5)


def test_tiled_and_turntable_frames_carry_the_same_attributes(slab, tmp_path):
    scene, out = slab
    ref = exr_attributes(out)
    tiled = tmp_path / "tiled.exr"
    assert main(["render", str(scene), "-o", str(tiled), "--resolution", f"{W}x{H}", "--spp", "1",
                 "--tiles", "2", "-q"]) == 0
    frames = tmp_path / "tt"
    assert main(["turntable", str(scene), "-o", str(frames), "--frames", "2", "--resolution", f"{W}x{H}",
                 "--spp", "1", "-q"]) == 0
    got = exr_attributes(tiled)
    for name in CAMERA_ATTRS:
        assert np.allclose(got[name], ref[name]), name
    # Frame 1 of a turntable is the scene's own camera; frame 2 has moved on.
    f0, f1 = (exr_attributes(frames / f"slab.{FIRST_FRAME + k}.exr") for k in range(2))
    # Frame 1's camera is recomputed from the orbit (angle 0: cos/sin and the origin's
    # rotation in float32), so its matrix equals the still's up to rounding, not bitwise.
    assert np.allclose(f0["worldToNDC"], ref["worldToNDC"], atol=1e-6)
    assert not np.allclose(f1["worldToNDC"], ref["worldToNDC"])
    assert f1["nearClip"] == ref["nearClip"] and f1["farClip"] == ref["farClip"]
