"""Issue 33 part 2, "make the look cheap": the shortcuts of the triplanar material
must not change what it computes beyond their stated bounds.

* MIP pyramids (``materials/mipmap.py``): box-filtered levels, bilinear lookups with
  wrap-around, a stochastic level choice whose expectation is the trilinear value;
* projections ranked by weight, the negligible ones dropped (``weights.py``): within
  ``2 MIN_PROJECTION`` of the texture's range of the three-projection blend;
* layers skipped per SIMD packet where their weight is zero: the same result as
  evaluating every layer;
* mesh mode: the field's material on its mesh is shaded once per vertex by
  ``implicit_path``, which converges to the image of Mitsuba's ``path``.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from helpers import variant

variant()

from arches_render import tomlfile  # noqa: E402
from arches_render.imaging.welch import PixelMoments, power_check, welch_compare  # noqa: E402
from arches_render.materials import textures as T, triplanar as tp, weights as W  # noqa: E402
from arches_render.materials.detail import footprint  # noqa: E402
from arches_render.materials.mipmap import MipTexture, mip_levels, position_hash  # noqa: E402
from arches_render.render.plugins import ensure_registered  # noqa: E402
from arches_render.render.renderer import build_scene, render_image, render_moments  # noqa: E402
from arches_render.scene import parse_scene  # noqa: E402

ensure_registered()
tp.register()


def _np(x):
    return np.array(x, dtype=np.float64)


def _si(p, n, t=1.0):
    p = np.asarray(p, np.float32).reshape(-1, 3)
    n = np.asarray(n, np.float64).reshape(-1, 3)
    n = (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, len(p))
    si.p = mi.Point3f(p.T)
    si.n = mi.Normal3f(n.T)
    si.sh_frame = mi.Frame3f(si.n)
    si.wi = mi.Vector3f(np.tile(np.float32([0.0, 0.0, 1.0]), (len(p), 1)).T)
    si.t = mi.Float(np.broadcast_to(np.float32(t), (len(p),)).copy())
    return si


def _bilinear_wrap(level: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Reference bilinear lookup with wrap-around, texel centres at (i + 1/2) / size."""
    h, w, _ = level.shape
    x = (uv[:, 0] - np.floor(uv[:, 0])) * w - 0.5
    y = (uv[:, 1] - np.floor(uv[:, 1])) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(int) % w, y0.astype(int) % h
    x1, y1 = (x0 + 1) % w, (y0 + 1) % h
    top = level[y0, x0] * (1 - fx) + level[y0, x1] * fx
    bottom = level[y1, x0] * (1 - fx) + level[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


# ---------------------------------------------------------------- pyramids
@pytest.mark.parametrize("shape", [(32, 16, 3), (16, 16, 1), (12, 12, 2)])
def test_mip_levels_are_the_box_filtered_means_of_the_texture(shape):
    rng = np.random.default_rng(1)
    arr = rng.uniform(0.0, 2.0, shape).astype(np.float32)
    tex = MipTexture(arr)
    h, w, c = shape
    assert tex.count == int(np.log2(min(h, w))) + 1
    for level in range(tex.count):
        k = 2 ** level
        hh, ww = h // k, w // k
        # Odd rows and columns are dropped level by level: the blocks start at the origin.
        want = arr[:hh * k, :ww * k].astype(np.float64).reshape(hh, k, ww, k, c).mean(axis=(1, 3))
        got = tex.level_array(level)
        assert got.shape == want.shape and got.dtype == np.float32
        # 1e-6: the pyramid is stored in float32 (texels in [0, 1]: ~1e-7 rounding per level).
        assert np.allclose(got, want, atol=1e-6), level
    if h == w and h & (h - 1) == 0:  # a square power of two: the last level is the mean
        assert np.allclose(tex.level_array(tex.count - 1).reshape(-1), arr.mean(axis=(0, 1)), atol=1e-6)


def test_mip_lookup_is_bilinear_with_wrap_around_on_every_level():
    rng = np.random.default_rng(2)
    arr = rng.uniform(0.0, 1.0, (16, 32, 3)).astype(np.float32)
    tex = MipTexture(arr)
    uv = rng.uniform(-40.0, 40.0, (4000, 2)).astype(np.float32)
    levels = rng.integers(0, tex.count, 4000)
    got = np.stack([_np(v) for v in tex.eval(mi.Point2f(uv.T), mi.UInt32(levels))], axis=1)
    want = np.empty_like(got)
    pyramid = mip_levels(arr)
    for lv in range(tex.count):
        sel = levels == lv
        want[sel] = _bilinear_wrap(pyramid[lv], uv[sel].astype(np.float64))
    # float32 uv wrapped to one period: about 40 * 2^-24 periods of error, times 32 texels.
    assert np.abs(got - want).max() < 2e-4


def test_level_choice_follows_the_footprint():
    tex = MipTexture(np.ones((64, 64, 1), np.float32))  # 7 levels
    f = mi.Float([0.0, 1.0, 2.0, 4.0, 8.0, 64.0, 1e9])
    assert list(_np(tex.level(f, mi.Float(0.999)))) == [0, 0, 1, 2, 3, 6, 6]
    assert list(_np(tex.level(None))) == [0]
    # 2^2.3 texels: level 2 with probability 0.7, level 3 with 0.3.
    xi = (np.arange(1000) + 0.5) / 1000
    chosen = _np(tex.level(mi.Float(np.full(1000, 2 ** 2.3, np.float32)), mi.Float(xi)))
    assert set(chosen) == {2.0, 3.0} and abs((chosen == 3).mean() - 0.3) < 2e-3


def test_stochastic_level_expectation_is_the_trilinear_value():
    """Averaged over ``xi``, one bilinear tap on a randomly chosen level is the trilinear
    (two-level) lookup, for the plain and the histogram-preserving tilings."""
    rng = np.random.default_rng(3)
    n_uv, n_xi = 64, 1000
    uv = rng.uniform(-5.0, 5.0, (n_uv, 2)).astype(np.float32)
    lam = rng.uniform(0.0, 5.0, n_uv).astype(np.float32)  # the continuous level of each point
    uv_all = mi.Point2f(np.repeat(uv, n_xi, axis=0).T)
    xi = mi.Float(np.tile((np.arange(n_xi) + 0.5) / n_xi, n_uv).astype(np.float32))
    fp_all = mi.Float(np.repeat(np.exp2(lam), n_xi))
    lo = np.floor(lam)
    frac = (lam - lo)[:, None]
    for tiling in ("repeat", "histogram"):
        tex = T.load_texture("rock_gravel.png", tiling=tiling)
        mean = _np(tex.eval(uv_all, fp_all, True, xi)).T.reshape(n_uv, n_xi, 3).mean(axis=1)
        # The two levels around lam, each at its exact footprint 2^l (no choice left).
        v_lo = _np(tex.eval(mi.Point2f(uv.T), mi.Float(np.exp2(lo)), True, mi.Float(0.5))).T
        v_hi = _np(tex.eval(mi.Point2f(uv.T), mi.Float(np.exp2(lo + 1)), True, mi.Float(0.5))).T
        trilinear = (1 - frac) * v_lo + frac * v_hi
        # The xi grid rounds the probability to 1/n_xi.
        tol = 1.5 / n_xi * np.abs(v_hi - v_lo).max() + 1e-5
        assert np.abs(mean - trilinear).max() < tol, tiling
        assert np.abs(v_hi - v_lo).max() > 0.05  # the levels differ: the test can fail


def test_position_hash_is_uniform_and_deterministic():
    rng = np.random.default_rng(4)
    p = mi.Point3f(rng.uniform(-1000.0, 1000.0, (3, 200_000)).astype(np.float32))
    xi = _np(position_hash(p))
    assert xi.min() >= 0.0 and xi.max() < 1.0
    counts = np.histogram(xi, bins=20, range=(0, 1))[0] / xi.size
    assert np.abs(counts - 0.05).max() < 0.003  # ~7 sigma of a bin of 10^4 draws
    # Neighbouring points (a ulp apart) decorrelate; the same point gives the same number.
    q = rng.uniform(-10.0, 10.0, (3, 50_000)).astype(np.float32)
    a = _np(position_hash(mi.Point3f(q)))
    b = _np(position_hash(mi.Point3f(np.nextafter(q, np.float32(np.inf)))))
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.02
    assert np.array_equal(a, _np(position_hash(mi.Point3f(q))))


# --------------------------------------------------------------- projections
def _normals(rng, count):
    n = rng.normal(size=(count, 3))
    # Axis-aligned and near-axis normals (flat ground, plain cliffs), where slots drop.
    n[: count // 4] = [0.0, 0.0, 1.0]
    n[count // 4: count // 2, :2] *= 0.05
    n[count // 2: 5 * count // 8, 1:] *= 0.1
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_projection_slots_rank_weights_and_keep_each_axis_uv():
    rng = np.random.default_rng(5)
    n, p = _normals(rng, 4000), rng.uniform(-50, 50, (4000, 3))
    b = W.triplanar_weights(mi.Vector3f(n.T.astype(np.float32)), 8.0)
    slots = W.projection_slots(mi.Point3f(p.T.astype(np.float32)), b)
    bw = _np(b).T
    ws = np.stack([_np(s[1]) for s in slots], axis=1)
    assert np.all(ws[:, 0] >= ws[:, 1]) and np.all(ws[:, 1] >= ws[:, 2])
    assert np.allclose(np.sort(ws, axis=1), np.sort(bw, axis=1))
    # Each slot's uv is its axis's: uv_x = (y, z), uv_y = (x, z), uv_z = (x, y).
    axis_uv = [p[:, [1, 2]], p[:, [0, 2]], p[:, [0, 1]]]
    for k, (uv, w) in enumerate(slots):
        uv = _np(uv).T
        axis = np.array([np.flatnonzero(bw[i] == ws[i, k])[0] for i in range(len(p))])
        want = np.stack([axis_uv[a][i] for i, a in enumerate(axis)])
        # Tied weights: either tied axis may take the slot, but the axes stay distinct.
        tied = (bw == ws[:, k:k + 1]).sum(axis=1) > 1
        # 1e-4: positions up to ~100 m pass through float32 (ulp ~8e-6); the test is which axis, not rounding.
        assert np.allclose(uv[~tied], want[~tied], atol=1e-4)


def test_blend_with_dropped_slots_stays_within_its_bound_of_the_full_blend():
    rng = np.random.default_rng(6)
    count = 20_000
    n, p = _normals(rng, count), rng.uniform(-30, 30, (count, 3))
    R = 3.0  # the lookup's range [0, R]

    def lookup_np(uv):
        return R * (0.5 + 0.5 * np.sin(np.stack([3 * uv[:, 0] + 2 * uv[:, 1], uv[:, 0] - 5 * uv[:, 1],
                                                 7 * uv[:, 0]], axis=1)))

    def lookup(uv, active):
        return mi.Color3f(*(R * (0.5 + 0.5 * dr.sin(v)) for v in
                            (3 * uv.x + 2 * uv.y, uv.x - 5 * uv.y, 7 * uv.x)))

    b = W.triplanar_weights(mi.Vector3f(n.T.astype(np.float32)), 8.0)
    got = _np(W.blend_projections(lookup, W.projection_slots(mi.Point3f(p.T.astype(np.float32)), b))).T
    bw = _np(b).T
    pf = p.astype(np.float32).astype(np.float64)
    T_k = [lookup_np(pf[:, [1, 2]]), lookup_np(pf[:, [0, 2]]), lookup_np(pf[:, [0, 1]])]
    full = sum(bw[:, k:k + 1] * T_k[k] for k in range(3))
    kept = bw >= W.MIN_PROJECTION
    assert (~kept).sum(axis=1).max() == 2 and (~kept).any(axis=1).mean() > 0.3  # slots do drop
    # The blend is the kept projections renormalised (slot 0 always kept) ...
    wk = np.where(kept, bw, 0.0)
    renorm = sum(wk[:, k:k + 1] * T_k[k] for k in range(3)) / wk.sum(axis=1, keepdims=True)
    assert np.abs(got - renorm).max() < 2e-5 * R
    # ... within 2 MIN_PROJECTION of the range of the three-projection blend.
    err = np.abs(got - full).max()
    assert err <= 2 * W.MIN_PROJECTION * R + 2e-5 * R, err


# --------------------------------------------------------------- layer skip
def test_skipping_zero_weight_layers_matches_evaluating_every_layer():
    """Points sorted by height, so whole packets lie outside the upper layers' bands
    (skipped) and some packets straddle a band's edge (mixed); shuffled, every packet
    is mixed. Both give what each layer evaluated on every lane gives."""
    layers = [tp.Layer(texture="rock_gravel.png", tint=(0.6, 0.5, 0.4), scale=2.0),
              tp.Layer(texture="sand.png", tint=(0.8, 0.7, 0.5), scale=1.5, tiling="repeat",
                       height_min=10.0, height_max=20.0, height_soft=2.0),
              tp.Layer(texture="rock_gravel.png", tint=(0.3, 0.35, 0.3), scale=0.7,
                       height_min=25.0, height_soft=1.0),
              tp.Layer(tint=(0.9, 0.9, 0.9), slope_max=10.0, slope_soft=5.0, height_max=5.0)]
    bsdf = mi.load_dict(tp.triplanar_dict(layers, pixel_spread=2e-3))
    rng = np.random.default_rng(7)
    count = 4096
    z = np.sort(rng.uniform(0.0, 30.0, count))
    p = np.stack([rng.uniform(-40, 40, count), rng.uniform(-40, 40, count), z], axis=1)
    n = _normals(rng, count)
    t = rng.uniform(1.0, 300.0, count)  # footprints over several MIP levels
    for order in (np.arange(count), rng.permutation(count)):
        si = _si(p[order], n[order], t[order])
        albedo, ca, cb, _ = bsdf.shade(si, True, False)
        w = bsdf.layer_weights(si)
        wn = np.stack([_np(x) for x in w])
        assert (wn[1] == 0).mean() > 0.3 and (wn[1] > 0).mean() > 0.2  # a layer skipped and not
        P = mi.Point3f(si.p)
        slots = W.projection_slots(P, W.triplanar_weights(mi.Vector3f(si.sh_frame.n), bsdf.sharpness))
        fp, xi = footprint(si, bsdf.pixel_spread), position_hash(P)
        want = mi.Color3f(0.0)
        for i in range(len(layers)):
            want += dr.clip(bsdf.tint[i] * bsdf._texel(i, slots, fp, xi), 0.0, 1.0) * w[i]
        # 1e-6: float32 sums of the same terms, in another order inside the branches.
        assert np.allclose(_np(albedo), _np(want), atol=1e-6)
        # Roughness 0: Lambert, so the Oren-Nayar terms are the albedo and zero.
        assert np.allclose(_np(ca), _np(want), atol=1e-6) and np.abs(_np(cb)).max() == 0.0


# ---------------------------------------------------------------- mesh mode
MESH_SCENE = """
[render]
resolution = [24, 16]
spp = 2
geometry = "mesh"

[camera]
origin = [0.0, -30.0, 12.0]
target = [0.0, 0.0, 2.0]
fov = 40.0

[[lights]]
type = "directional"
direction = [0.3, 1.0, -0.6]

[materials.ground]
type = "{kind}"
{extra}

[field]
root = { type = "sphere", center = [0.0, 0.0, 2.0], radius = 6.0 }
material = "ground"
"""


@pytest.mark.parametrize("kind", ["triplanar", "diffuse"])
def test_mesh_mode_shades_the_look_with_implicit_path(kind, tmp_path):
    extra = 'preset = "terrain"' if kind == "triplanar" else "color = [0.5, 0.5, 0.5]"
    text = MESH_SCENE.replace("{kind}", kind).replace("{extra}", extra)
    path = tmp_path / "s.toml"
    path.write_text(text)
    desc = parse_scene(tomlfile.loads(text), path)
    scene = build_scene(desc, "mesh", voxel=1.0)
    integrator = scene.integrator()
    if kind == "triplanar":
        assert "ImplicitPathIntegrator" in str(integrator) and integrator.tracer is None
        assert hasattr(integrator.shaded_bsdf, "shade") and integrator.shades_once
    else:  # nothing to shade once: Mitsuba's path, as before
        assert "ImplicitPathIntegrator" not in str(integrator) and not hasattr(integrator, "attach_material")


def _triplanar_mesh_scene(integrator, bsdf, width=48, height=36):
    return mi.load_dict({
        "type": "scene", "integrator": integrator,
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, -5, 2], target=[0, 0, 0.4], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 0.4}},
        "sun": {"type": "directional", "direction": [-0.3, 0.5, -0.8], "irradiance": {"type": "rgb", "value": 3.0}},
        "ground": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(4), "bsdf": bsdf},
        "ball": {"type": "sphere", "center": [0, 0, 0.5], "radius": 0.5, "bsdf": bsdf},
    })


def test_shading_once_on_a_triplanar_mesh_matches_stock_path():
    """``implicit_path`` with the material attached (one ``shade`` per vertex, slots
    and layers skipped per packet) converges to the image of Mitsuba's ``path``
    (``shade`` at every query). No footprint (no pixel spread, no cones): both look
    up full detail, so the expected images are the same."""
    layers = [tp.Layer(texture="rock_gravel.png", tint=(0.6, 0.5, 0.4), roughness=0.6, scale=0.8),
              tp.Layer(texture="sand.png", tint=(0.8, 0.7, 0.5), roughness=0.3, scale=0.5,
                       slope_max=20.0, slope_soft=5.0)]
    bsdf = mi.load_dict(tp.triplanar_dict(layers, detail_octaves=3, detail_wavelength=0.5))
    ref = PixelMoments.from_batches([render_image(_triplanar_mesh_scene({"type": "path", "max_depth": 6}, bsdf),
                                                  32, seed=s) for s in range(1, 9)], 32)
    scene = _triplanar_mesh_scene({"type": "implicit_path", "max_depth": 6, "aovs": True, "moments": True,
                                   "lod": False}, bsdf)
    scene.integrator().attach_material(bsdf)
    ours = render_moments(scene, 128, seed=20)
    res = welch_compare(ref, ours, geometry=False)
    assert res.passed, res.summary() + "\n" + "\n".join(res.failures)
    assert power_check(ref, ours) == [], "too few samples to tell a 1 % shift or a 25 % patch"


def test_the_look_parts_benchmark_turns_off_what_it_names(monkeypatch):
    """``lookdev_parts_default``'s variants of the default scene each lose exactly their part."""
    from helpers import REPO
    monkeypatch.syspath_prepend(str(REPO / "benchmarks"))
    import bench_lookdev as B
    doc = tomlfile.load(B.DEFAULT)
    material = doc["field"]["material"]
    descs = {name: B.parse_plain(d, B.DEFAULT) for name, d in B.look_variants(doc, material).items()}
    look = descs["look"]
    props = {name: d.materials[material] for name, d in descs.items()}
    assert look.atmosphere is not None and descs["no_atmosphere"].atmosphere is None
    assert props["look"]["type"] == "triplanar" and props["plain"]["type"] == "diffuse"
    tilings = {name: {v for k, v in p.items() if k.endswith("_tiling")} for name, p in props.items()}
    assert "histogram" in tilings["look"] and tilings["repeat_tiling"] == {"repeat"}, tilings
    assert props["look"]["detail_octaves"] > 0 and props["no_detail"]["detail_octaves"] == 0
    changed = {name: sorted(k for k in set(p) | set(props["look"]) if p.get(k) != props["look"].get(k))
               for name, p in props.items() if name not in ("look", "plain")}
    assert changed["no_atmosphere"] == [] and all(changed[n] for n in ("repeat_tiling", "no_detail", "no_strata",
                                                                          "no_cavity")), changed
    assert not any("strata" in k for k in changed["no_cavity"] + changed["no_detail"]), changed
