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
    # Normals are unit length where a pixel sees one surface; the plane's is +Z.
    pure = (c["field"] == 1.0) | (c["mesh"] == 1.0)
    norm = np.linalg.norm(n, axis=-1)
    assert np.abs(norm[pure & (np.abs(n[..., 2] - 1) < 1e-3)] - 1).max() < 1e-4
    assert pure.sum() > 400
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
    out = flat.parent / "aces.exr"
    assert main(["render", str(flat), "-o", str(out), "--spp", "1", "--view", "aces", "--no-aovs", "-q"]) == 0
    assert out.with_suffix(".png").is_file()
    assert main(["render", str(flat), "-o", str(out), "--view", "nope"]) == 2
    assert "--view must be one of" in capsys.readouterr().err


def test_triplanar_textures_decode_srgb_colour_and_keep_data_linear(tmp_path):
    import imageio.v3 as iio

    from arches_render.materials.triplanar import _load_texture
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    iio.imwrite(tmp_path / "grey.png", np.full((4, 4, 3), 128, np.uint8))
    colour_tex = np.asarray(_load_texture(str(tmp_path / "grey.png"), True, False).tensor())
    data_tex = np.asarray(_load_texture(str(tmp_path / "grey.png"), False, False).tensor())
    assert np.allclose(colour_tex, colour.cctf_decoding(128 / 255, function="sRGB"), atol=1e-5)
    assert np.allclose(data_tex, 128 / 255, atol=1e-6)


def test_tiled_still_is_assembled_from_its_tiles(flat):
    from arches_render.render.distributed import render_tiled, tile_grid
    from arches_render.render.jobs import RenderJob, run_job
    grid = tile_grid(32, 18, 4)
    assert sum(w * h for _, _, w, h in grid) == 32 * 18 and len(grid) == 4
    job = RenderJob(scene=str(flat), width=32, height=18, spp=2)
    rgb, layers = render_tiled(job, 4)
    x0, y0, w, h = grid[3]
    tile, tile_layers = run_job(job.with_(crop=grid[3], stream=3))
    assert np.array_equal(rgb[y0:y0 + h, x0:x0 + w], tile)
    assert np.array_equal(layers["depth"][0][y0:y0 + h, x0:x0 + w], tile_layers["depth"][0])
    assert np.allclose(layers["coverage"][0].sum(axis=-1), 1.0)  # every tile landed


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
