"""Production outputs as a user meets them: AOV layers and header of `render`,
`--denoise`, view transforms, sRGB texture decoding, tiles, and the lookdev API."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

from helpers import REPO, variant
from production_helpers import FLAT, assert_edits_compile_nothing, write_scene

variant()

from arches_render.cli import main  # noqa: E402
from arches_render.imaging.exr import read_exr  # noqa: E402


@pytest.fixture(scope="module")
def flat(tmp_path_factory):
    return write_scene(tmp_path_factory.mktemp("flat"), FLAT, "flat")


@pytest.fixture(scope="module")
def flat_render(flat):
    """`arches-render render` of the flat scene at 64 spp (AOVs on by default), and with --denoise."""
    out = flat.parent / "flat.exr"
    assert main(["render", str(flat), "-o", str(out), "--spp", "64", "-q"]) == 0
    den = flat.parent / "flat_denoised.exr"
    assert main(["render", str(flat), "-o", str(den), "--spp", "64", "--denoise", "-q"]) == 0
    return read_exr(out), read_exr(den)


def _pixel_directions(width, height, fov_deg, sub=16):
    """Unit ray directions (camera space, -z forward) at sub x sub points per pixel."""
    tx = np.tan(np.radians(fov_deg) / 2)
    ty = tx * height / width
    s = (np.arange(sub) + 0.5) / sub
    x = (np.arange(width)[:, None] + s[None, :]).ravel() / width * 2 - 1
    y = 1 - (np.arange(height)[:, None] + s[None, :]).ravel() / height * 2
    X, Y = np.meshgrid(x * tx, y * ty)
    d = np.stack([X, Y, -np.ones_like(X)], -1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def test_render_exr_has_aov_layers_and_header(flat_render):
    img, _ = flat_render
    for layer in ("albedo", "normal", "depth", "position", "coverage", "layers"):
        assert layer in img.layers, sorted(img.layers)
    h = img.header
    assert h["scene_name"] == "flat" and h["seed"] == "0" and h["spp"] == "64"
    assert h["camera_origin"] == "0 0 10" and h["camera_target"] == "0 0 0" and h["camera_fov"] == "60"
    assert h["arches_render_version"] and h["resolution"] == "32x18"


def test_depth_is_the_analytic_distance_to_the_plane(flat_render):
    img, _ = flat_render
    cov = img.layers["coverage"]
    field = dict(zip(img.layer_channels["coverage"], np.moveaxis(cov, -1, 0)))["field"]
    pos = img.layers["position"]
    depth = img.layers["depth"]
    # Pixels that see only the flat top (not the ball or the mesh sphere).
    plane = (field == 1.0) & (np.abs(pos[..., 2]) < 1e-3)
    plane &= np.hypot(pos[..., 0] - 3.0, pos[..., 1] - 1.0) > 1.6
    plane &= np.hypot(pos[..., 0], pos[..., 1]) > 1.6
    assert plane.sum() > 300
    # Ray length to z = 0 from 10 m: 10 / cos(theta), averaged over the pixel (box filter).
    d = _pixel_directions(32, 18, 60.0)
    t = 10.0 / -d[..., 2]
    expected = t.reshape(18, 16, 32, 16).mean(axis=(1, 3))
    rel = np.abs(depth[plane] - expected[plane]) / expected[plane]
    assert rel.max() < 5e-3 and np.median(rel) < 1e-3, (rel.max(), np.median(rel))


def test_normals_coverage_weights_albedo(flat_render):
    img, _ = flat_render
    n = img.layers["normal"]
    c = dict(zip(img.layer_channels["coverage"], np.moveaxis(img.layers["coverage"], -1, 0)))
    # Every pixel sees a surface: coverage adds up to 1 (field or mesh).
    assert np.allclose(c["field"] + c["mesh"], 1.0, atol=1e-6)
    # The mesh sphere of radius 1 at the origin, seen from above: mesh at the centre.
    cy, cx = 9, 16
    assert c["mesh"][cy - 1:cy + 1, cx - 1:cx + 1].min() == 1.0
    assert c["field"][cy - 1:cy + 1, cx - 1:cx + 1].max() == 0.0
    assert np.allclose(img.layers["albedo"][cy, cx], [0.2, 0.4, 0.6], atol=1e-6)
    # Normals against the analytic ones. A sphere's normal (p - c) / r is linear in p, so the
    # pixel-averaged normal (box filter) is exactly that of the pixel-averaged position: plane
    # +Z, the field ball about (3, 1, 0.5), the mesh sphere about (0, 0, 1), radius 1 both.
    from scipy.ndimage import binary_erosion
    pos = img.layers["position"]
    checks = [
        ("plane", (c["field"] == 1.0) & (np.abs(pos[..., 2]) < 1e-3)
         & (np.hypot(pos[..., 0] - 3.0, pos[..., 1] - 1.0) > 1.6) & (np.hypot(pos[..., 0], pos[..., 1]) > 1.6),
         lambda p: np.broadcast_to([0.0, 0.0, 1.0], p.shape), 2e-3, 60),
        # Pixels whose neighbours all see the ball too: none mixes ball and slab samples.
        ("field ball", binary_erosion((c["field"] == 1.0) & (pos[..., 2] > 0.2)
                                      & (np.linalg.norm(pos - [3.0, 1.0, 0.5], axis=-1) < 1.01), np.ones((3, 3))),
         lambda p: p - [3.0, 1.0, 0.5], 1e-2, 4),
        ("mesh sphere", c["mesh"] == 1.0, lambda p: p - [0.0, 0.0, 1.0], 1e-2, 4),
    ]
    for what, mask, analytic, tol, least in checks:
        assert mask.sum() >= least, (what, int(mask.sum()))
        want = analytic(pos[mask])
        err = np.linalg.norm(n[mask] - want, axis=-1).max()
        assert err < tol, (what, err)
    # Triplanar layer weights sum to the field coverage; albedo within [0, 1].
    w = img.layers["layers"].sum(axis=-1)
    assert np.allclose(w, c["field"], atol=1e-5)
    assert set(img.layer_channels["layers"]) == {"rock", "sand", "grass", "snow"}
    a = img.layers["albedo"]
    assert a.min() >= 0 and a.max() <= 1 and a[c["field"] == 1].std() > 0


def test_denoise_adds_a_layer_and_keeps_the_beauty(flat, flat_render):
    img, den = flat_render
    assert "denoised" in den.layers and "denoised" not in img.layers
    assert np.array_equal(img.rgb, den.rgb)  # raw beauty untouched
    # The denoised image is closer to a converged render than the raw one.
    ref = flat.parent / "ref.exr"
    assert main(["render", str(flat), "-o", str(ref), "--spp", "1024", "--no-aovs", "--seed", "5", "-q"]) == 0
    r = read_exr(ref).rgb
    raw4 = flat.parent / "raw4.exr"
    assert main(["render", str(flat), "-o", str(raw4), "--spp", "4", "--denoise", "-q"]) == 0
    low = read_exr(raw4)
    err_raw = np.mean((low.rgb - r) ** 2)
    err_den = np.mean((low.layers["denoised"] - r) ** 2)
    assert err_den < 0.5 * err_raw, (err_den, err_raw)


def test_view_transforms():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    from arches_render.imaging.colour import apply_view, ocio_config
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 1.2, (8, 8, 3)).astype(np.float32)
    srgb = apply_view(img, "srgb")
    assert np.allclose(srgb, colour.cctf_encoding(np.clip(img, 0, 1), function="sRGB"), atol=1e-6)
    # OCIO's un-tone-mapped sRGB display agrees with colour-science (LUT-free CPU path).
    assert np.abs(apply_view(img, "untonemapped") - srgb).max() < 1e-4
    # ACES comes from the built-in config shipped in the wheel: no file, no network.
    assert "studio-config" in ocio_config().getName()
    ramp = np.repeat(np.logspace(-3, 2, 32, dtype=np.float32)[None, :, None], 3, axis=2)
    aces = apply_view(ramp, "aces")[0, :, 1]
    assert np.all(np.diff(aces) >= -1e-6) and aces[-1] > 0.9 and aces[0] < 0.05
    # Tone mapping compresses highlights: 4.0 is not clipped to white as in sRGB.
    assert apply_view(np.full((1, 1, 3), 4.0, np.float32), "aces").max() < 0.999
    with pytest.raises(ValueError, match="allowed"):
        apply_view(img, "filmic")


def test_cli_view_and_bad_view(flat, capsys):
    """The PNG of `--view aces` is the ACES view of the EXR beside it, not the sRGB one."""
    import imageio.v3 as iio
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    from arches_render.imaging.colour import view_to_uint8
    pngs = {}
    for view in ("aces", "srgb"):
        out = flat.parent / f"{view}.exr"
        assert main(["render", str(flat), "-o", str(out), "--spp", "2", "--view", view, "--no-aovs", "-q"]) == 0
        image = read_exr(out)
        exr, png = image.rgb, iio.imread(out.with_suffix(".png"))[..., :3].astype(int)
        exposure = float(image.header["exposure"])   # metered: the scene sets none
        assert png.shape == exr.shape
        # The PNG is the named view of this very EXR at the exposure its header records (within a rounding step).
        assert np.abs(png - view_to_uint8(exr, view, exposure).astype(int)).max() <= 1, view
        pngs[view] = (exr, png, exposure)
    (exr_a, aces, _), (exr_s, srgb, exposure) = pngs["aces"], pngs["srgb"]
    assert np.array_equal(exr_a, exr_s)  # same seed: the views differ, the pixels do not
    # The sRGB PNG is the plain sRGB encoding (IEC 61966-2-1, by colour-science) of the exposed, clipped EXR.
    want = np.round(255 * colour.cctf_encoding(np.clip(exr_s * 2.0 ** exposure, 0, 1), function="sRGB")).astype(int)
    assert np.abs(srgb - want).max() <= 1
    # ACES tone-maps: other values, the same order of brightness.
    assert np.abs(aces - srgb).mean() > 5
    ya, ys = aces @ [0.2126, 0.7152, 0.0722], srgb @ [0.2126, 0.7152, 0.0722]
    assert np.corrcoef(ya.ravel(), ys.ravel())[0, 1] > 0.9
    assert main(["render", str(flat), "-o", str(flat.parent / "aces.exr"), "--view", "nope"]) == 2
    assert "--view must be one of" in capsys.readouterr().err


def test_triplanar_textures_decode_srgb_colour_and_keep_data_linear(tmp_path):
    import imageio.v3 as iio

    from arches_render.materials.textures import load_texture
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    iio.imwrite(tmp_path / "grey.png", np.full((4, 4, 3), 128, np.uint8))
    colour_tex = np.asarray(load_texture(str(tmp_path / "grey.png"), True, False, tiling="repeat").pyramid.level_array(0))
    data_tex = np.asarray(load_texture(str(tmp_path / "grey.png"), False, False, tiling="repeat").pyramid.level_array(0))
    assert np.allclose(colour_tex, colour.cctf_decoding(128 / 255, function="sRGB"), atol=1e-5)
    assert np.allclose(data_tex, 128 / 255, atol=1e-6)


def test_tiled_still_matches_the_untiled_one(flat):
    """A tiled render is the untiled image: every tile in its place (position and depth AOVs agree
    to within the sub-pixel sampling noise, a fraction of the 0.36 m pixel), the beauty within its
    noise. Serial and Dask tiles are the same bits (tests/test_render_jobs.py)."""
    from arches_render.render.distributed import render_tiled, tile_grid
    from arches_render.render.jobs import RenderJob, run_job
    grid = tile_grid(32, 18, 6)
    assert sum(w * h for _, _, w, h in grid) == 32 * 18 and len(grid) == 6
    job = RenderJob(scene=str(flat), width=32, height=18, spp=32)
    rgb, layers = render_tiled(job, 6)
    ref_rgb, ref = run_job(job)
    cov = dict(zip(ref["coverage"][1], np.moveaxis(ref["coverage"][0], -1, 0)))
    tcov = dict(zip(layers["coverage"][1], np.moveaxis(layers["coverage"][0], -1, 0)))
    pos, tpos = ref["position"][0], layers["position"][0]
    # Pixels that see the flat slab only, in both renders (no silhouette inside the pixel).
    plane = ((cov["field"] == 1) & (tcov["field"] == 1) & (np.abs(pos[..., 2]) < 1e-3)
             & (np.abs(tpos[..., 2]) < 1e-3))
    assert plane.sum() > 300
    d = np.linalg.norm(tpos - pos, axis=-1)[plane]
    assert d.max() < 0.12 and np.median(d) < 0.04, (d.max(), np.median(d))  # a pixel is 0.36 m
    depth, tdepth = (np.asarray(x["depth"][0]).reshape(18, 32) for x in (ref, layers))
    rel = np.abs(tdepth - depth)[plane] / depth[plane]
    assert rel.max() < 5e-3, rel.max()
    # Beauty: each tile's mean within the noise of the two renders.
    for x0, y0, w, h in grid:
        a, b = rgb[y0:y0 + h, x0:x0 + w].mean(), ref_rgb[y0:y0 + h, x0:x0 + w].mean()
        assert abs(a - b) < 0.03 * b, ((x0, y0), a, b)
    assert abs(rgb.mean() - ref_rgb.mean()) < 0.01 * ref_rgb.mean()


def test_lookdev_api_edits_without_recompiling(flat):
    from arches_render import api
    look = api.load(flat, resolution=(32, 18), spp=2)
    look.render()
    base = look.render()
    assert look.compiled == 0
    edits = {"materials.ground.rock.tint": [0.7, 0.2, 0.1], "materials.paint.color": [0.9, 0.9, 0.1],
             "lights.0.elevation": 20.0, "camera.origin": [0.5, -0.5, 9.0], "camera.fov": 50.0,
             "nodes.ball.radius": 1.4, "nodes.ball.center": [2.5, 0.5, 0.5]}
    prev = assert_edits_compile_nothing(look, edits, base)
    assert look.rebuilds == 1
    # The edited session renders what a fresh load of the edited scene renders.
    fresh = api.load(flat, resolution=(32, 18), spp=2).update(edits)
    assert np.array_equal(fresh.render(), prev)
    assert look.get("nodes.ball.radius") == 1.4
    res = api.compare(base, prev)
    assert not res.passed
    assert api.compare(prev, prev).passed


def test_lookdev_api_rejects_bad_values(flat):
    from arches_render import api
    from arches_render.scene import SceneError
    look = api.load(flat, resolution=(16, 9), spp=1)
    with pytest.raises(SceneError, match="radius"):
        look.set("nodes.ball.radius", -1.0)
    with pytest.raises(KeyError):
        look.set("nodes.nothing.radius", 1.0)
    assert look.get("nodes.ball.radius") == 1.0  # unchanged after the failed edit


def test_lookdev_example_runs(tmp_path):
    r = subprocess.run([sys.executable, str(REPO / "examples" / "lookdev.py"), "--resolution", "32x18",
                        "--spp", "2", "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "lookdev_after.exr").is_file() and "compiled" in r.stdout
