"""Lookdev materials: strata colours from the geology, tiling without repetition, detail, cavity, wetness."""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from scipy import ndimage

from helpers import variant

variant()

from arches_render import field as F  # noqa: E402
from arches_render.materials import detail as D, masks as M, textures as T, triplanar as tp  # noqa: E402
from arches_render.render.renderer import build_scene, render_layers  # noqa: E402
from arches_render import tomlfile  # noqa: E402
from arches_render.scene import SceneError, parse_scene  # noqa: E402

CTX = mi.BSDFContext()


def _si(p, n, wi=(0.0, 0.0, 1.0), t=1.0):
    p = np.asarray(p, np.float32).reshape(-1, 3)
    n = np.asarray(n, np.float64).reshape(-1, 3)
    n = (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, len(p))
    si.p = mi.Point3f(p.T)
    si.n = mi.Normal3f(n.T)
    si.sh_frame = mi.Frame3f(si.n)
    si.wi = mi.Vector3f(np.tile(np.asarray(wi, np.float32), (len(p), 1)).T)
    si.t = mi.Float(t)
    return si


def _scene(text, tmp_path, name="s.toml"):
    path = tmp_path / name
    path.write_text(text)
    return parse_scene(tomlfile.loads(text), path)


def _np(x):
    return np.array(x, dtype=np.float64)


# ------------------------------------------------------------------ strata
STRATA_CLIFF = """
[render]
resolution = [72, 96]
spp = 2

[camera]
origin = [0.0, -70.0, 12.0]
target = [0.0, 0.0, 12.0]
fov = 22.0

[[lights]]
type = "directional"
direction = [0.3, 1.0, -0.6]

[materials.cliff]
type = "triplanar"
preset = "basalt"
detail = false
overrides = { "rock.texture" = "" }
strata = { node = "geology", palette = "sandstone", levels = [0.3, 0.5, 0.75] }

[nodes.geology]
type = "resistance_fold"
amplitude = 1.2
wavelength = 14.0
seed = 3
child = { type = "resistance_blend", children = [{ type = "resistance_constant", value = 0.2 },
          { type = "resistance_strata", spacing = 4.0, R = 1.9, weight = 0.8 }] }

[field]
root = { type = "box", center = [0.0, 0.0, 12.0], size = [40.0, 20.0, 30.0] }
material = "cliff"
"""


def test_strata_colours_change_exactly_where_the_layer_function_does(tmp_path):
    desc = _scene(STRATA_CLIFF, tmp_path)
    scene = build_scene(desc, "field", aovs=True)
    _, layers = render_layers(scene, 2, seed=5)
    albedo, pos, normal = layers["albedo"][0], layers["position"][0], layers["normal"][0]
    geology = desc.material_nodes["cliff"]["strata"]
    levels = [0.3, 0.5, 0.75]
    palette = np.array(M.PALETTES["sandstone"])
    face = normal[..., 1] < -0.999  # pixels wholly on the cliff face that looks at the camera
    assert face.mean() > 0.8
    rho = F.evaluate(geology, pos.reshape(-1, 3)).reshape(pos.shape[:2])
    k = M.strata_index(rho, levels)
    assert len(np.unique(k[face])) == 4  # every stratum shows
    # Away from stratum boundaries the albedo is the palette colour of the layer function.
    same = face.copy()
    same[1:] &= k[1:] == k[:-1]
    same[:-1] &= k[:-1] == k[1:]
    assert np.abs(albedo[same] - palette[k[same]]).max() < 2e-3
    # Along every vertical line: a colour change between two pixels <=> a change of the
    # layer function within one pixel (the pixel averages its samples, its position too).
    changes_colour = np.abs(np.diff(albedo, axis=0)).max(-1) > 0.01
    changes_layer = k[1:] != k[:-1]
    near = changes_layer.copy()
    near[1:] |= changes_layer[:-1]
    near[:-1] |= changes_layer[1:]
    both = face[1:] & face[:-1]
    assert changes_layer[both].sum() > 3 * albedo.shape[1]
    assert not (changes_colour & both & ~near).any(), "colour changes where the layer function does not"
    missed = changes_layer & both & ~(changes_colour | np.roll(changes_colour, 1, 0) | np.roll(changes_colour, -1, 0))
    assert not missed.any(), "the layer function changes where the colour does not"


def test_strata_index_and_keys_validate(tmp_path):
    assert list(M.strata_index([0.0, 0.29, 0.3, 0.6, 1.3], [0.3, 0.5, 0.75])) == [0, 0, 1, 2, 3]
    bad = STRATA_CLIFF.replace("levels = [0.3, 0.5, 0.75]", "levels = [0.5, 0.3, 0.75]")
    with pytest.raises(SceneError, match=r"materials\.cliff\.strata\.levels.*increasing"):
        _scene(bad, tmp_path)
    bad = STRATA_CLIFF.replace('palette = "sandstone"', 'palette = "marble"')
    with pytest.raises(SceneError, match=r"strata\.palette.*sandstone"):
        _scene(bad, tmp_path)
    bad = STRATA_CLIFF.replace("detail = false", 'masks = [{ layer = "rock", kind = "cavity" }]')
    with pytest.raises(SceneError, match="layer"):
        _scene(bad, tmp_path)


# -------------------------------------------------------------- repetition
FLAT_GROUND = """
[render]
resolution = [400, 225]
spp = 2

[camera]
origin = [0.0, 0.0, 3.0]
target = [0.0, 40.0, 0.0]
fov = 60.0

[[lights]]
type = "directional"
direction = [0.3, 0.5, -1.0]

[materials.ground]
type = "triplanar"
preset = "terrain"
overrides = { "rock.scale" = 2.0, "sand.coverage" = 0.0, "grass.coverage" = 0.0, "snow.coverage" = 0.0 }
{extra}

[[meshes]]
shape = "rectangle"
scale = 400.0
material = "ground"
"""


def _autocorrelation_peak(albedo, pos, cell=0.1, box=(-6.0, 6.0, 3.0, 15.0), max_lag=30, highpass=5.0, min_lag=8):
    """Largest normalised 2-D autocorrelation of the albedo resampled on the ground, lags 8..30 cells (0.8..3 m; the texture repeats every 2 m).

    The ground-plane image is high-passed first (minus its Gaussian blur of ``highpass``
    cells, both normalised over the covered cells) so that variations slower than the
    texture (the detail's large octaves, the light) do not count as correlation.
    """
    x0, x1, y0, y1 = box
    nx, ny = int(round((x1 - x0) / cell)), int(round((y1 - y0) / cell))
    lum = albedo.mean(-1)
    ix = np.floor((pos[..., 0] - x0) / cell).astype(int)
    iy = np.floor((pos[..., 1] - y0) / cell).astype(int)
    ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny) & (np.abs(pos[..., 2]) < 1e-3)
    s, c = np.zeros((ny, nx)), np.zeros((ny, nx))
    np.add.at(s, (iy[ok], ix[ok]), lum[ok])
    np.add.at(c, (iy[ok], ix[ok]), 1.0)
    valid = c > 0
    assert valid.mean() > 0.5
    img = np.where(valid, s / np.maximum(c, 1), 0.0)
    blur = ndimage.gaussian_filter(img, highpass) / np.maximum(ndimage.gaussian_filter(valid * 1.0, highpass), 1e-6)
    g = np.where(valid, img - blur, 0.0)
    shape = (2 * ny, 2 * nx)
    ac = np.fft.irfft2(np.abs(np.fft.rfft2(g, s=shape)) ** 2, s=shape)
    n = np.fft.irfft2(np.abs(np.fft.rfft2(valid.astype(float), s=shape)) ** 2, s=shape)
    ac = np.fft.fftshift(ac / np.maximum(n, 1.0) / ((g ** 2).sum() / valid.sum()))
    cy, cx = ny, nx
    win = ac[cy - max_lag:cy + max_lag + 1, cx - max_lag:cx + max_lag + 1]
    yy, xx = np.mgrid[-max_lag:max_lag + 1, -max_lag:max_lag + 1]
    return float(win[np.hypot(yy, xx) >= min_lag].max())


@pytest.mark.parametrize("look", ["preset", "opt_out"])
def test_ground_albedo_has_no_periodic_peak(look, tmp_path):
    # "preset" is the terrain preset as shipped (histogram tiling and detail, issue 24);
    # "opt_out" turns both off: a repeated texture, no detail, whose period must show.
    extra = 'detail = false\ntiling = "repeat"\noverrides = { "rock.scale" = 2.0, ' \
            '"sand.coverage" = 0.0, "grass.coverage" = 0.0, "snow.coverage" = 0.0 }' if look == "opt_out" else ""
    text = FLAT_GROUND.replace("{extra}", extra)
    if look == "opt_out":
        text = text.replace('overrides = { "rock.scale" = 2.0, "sand.coverage"', '# overrides', 1)
    desc = _scene(text, tmp_path)
    scene = build_scene(desc, "field", aovs=True)
    _, layers = render_layers(scene, 2, seed=1)
    peak = _autocorrelation_peak(layers["albedo"][0], layers["position"][0])
    THRESHOLD = 0.15
    if look == "opt_out":
        assert peak > THRESHOLD, f"the repeated texture should show its period (peak {peak:.3f})"
    else:
        assert peak < THRESHOLD, f"periodic peak {peak:.3f} in the ground's albedo"


def test_histogram_tiling_keeps_the_histogram_and_breaks_the_period():
    rng = np.random.default_rng(2)
    uv = rng.uniform(-20, 20, (2, 200_000)).astype(np.float32)
    arr = T._read(T.texture_path("rock_gravel.png"), True, True)
    values = {}
    for tiling in ("repeat", "histogram"):
        tex = T.load_texture("rock_gravel.png", tiling=tiling)
        a = _np(tex.eval(mi.Point2f(uv)))[0]
        b = _np(tex.eval(mi.Point2f(uv[0] + 1.0, uv[1])))[0]  # one period further
        values[tiling] = (a, np.corrcoef(a, b)[0, 1])
    a, corr = values["histogram"]
    assert values["repeat"][1] > 0.999 and abs(corr) < 0.1
    q = np.linspace(0.05, 0.95, 10)
    # The blended tiles keep the texture's histogram (bilinear lookups smooth it a little).
    assert np.abs(np.quantile(a, q) - np.quantile(arr[..., 0], q)).max() < 0.08
    assert abs(a.mean() - arr.mean()) < 0.02 and abs(a.std() / arr.std() - 1) < 0.15
    # A footprint covering the texture returns its mean, whatever the tile.
    wide = _np(T.load_texture("rock_gravel.png").eval(mi.Point2f(uv), mi.Float(1e6)))[0]
    assert np.abs(wide - arr.mean()).max() < 0.01


# ------------------------------------------------------------------ detail
def _detail_bsdf(**extra):
    layers = [tp.Layer(tint=(0.5, 0.5, 0.5), roughness=0.5)]
    return mi.load_dict(tp.triplanar_dict(layers, detail_octaves=6, detail_wavelength=4.0, **extra))


def test_detail_fades_under_the_footprint_and_bumps_consistently():
    rng = np.random.default_rng(4)
    p = rng.uniform(-50, 50, (20000, 3))
    b = _detail_bsdf()
    near = _np(b.albedo(_si(p, [[0, 0, 1]] * len(p), t=1.0)))[0]
    params = mi.traverse(b)
    params["pixel_spread"] = D.pixel_spread(60.0, 640)
    params.update()
    mid = _np(b.albedo(_si(p, [[0, 0, 1]] * len(p), t=30.0)))[0]
    far = _np(b.albedo(_si(p, [[0, 0, 1]] * len(p), t=1e5)))[0]
    assert 0.08 < near.std() and far.std() < 1e-6 and mid.std() < near.std()
    assert abs(far.mean() - 0.5) < 1e-6
    # A secondary vertex 1 m from the last bounce, its ray cone 0.5 m wide: the cone, not
    # the bounce length, sets the footprint (the fine octaves drop out).
    si = _si(p, [[0, 0, 1]] * len(p), t=1.0)
    fp_pixel = _np(D.footprint(si, params["pixel_spread"]))
    fp_cone = _np(D.footprint(si, params["pixel_spread"], mi.Float(0.25)))
    assert np.allclose(fp_cone, 0.5, rtol=1e-5) and (fp_pixel < 0.01).all()
    assert [float(D.octave_weight(mi.Float(w), mi.Float(1.0))[0]) for w in (1.9, 2.0, 3.0, 4.0, 9.0)] == \
        pytest.approx([0.0, 0.0, 0.5, 1.0, 1.0])
    # Bumped: sample weight == eval / pdf, nothing below the geometric surface.
    b = _detail_bsdf(detail_bump=0.4)
    count = 4096
    si = _si(rng.uniform(-5, 5, (count, 3)), rng.normal(size=(count, 3)), t=1.0)
    wi = rng.normal(size=(count, 3))
    si.wi = mi.Vector3f((wi / np.linalg.norm(wi, axis=1, keepdims=True)).T.astype(np.float32))
    s = rng.random((3, count)).astype(np.float32)
    bs, weight = b.sample(CTX, si, mi.Float(s[0]), mi.Point2f(s[1], s[2]))
    value, pdf = b.eval_pdf(CTX, si, bs.wo)
    w, v, pd = _np(weight), _np(value), _np(pdf)
    ok = pd > 1e-3
    assert ok.sum() > count // 3
    assert np.allclose(w[:, ok], v[:, ok] / pd[ok], rtol=1e-4, atol=1e-6)
    assert (_np(bs.wo.z)[ok] > 0).all()
    # The bump really tilts the normal: the BRDF differs from the flat one.
    flat = _detail_bsdf(detail_bump=0.0)
    assert np.abs(_np(flat.eval(CTX, si, bs.wo)) - v)[:, ok].mean() > 1e-3


# ---------------------------------------------------------- cavity, wetness
def test_cavity_darkens_caves_and_overhangs_and_wetness_the_shore():
    # A slab of rock 0 < z < 10 with a spherical cave of radius 4 centred at z = 5.
    slab = F.Box([0, 0, 5], [50, 50, 5])  # half extents
    rock = F.Difference(slab, F.Sphere([0, 0, 5], 4.0))
    b = mi.load_dict(tp.triplanar_dict([tp.Layer(tint=(0.5, 0.5, 0.5))], cavity=True, cavity_radius=2.0,
                                       wetness=True, wet_level=0.0, wet_height=1.0))
    b.set_node("cavity", rock)
    pts = [[30, 30, 10.0], [0, 0, 1.0], [0, 0, 9.0], [4.0, 0, 5.0]]   # open top, cave floor, ceiling, wall
    normals = [[0, 0, 1], [0, 0, 1], [0, 0, -1], [-1, 0, 0]]
    si = _si(pts, normals)
    occ = _np(b.look.occlusion(si.p, si.sh_frame.n))
    assert occ[0] < 0.05 and (occ[1:] > 0.5).all(), occ
    alb = _np(b.albedo(si))[0]
    assert alb[0] > 0.45 and (alb[1:] < 0.3).all(), alb
    # Wetness: at and below the water line darker than 2 m above it.
    b2 = mi.load_dict(tp.triplanar_dict([tp.Layer(tint=(0.5, 0.4, 0.3))], wetness=True, wet_level=0.0,
                                        wet_height=1.0))
    a = _np(b2.albedo(_si([[0, 0, -1.0], [0, 0, 0.5], [0, 0, 2.0]], [[0, 0, 1]] * 3)))
    assert a[0, 0] < a[0, 1] < a[0, 2] and np.allclose(a[:, 2], [0.5, 0.4, 0.3], atol=1e-6)
    assert a[0, 0] / a[2, 0] > 0.5 / 0.3  # wet rock is more saturated


def test_cavity_mask_and_scene_keys(tmp_path):
    text = STRATA_CLIFF.replace("detail = false", 'detail = false\ncavity = { radius = 1.5 }\n'
                                'wetness = { level = 2.0 }')
    desc = _scene(text, tmp_path)
    m = desc.materials["cliff"]
    assert m["cavity"] and m["cavity_radius"] == 1.5 and m["wet_level"] == 2.0 and m["detail_octaves"] == 0
    from arches_render.scene.material_keys import FIELD_ROOT
    assert desc.material_nodes["cliff"]["cavity"] == FIELD_ROOT
    bad = text.replace("radius = 1.5", "radius = -1.5")
    with pytest.raises(SceneError, match=r"cavity\.radius"):
        _scene(bad, tmp_path)
    assert math.isclose(D.pixel_spread(90.0, 2), 1.0)


def test_average_ranks_are_scipys_average_ranks():
    """``average_ranks`` stands in for ``scipy.stats.rankdata(method='average')`` (whose
    import costs 0.9 s in every process): the same floats, ties included."""
    from scipy.stats import rankdata

    from arches_render.materials.textures import average_ranks
    rng = np.random.default_rng(0)
    for v in (rng.random(1000), rng.integers(0, 20, 5000).astype(float), np.round(rng.normal(size=4096), 1)):
        assert np.array_equal(average_ranks(v), rankdata(v, method="average"))
