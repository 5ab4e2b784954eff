"""Tests of the ``triplanar`` BSDF, its presets and bundled textures."""

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from scipy import ndimage

from arches_render import backend

try:
    backend.set_variant()
except ImportError:  # the lead's integrator is not importable yet
    pass
from arches_render.materials import presets, triplanar as tp, weights as tw  # noqa: E402

tp.register()

CTX = mi.BSDFContext()


def _si(p, n, wi=(0.0, 0.0, 1.0)):
    """A hand-built interaction (no shape), as the implicit-field tracer makes them."""
    p = np.asarray(p, np.float32).reshape(-1, 3)
    n = np.asarray(n, np.float64).reshape(-1, 3)
    n = (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, len(p))
    si.p = mi.Point3f(p.T)
    si.n = mi.Normal3f(n.T)
    si.sh_frame = mi.Frame3f(si.n)
    si.wi = mi.Vector3f(np.tile(np.asarray(wi, np.float32), (len(p), 1)).T)
    si.t = mi.Float(1.0)
    return si


def _bsdf(layers, **kw):
    return mi.load_dict(tp.triplanar_dict(layers, **kw))


def _np(x):
    return np.array(x, dtype=np.float64)


def _sphere_scene(bsdf, **shape):
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, -6, 0], target=[0, 0, 0],
                                                              up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": 32, "height": 32,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 8}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
        "sphere": {"type": "sphere", "radius": 1.0, "bsdf": bsdf, **shape},
    })


# ----------------------------------------------------------------- weights
def test_projection_weights_sum_to_one_and_favour_dominant_axis():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(1000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    b = _np(tw.triplanar_weights(mi.Vector3f(n.T.astype(np.float32)), 8.0)).T
    assert np.allclose(b.sum(1), 1.0, atol=1e-5)
    assert (b.argmax(1) == np.abs(n).argmax(1)).all()
    expected = np.abs(n) ** 8 / (np.abs(n) ** 8).sum(1, keepdims=True)
    assert np.allclose(b, expected, atol=1e-5)
    assert np.allclose(_np(tw.triplanar_weights(mi.Vector3f(0, 0, -1), 8.0)).ravel(), [0, 0, 1])


def test_composite_weights_follow_paint_formula():
    c = [0.0, 0.3, 0.6, 0.25]
    w = [float(x[0]) for x in tw.composite_weights([mi.Float(x) for x in c])]
    c[0] = 1.0
    expected = [c[i] * np.prod([1 - c[j] for j in range(i + 1, 4)]) for i in range(4)]
    assert np.allclose(w, expected, atol=1e-6) and abs(sum(w) - 1) < 1e-6
    # The same through the plugin's coverage properties.
    b = _bsdf([tp.Layer(), tp.Layer(coverage=0.3), tp.Layer(coverage=0.6), tp.Layer(coverage=0.25)])
    w = [float(x[0]) for x in b.layer_weights(_si([0, 0, 0], [0, 0, 1]))]
    assert np.allclose(w, expected, atol=1e-6)


def test_height_and_slope_rules_select_layers():
    b = mi.load_dict(presets.preset_dict("terrain"))
    names = ["rock", "sand", "grass", "snow"]
    def tilt(deg):
        return [math.sin(math.radians(deg)), 0.0, math.cos(math.radians(deg))]
    cases = [([10, 20, 2], tilt(3), "sand"), ([50, 80, 25], tilt(10), "grass"),
             ([90, 10, 55], tilt(5), "snow"), ([0, 0, 25], tilt(80), "rock"),
             ([0, 0, 55], tilt(70), "rock"), ([5, 5, 30], tilt(45), "rock")]
    si = _si([c[0] for c in cases], [c[1] for c in cases])
    w = _np(b.layer_weights(si))
    assert np.allclose(w.sum(0), 1.0, atol=1e-5)
    for k, (_, _, want) in enumerate(cases):
        assert names[w[:, k].argmax()] == want and w[:, k].max() > 0.95, (k, w[:, k])
    # Inside a soft ramp the coverage follows the smoothstep: snow starts at
    # 45 m with 6 m softness, so z = 42 m is half-way up the ramp.
    w = _np(b.layer_weights(_si([0, 0, 42], [0, 0, 1])))
    assert abs(w[3, 0] - 0.5) < 1e-4


def test_layer_mask_from_a_field_node():
    class XNode:  # the field-node protocol: eval(p) -> Float
        def eval(self, p):
            return p.x
    b = _bsdf([tp.Layer(tint=(0.2, 0.2, 0.2)), tp.Layer(tint=(0.8, 0.8, 0.8))])
    b.set_layer_mask(1, XNode(), -1.0, 1.0)
    si = _si([[-3, 0, 0], [0, 0, 0], [0.5, 0, 0], [3, 0, 0]], [[0, 0, 1]] * 4)
    w1 = _np(b.layer_weights(si))[1]
    t = 0.75
    assert np.allclose(w1, [0, 0.5, t * t * (3 - 2 * t), 1], atol=1e-5)
    assert np.allclose(_np(b.albedo(si))[0], 0.2 + 0.6 * w1, atol=1e-5)
    assert "layer1_mask_lo" in mi.traverse(b)
    b.set_layer_mask(1, None)
    assert np.allclose(_np(b.layer_weights(si))[1], 1.0)


# ------------------------------------------------------------ reflectance
def _directions(count, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(count, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return mi.Vector3f(v.T.astype(np.float32))


def test_sample_weight_is_eval_over_pdf():
    b = _bsdf([tp.Layer(texture="rock_gravel.png", tint=(0.6, 0.5, 0.4), roughness=0.7, scale=0.7),
               tp.Layer(tint=(0.9, 0.9, 0.9), roughness=0.2, slope_max=30, slope_soft=10)])
    count = 4096
    rng = np.random.default_rng(3)
    si = _si(rng.uniform(-5, 5, (count, 3)), rng.normal(size=(count, 3)))
    si.wi = _directions(count, 4)
    s = rng.random((3, count)).astype(np.float32)
    bs, weight = b.sample(CTX, si, mi.Float(s[0]), mi.Point2f(s[1], s[2]))
    value, pdf = b.eval_pdf(CTX, si, bs.wo)
    above = _np(si.wi.z) > 0
    w, v, p = _np(weight), _np(value), _np(pdf)
    assert np.allclose(p, _np(bs.pdf), rtol=1e-5)
    assert np.allclose(v, _np(b.eval(CTX, si, bs.wo)), rtol=1e-5, atol=1e-7)
    assert np.allclose(p, _np(b.pdf(CTX, si, bs.wo)), rtol=1e-5)
    ok = above & (p > 1e-3)
    assert ok.sum() > count // 3
    assert np.allclose(w[:, ok], v[:, ok] / p[ok], rtol=1e-4, atol=1e-6)
    # One-sided: nothing from below, nothing into the lower hemisphere.
    assert (w[:, ~above] == 0).all() and (p[~above] == 0).all()
    down = mi.Vector3f(0.3, 0.1, -0.9)
    assert (_np(b.eval(CTX, si, down)) == 0).all() and (_np(b.pdf(CTX, si, down)) == 0).all()
    assert int(b.flags()) == int(mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide)


@pytest.mark.parametrize("sigma", [0.1, 0.3, 0.6, 1.0])
def test_oren_nayar_energy_stays_below_albedo(sigma):
    b = _bsdf([tp.Layer(tint=(1, 1, 1), roughness=sigma)])
    grid = 400  # stratified midpoints: a deterministic quadrature of the hemisphere
    u = (np.arange(grid) + 0.5) / grid
    uu, vv = (a.ravel().astype(np.float32) for a in np.meshgrid(u, u))
    for theta in (0.0, 45.0, 80.0, 89.5):
        si = _si(np.zeros((uu.size, 3)), [[0, 0, 1]] * uu.size,
                 wi=(math.sin(math.radians(theta)), 0.0, math.cos(math.radians(theta))))
        _, w = b.sample(CTX, si, mi.Float(0.5), mi.Point2f(uu, vv))
        energy = float(dr.mean(w.x)[0])
        assert energy <= 1.0 + 1e-3, (sigma, theta, energy)
        assert energy > 0.55
    # Lambert (sigma 0) conserves exactly: weight == albedo for every sample.
    lam = _bsdf([tp.Layer(tint=(0.7, 0.7, 0.7))])
    _, w = lam.sample(CTX, _si([0, 0, 0], [0, 0, 1], wi=(0.6, 0, 0.8)), mi.Float(0.5),
                      mi.Point2f(0.3, 0.9))
    assert np.allclose(_np(w), 0.7, atol=1e-6)


def test_white_furnace_lambert_in_stock_path():
    t = (0.8, 0.5, 0.2)
    img = _np(mi.render(_sphere_scene(tp.triplanar_dict([tp.Layer(tint=t)])), spp=16))
    hit = np.abs(img - 1.0).max(2) > 1e-3
    # Silhouette pixels mix sphere and background: keep fully covered ones.
    inside = ndimage.binary_erosion(hit, iterations=1)
    assert inside.sum() > 150
    assert np.allclose(img[inside].mean(0), t, atol=0.01)
    assert np.allclose(img[~hit], 1.0, atol=1e-4)


# --------------------------------------------------------------- dispatch
def test_bsdfptr_dispatch_matches_direct_calls():
    tri = _bsdf([tp.Layer(texture="grass.png", tint=(0.3, 0.5, 0.2), roughness=0.5, scale=0.5),
                 tp.Layer(tint=(0.9, 0.9, 0.9), height_min=0.0, height_soft=0.5)], space="object")
    other = mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.1}})
    count = 256
    rng = np.random.default_rng(5)
    si = _si(rng.uniform(-2, 2, (count, 3)), rng.normal(size=(count, 3)) + [0, 0, 1.5],
             wi=(0.0, 0.0, 1.0))  # shape is null: object space falls back to world p
    mask = mi.Bool(rng.random(count) < 0.5)
    ptr = dr.select(mask, mi.BSDFPtr(tri), mi.BSDFPtr(other))
    wo = mi.Vector3f(0.36, 0.48, 0.8)
    m = _np(mask).astype(bool)
    via_ptr = _np(ptr.eval(CTX, si, wo))
    assert np.allclose(via_ptr[:, m], _np(tri.eval(CTX, si, wo))[:, m], rtol=1e-5, atol=1e-7)
    assert np.allclose(via_ptr[:, ~m], _np(other.eval(CTX, si, wo))[:, ~m], rtol=1e-5)
    s1, s2 = mi.Float(0.5), mi.Point2f(0.2, 0.7)
    bs_p, w_p = ptr.sample(CTX, si, s1, s2)
    bs_d, w_d = tri.sample(CTX, si, s1, s2)
    assert np.allclose(_np(w_p)[:, m], _np(w_d)[:, m], rtol=1e-5, atol=1e-7)
    assert np.allclose(_np(bs_p.pdf)[m], _np(bs_d.pdf)[m], rtol=1e-5)
    alb = _np(ptr.eval_diffuse_reflectance(si))
    assert np.allclose(alb[:, m], _np(tri.albedo(si))[:, m], rtol=1e-5)
    world = _bsdf([tp.Layer(texture="grass.png", tint=(0.3, 0.5, 0.2), roughness=0.5, scale=0.5),
                   tp.Layer(tint=(0.9, 0.9, 0.9), height_min=0.0, height_soft=0.5)])
    assert np.allclose(alb[:, m], _np(world.albedo(si))[:, m], rtol=1e-5)
    # Inside a recorded loop (as in a Python integrator).
    i, acc = mi.UInt32(0), mi.Color3f(0.0)
    def body(i, acc):
        return i + 1, acc + ptr.eval(CTX, si, wo)
    i, acc = dr.while_loop((i, acc), lambda i, acc: i < 3, body)
    assert np.allclose(_np(acc), 3 * via_ptr, rtol=1e-5, atol=1e-7)


def _objp_mesh(name, offset):
    """A textured-looking sphere mesh whose ``vertex_objp`` ignores ``offset``."""
    rows, cols = 24, 48
    th = np.linspace(0, np.pi, rows + 1)
    ph = np.linspace(0, 2 * np.pi, cols + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    v = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    faces = []
    for r in range(rows):
        for c in range(cols):
            a, b = r * (cols + 1) + c, r * (cols + 1) + c + 1
            d, e = a + cols + 1, b + cols + 1
            faces += [[a, d, b], [b, d, e]]
    faces = np.array(faces, np.uint32)
    m = mi.Mesh(name, len(v), len(faces), has_vertex_normals=True)
    params = mi.traverse(m)
    params["vertex_positions"] = mi.Float((v + offset).astype(np.float32).ravel())
    params["vertex_normals"] = mi.Float(v.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(faces.ravel())
    params.update()
    m.add_attribute(tp.OBJP_ATTRIBUTE, 3, mi.Float(v.astype(np.float32).ravel()))
    return m


@pytest.mark.parametrize("space", ["object", "world"])
def test_object_space_texture_follows_translated_mesh(space):
    layers = [tp.Layer(texture="rock_gravel.png", tint=(0.8, 0.8, 0.8), scale=0.4)]
    offset = np.array([7.3, -2.1, 0.4])
    albedos = []
    for k, off in enumerate((np.zeros(3), offset)):
        mesh = _objp_mesh(f"m{k}", off)
        # An analytic sphere has no vertex_objp: object space falls back to world p there.
        scene = mi.load_dict({"type": "scene", "mesh": mesh,
                              "ball": {"type": "sphere", "center": [0, 0, 30], "radius": 1.0}})
        bsdf = _bsdf(layers, space=space)
        count = 400
        rng = np.random.default_rng(7)
        d = rng.normal(size=(count, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = off + 3 * d
        ray = mi.Ray3f(mi.Point3f(o.T.astype(np.float32)), mi.Vector3f((-d).T.astype(np.float32)))
        si = scene.ray_intersect(ray)
        assert dr.all(si.is_valid())
        albedos.append(_np(bsdf.albedo(si)))
    diff = np.abs(albedos[0] - albedos[1]).max()
    if space == "object":
        assert diff < 2e-3
    else:
        assert diff > 0.05
    down = mi.Ray3f(mi.Point3f([0.3, -0.2, 0.1], [0.1, 0.4, -0.3], 40.0), mi.Vector3f(0, 0, -1))
    si = scene.ray_intersect(down)
    assert dr.all(si.is_valid()) and dr.all(si.p.z > 29)
    world = _np(_bsdf(layers).albedo(si))
    assert np.allclose(_np(bsdf.albedo(si)), world, atol=1e-6)


def test_object_space_in_stock_path_render():
    # The vertex_objp lookup runs inside the path integrator's BSDF call.
    offset = [5.0, 1.0, -2.0]
    images = []
    for k, off in enumerate(([0.0, 0.0, 0.0], offset)):
        mesh = _objp_mesh(f"r{k}", np.array(off))
        mesh.set_bsdf(_bsdf([tp.Layer(texture="rock_gravel.png", tint=(0.7, 0.6, 0.5), scale=0.5)],
                            space="object"))
        scene = mi.load_dict({
            "type": "scene", "integrator": {"type": "path", "max_depth": 3},
            "sensor": {"type": "perspective", "fov": 30,
                       "to_world": mi.ScalarTransform4f().look_at(
                           origin=list(np.add([0, -6, 0], off)), target=off, up=[0, 0, 1]),
                       "film": {"type": "hdrfilm", "width": 32, "height": 32,
                                "rfilter": {"type": "box"}},
                       "sampler": {"type": "independent", "sample_count": 4}},
            "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
            "mesh": mesh})
        assert "TriplanarBSDF" in str(scene.shapes()[0].bsdf())
        images.append(_np(mi.render(scene, spp=4, seed=3)))
    assert np.abs(images[0] - images[1]).mean() < 0.02


# ------------------------------------------------------------- parameters
def test_traverse_edit_changes_render_without_new_kernel():
    scene = _sphere_scene(tp.triplanar_dict([
        tp.Layer(texture="rock_gravel.png", tint=(0.5, 0.5, 0.5), roughness=0.4, scale=0.3),
        tp.Layer(tint=(0.9, 0.9, 0.9), height_min=0.3, height_soft=0.2)]))
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("layer0_tint"))
    rough = next(k for k in params.keys() if k.endswith("layer0_roughness"))
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        before = _np(mi.render(scene, spp=2, seed=1))
        first = {h["hash"] for h in dr.kernel_history() if h["type"] == dr.KernelType.JIT}
        params[key] = mi.Color3f(0.25, 0.1, 0.05)
        params[rough] = 0.8
        params.update()
        dr.kernel_history_clear()
        after = _np(mi.render(scene, spp=2, seed=1))
        second = {h["hash"] for h in dr.kernel_history() if h["type"] == dr.KernelType.JIT}
    assert second and second <= first, "editing a traversed parameter compiled a new kernel"
    assert np.abs(after - before).mean() > 0.02
    # Where the rock shows, red dropped much less than blue: the new tint
    # really reached the render.
    rock = np.abs(after - before).mean(2) > 0.05
    assert rock.sum() > 50
    assert after[rock][:, 0].mean() > 2.0 * after[rock][:, 2].mean()


def test_textures_are_cached_and_decoded():
    from arches_render.materials import textures
    a = textures.load_texture("sand.png", True, True)
    assert textures.load_texture("sand.png", True, True) is a
    assert textures.load_texture("sand.png", True, True, "repeat") is not a
    with pytest.raises(ValueError, match="bundled textures"):
        tp.texture_path("no_such_texture.png")


# ---------------------------------------------------------------- presets
def test_presets_load_and_validate():
    names = presets.list_presets()
    assert {"terrain", "sandstone", "basalt", "limestone"} <= set(names)
    for name in names:
        b = mi.load_dict(presets.preset_dict(name))
        assert isinstance(b, mi.BSDF)
    layers, options = presets.preset_layers("terrain", {"snow.height_min": 40.0,
                                                        "grass": {"scale": 2.5},
                                                        "sharpness": 4})
    assert layers[3].height_min == 40.0 and layers[2].scale == 2.5 and options["sharpness"] == 4.0
    with pytest.raises(ValueError, match="marble.*terrain"):
        presets.preset_layers("marble")
    with pytest.raises(ValueError, match="'snow.colour'.*tint"):
        presets.preset_dict("terrain", {"snow.colour": [1, 1, 1]})
    with pytest.raises(ValueError, match="'ice.tint'.*snow"):
        presets.preset_dict("terrain", {"ice.tint": [1, 1, 1]})
    with pytest.raises(ValueError, match="roughness"):
        presets.preset_dict("basalt", {"rock.roughness": 2.0})
    with pytest.raises(ValueError, match="space"):
        presets.preset_dict("basalt", {"space": "camera"})


def test_plugin_rejects_unknown_properties():
    d = tp.triplanar_dict([tp.Layer()])
    d["layer0_colour"] = [1, 0, 0]
    with pytest.raises(Exception, match="layer0_colour"):
        mi.load_dict(d)


def test_bundled_textures_are_small_tileable_and_licensed():
    folder = tp.TEXTURE_DIR
    pngs = sorted(folder.glob("*.png"))
    licence = (folder / "LICENSE.md").read_text()
    assert len(pngs) >= 3 and sum(p.stat().st_size for p in pngs) < 1_500_000
    for png in pngs:
        assert png.name in licence and png.stat().st_size < 300_000
        img = np.array(mi.Bitmap(str(png)), dtype=np.float64)
        assert max(img.shape[:2]) <= 512
        img = img.reshape(img.shape[0], img.shape[1], -1).mean(2)
        inner = np.abs(np.diff(img, axis=1)).mean()
        seam = np.abs(img[:, 0] - img[:, -1]).mean()
        assert seam < 1.5 * inner, png.name
