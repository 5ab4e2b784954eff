"""Footprint level of detail (arches_render.field.lod): the footprint field's bounds
hold numerically, full detail is bitwise the plain field, skipped octaves cost
nothing; a footprint changes octave sums and nothing else, a cone-traced ray hits
the footprint surface rather than the full-detail one, and images with level of
detail take fewer tracer steps and agree with full detail within noise."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import SCENES, random_points, variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render import field as F  # noqa: E402
from arches_render.field.lod import Footprint, lod_lipschitz  # noqa: E402
from arches_render.field.noise import fbm  # noqa: E402
from arches_render.render.sphere_tracer import SphereTracer  # noqa: E402
from arches_render.generators.terrain.skeletal_set import SkeletalSet  # noqa: E402

#: The cone every test point sees: apex O, radius R0 + S |q - O|.
O = np.array([-9.0, -7.0, 4.0])
R0, S = 0.01, 0.02


def _skeletal():
    rng = np.random.default_rng(4)
    a = rng.uniform(-3, 3, (40, 3))
    return SkeletalSet(a, a + rng.normal(0, 0.8, a.shape), rng.uniform(0.6, 1.4, 40), 1.0, 0.2,
                       noise=dict(amplitude=0.25, wavelength=0.6, octaves=5), threshold=0.3)


def make_nodes():
    cap = F.Capsule([-1, 0, 0], [1, 0.5, 0.3], 0.9)
    disp = F.Displace(cap, amplitude=0.3, wavelength=1.5, octaves=7, seed=5)
    x = np.linspace(0, 1, 33)
    X, Y = np.meshgrid(x, x)
    hf = F.Heightfield(2.0 * np.sin(6 * X) * np.cos(4 * Y), (-4, -4, 4, 4))
    return {
        "noise": F.Noise(0.4, 1.2, octaves=6, seed=9),
        "displace": disp,
        "warp": F.DomainWarp(F.Box([0, 0, 0], [1.0, 0.5, 0.8]), amplitude=0.2, wavelength=1.0, octaves=5, seed=2),
        "rotate": F.Transform.rotate(disp, [1, 1, 0], 37.0),
        "scale": F.Transform.scale(disp, [2.0, 0.5, 1.0]),
        "blend": F.Blend(hf, disp, radius=0.8),
        "skeletal": _skeletal(),
    }


NODES = make_nodes()


def _points(arr):
    arr = np.asarray(arr, dtype=np.float32)
    return mi.Point3f(*(mi.Float(arr[:, i]) for i in range(3)))


def _footprint(pts):
    """The cone's footprint at each point (a function of position, rate S)."""
    r = R0 + S * np.linalg.norm(np.asarray(pts, float) - O, axis=1)
    return Footprint(mi.Float(r.astype(np.float32)), mi.Float(np.full(len(r), S, np.float32)))


def footprint_field(node, pts):
    """``F(q) = f_fp(q)(q)``: the footprint field at numpy points."""
    f = node.eval_bounds(_points(pts), (), footprint=_footprint(pts))[0]
    dr.eval(f)
    return f.numpy().astype(np.float64)


def test_full_detail_is_bitwise_the_plain_field():
    pts = random_points(20_000, -4, 4, seed=1)
    p = _points(pts)
    for name, node in NODES.items():
        zero = Footprint(mi.Float(np.zeros(len(pts), np.float32)), mi.Float(np.zeros(len(pts), np.float32)))
        a, b = node.eval_bounds(p, (), footprint=zero)[0], node.eval(p)
        dr.eval(a, b)
        assert np.array_equal(a.numpy(), b.numpy()), name
    q = p * 0.37
    full = fbm(q, 6, 2.0, 0.5, mi.UInt32(3))
    lvl = fbm(q, 6, 2.0, 0.5, mi.UInt32(3), level=mi.Float(6.0))
    dr.eval(full, lvl)
    assert np.array_equal(full.numpy(), lvl.numpy())


def test_skipped_octaves_contribute_nothing():
    """At a footprint that keeps octaves 0-3, seven octaves equal four, bitwise: the
    finer ones are not evaluated (a symbolic branch skips them)."""
    cap = F.Capsule([-1, 0, 0], [1, 0.5, 0.3], 0.9)
    seven = F.Displace(cap, amplitude=0.3, wavelength=1.5, octaves=7, seed=5)
    four = F.Displace(cap, amplitude=0.3, wavelength=1.5, octaves=4, seed=5)
    pts = random_points(20_000, -3, 3, seed=2)
    # x(fp) = log2(lambda / (2 fp)) in [3.2, 3.9]: octave 3 fades, 4 and beyond are off.
    r = 1.5 / 2.0 / 2.0 ** np.random.default_rng(3).uniform(3.2, 3.9, len(pts))
    fp = Footprint(mi.Float(r.astype(np.float32)), mi.Float(np.full(len(r), 0.01, np.float32)))
    a, b = (n.eval_bounds(_points(pts), (), footprint=fp)[0] for n in (seven, four))
    dr.eval(a, b)
    assert np.array_equal(a.numpy(), b.numpy())
    assert not np.array_equal(a.numpy(), F.evaluate(seven, pts))


#: Nodes without an octave sum: a footprint must not change them.
PLAIN = {
    "capsule": F.Capsule([-1, 0, 0], [1, 0.5, 0.3], 0.9),
    "box": F.Box([0, 0, 0], [1.0, 0.5, 0.8]),
    "heightfield": NODES["blend"].children[0],
    "rotate": F.Transform.rotate(F.Capsule([-1, 0, 0], [1, 0.5, 0.3], 0.9), [1, 1, 0], 37.0),
    "blend": F.Blend(NODES["blend"].children[0], F.Box([0, 0, 0], [1.0, 0.5, 0.8]), radius=0.8),
}


def test_footprints_truncate_octave_sums_and_nothing_else():
    """At a footprint of 0.3 m (octaves finer than about 0.6 m skipped) every node with an octave
    sum changes at a good share of random points (measured: 34 % for the blend of a plain
    heightfield and a displacement, which only the displaced side feels, 58 % for the skeletal set,
    100 % for the others); nodes without one do not change at all (bitwise)."""
    pts = random_points(20_000, -4, 4, seed=1)
    p = _points(pts)
    fp = Footprint(mi.Float(np.full(len(pts), 0.3, np.float32)), mi.Float(np.full(len(pts), S, np.float32)))

    def changed(node):
        a, b = node.eval_bounds(p, (), footprint=fp)[0], node.eval(p)
        dr.eval(a, b)
        return float(np.mean(a.numpy() != b.numpy()))

    for name, node in NODES.items():
        assert changed(node) > 0.25, f"{name}: the footprint changed only {changed(node):.1%} of the points"
    for name, node in PLAIN.items():
        assert changed(node) == 0.0, f"{name}: a footprint changed a node without octaves"


@pytest.mark.parametrize("name", sorted(NODES))
def test_footprint_field_lipschitz_bound_holds(name):
    """Random pairs, near and far: |F(a) - F(b)| <= L (1 + kappa s) |a - b|."""
    node = NODES[name]
    bound = lod_lipschitz(node, Footprint(None, S))
    a = random_points(30_000, -4, 4, seed=3)
    fa = footprint_field(node, a)
    for scale in (1e-2, 1e-1, 1.0):
        b = a + np.random.default_rng(int(scale * 1000)).normal(0, scale, a.shape)
        dist = np.linalg.norm(a - b, axis=1)
        ratio = np.abs(fa - footprint_field(node, b)) / np.maximum(dist, 1e-9)
        slack = 1e-5 * (1 + np.abs(fa)) / np.maximum(dist, 1e-9)
        assert np.all(ratio <= bound * (1 + 1e-4) + slack), f"{name}: {ratio.max():.4f} > {bound:.4f}"


@pytest.mark.parametrize("name", ["noise", "displace", "warp"])
def test_truncated_value_within_its_stated_error(name):
    """``|F_fp(p) - f(p)| <= octave_error`` (times ``sqrt(3) L_child`` for a warp), and
    the bound is not vacuous: the footprints truncate, the error is reached to within
    a factor of a few."""
    node = NODES[name]
    pts = random_points(40_000, -4, 4, seed=12)
    # Footprints from nothing to above the base wavelength: every level of truncation.
    r = 10.0 ** np.random.default_rng(13).uniform(-4, 0.5, len(pts))
    fp = Footprint(mi.Float(r.astype(np.float32)), mi.Float(np.full(len(r), S, np.float32)))
    trunc = node.eval_bounds(_points(pts), (), footprint=fp)[0]
    err = node.octave_error(fp)
    dr.eval(trunc, err)
    err = err.numpy().astype(np.float64)
    if name == "warp":
        err = err * np.sqrt(3.0) * node.children[0].lipschitz
    diff = np.abs(trunc.numpy().astype(np.float64) - F.evaluate(node, pts))
    assert np.all(diff <= err + 1e-5), f"{name}: {np.max(diff - err):.2e} above the bound"
    assert np.any(err == 0.0) and np.any(err > 0.0)
    assert diff.max() > 0.2 * err.max(), "the stated error is loose"


@pytest.mark.parametrize("name", ["noise", "displace", "warp"])
def test_truncated_slope_holds_within_its_reach(name):
    """The local bound of the truncated sum: ``|F(b) - F(a)| <= (L_rest + S(a)) |b - a|``
    for ``b`` within ``rho(a)``, on random segments from ``a``."""
    node = NODES[name]
    a = random_points(30_000, -4, 4, seed=4)
    fp = _footprint(a)
    x = node._lod.level(fp)
    slope, rho = node._lod.slope(x, fp)
    if name == "displace":
        L_rest, scale = node.children[0].lipschitz, 1.0
    elif name == "warp":
        L_rest, scale = node.children[0].lipschitz, np.sqrt(3.0) * node.children[0].lipschitz
    else:
        L_rest, scale = 0.0, 1.0
    dr.eval(slope, rho)
    L = L_rest + scale * slope.numpy().astype(np.float64)
    reach = rho.numpy().astype(np.float64)
    assert np.any(L < node.lipschitz * 0.8), "the footprint never truncated the sum"
    fa = footprint_field(node, a)
    rng = np.random.default_rng(5)
    for _ in range(6):
        v = rng.normal(size=a.shape)
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        b = a + v * (np.minimum(reach, 2.0) * rng.uniform(0, 1, len(a)))[:, None]
        dist = np.linalg.norm(b - a, axis=1)
        diff = np.abs(footprint_field(node, b) - fa)
        assert np.all(diff <= L * dist * (1 + 1e-4) + 1e-5 * (1 + np.abs(fa))), name


@pytest.mark.parametrize("name", sorted(n for n in NODES if n != "noise"))
@pytest.mark.parametrize("direction", [None, (0.6, -0.8, 0.05)])
def test_footprint_distance_bounds_are_free(name, direction):
    """No point of a ball (or a two-sided segment) that ``eval_bounds`` declares free
    at a footprint lies in the footprint field's set ``{F >= -c}``."""
    from test_field_bounds import free_ball_violations

    dv = None if direction is None else mi.Vector3f(*(float(c / np.linalg.norm(direction)) for c in direction))
    for level in (0.0, 0.3):
        worst = free_ball_violations(NODES[name], level, dv, _footprint, footprint_field, rounds=12)
        assert worst <= 1e-4, f"{name} level {level}: {worst}"


def test_cone_tracer_hits_the_footprint_surface():
    """A cone-traced hit lies within its tolerance of the footprint field's surface,
    and the tolerance follows the cone (larger than eps t where the cone is wider)."""
    node = NODES["displace"]
    tracer = SphereTracer(node)
    o = np.array([-2.5, -2.5, 1.2])  # nearer than the field's diagonal: the cone's part counts
    rng = np.random.default_rng(8)
    d = rng.uniform(-0.5, 0.5, (2000, 3)) - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    D = mi.Vector3f(*(mi.Float(d[:, i].astype(np.float32)) for i in range(3)))
    cone = (mi.Float(R0), mi.Float(S))
    hit, t = tracer.trace(mi.Point3f(*map(float, o)), D, mi.Float(1e3), mi.Bool(True), cone)
    tol = tracer.tolerance(t, cone)
    dr.eval(hit, t, tol)
    h, tt, tol = hit.numpy(), t.numpy().astype(np.float64), tol.numpy()
    assert h.mean() > 0.9
    p = o + d * tt[:, None]
    r = R0 + S * np.linalg.norm(p - o, axis=1)
    fp = Footprint(mi.Float(r.astype(np.float32)), mi.Float(np.full(len(r), S, np.float32)))
    f = node.eval_bounds(_points(p), (), footprint=fp)[0].numpy()
    assert np.all(-f[h] < tol[h] * 1.001 + 1e-5)
    assert np.all(tol[h] > 1.5 * float(tracer.eps[0]) * tt[h])
    # ... and it is the footprint surface, not the full-detail one: most hits lie off the latter by
    # more than the tolerance (measured 83 %; a tracer that ignored the footprint would give none).
    off = np.abs(F.evaluate(node, p)[h]) > tol[h]
    assert off.mean() > 0.5, f"only {off.mean():.1%} of the hits lie off the full-detail surface"


MINI = """
[render]
resolution = [48, 32]
spp = 4
[camera]
origin = [0.0, -9.0, 3.0]
target = [0.0, 0.0, 0.5]
[[lights]]
type = "sunsky"
elevation = 35.0
azimuth = -120.0
[materials.rock]
type = "triplanar"
preset = "sandstone"
[field]
root = "ball"
material = "rock"
[nodes.ball]
type = "displace"
child = { type = "sphere", center = [0.0, 0.0, 0.5], radius = 1.5 }
amplitude = 0.25
wavelength = 1.2
octaves = 6
seed = 3
"""


def _lod_render(desc, lod, spp, seed, width=None, height=None):
    """Moments and mean primary tracer steps of a render with or without level of detail."""
    from arches_render.render.renderer import build_scene, moments_of, render_layers
    scene = build_scene(desc, "field", width, height, moments=True)
    scene.integrator().lod = lod
    rgb, layers = render_layers(scene, spp, seed=seed)
    return moments_of(rgb, layers, spp), float(layers["steps"][0].mean())


def _same_image_fewer_steps(full, lod, proven=False):
    """Level of detail leaves the image as it was (the golden tests' Welch tests on the beauty,
    with independent samples, and the image mean within 1 %) and takes fewer tracer steps. The
    depth is not compared: truncated octaves move the surface by less than a pixel's footprint,
    which the depth test resolves (mini: |z| 6.7 at 64 spp). ``proven``: the level-of-detail
    render must also pass the golden tests' power check (a 1 % global and a 25 % window
    change, up and down, would have failed)."""
    from arches_render.imaging.welch import power_check, welch_compare
    (fm, fsteps), (lm, lsteps) = full, lod
    res = welch_compare(fm, lm, geometry=False)
    assert res.passed, res.summary()
    if proven:
        assert power_check(fm, lm) == [], "too few samples to tell a 1 % shift or a 25 % patch"
    rel = abs(lm.mean.mean() / fm.mean.mean() - 1)
    assert rel <= 0.01, f"image mean shift {rel:.4f}"
    assert lsteps < fsteps, f"level of detail took {lsteps:.2f} steps per camera ray, full detail {fsteps:.2f}"


def test_level_of_detail_image_agrees_with_full_detail():
    """Octaves below the pixel skipped: the same image within noise, in fewer steps (mini:
    16.7 against 18.0 per camera ray, measured). Not proven at this spp: at 64 spp against a
    256-spp full-detail reference the window test fails at the sphere's rim in 2 of 3 seeds
    (rim windows 15-61 % darker; full detail against itself passes): without their sub-pixel
    bumps grazing rays cover less of a rim pixel. Issue 36, item 4: accepted and stated
    (arches_render.field.lod, "What it does not keep: silhouettes")."""
    import tomllib

    from arches_render.scene import parse_scene

    desc = parse_scene(tomllib.loads(MINI), SCENES / "mini.toml")
    _same_image_fewer_steps(_lod_render(desc, False, 64, seed=1), _lod_render(desc, True, 64, seed=2))


def test_default_scene_level_of_detail_agrees_and_is_deterministic():
    """The default scene at low resolution: with level of detail, the same bits twice
    (shadow rays included; the second render reuses the kernels), and the same image as
    full detail within noise, proven at 64 spp against a 256-spp full-detail reference
    (as a golden's check: its power check passes, 3 of 3 seeds), in fewer steps (5.2
    against 5.5 per camera ray, measured)."""
    from arches_render.scene import load_scene

    desc = load_scene(SCENES / "default.toml")
    a, b = (_lod_render(desc, True, 8, 1, 80, 45) for _ in range(2))
    assert np.array_equal(a[0].mean, b[0].mean) and a[1] == b[1]
    _same_image_fewer_steps(_lod_render(desc, False, 256, 2, 80, 45), _lod_render(desc, True, 64, 1, 80, 45),
                            proven=True)


def test_render_lod_key_reaches_the_integrator():
    """``[render] lod`` (default true) switches the integrator's level of detail; a value
    that is not a boolean is refused with the key named."""
    import tomllib

    from arches_render.render.renderer import build_scene
    from arches_render.scene import SceneError, parse_scene

    on = parse_scene(tomllib.loads(MINI), SCENES / "mini.toml")
    off = parse_scene(tomllib.loads(MINI.replace("spp = 4", "spp = 4\nlod = false")), SCENES / "mini.toml")
    assert on.render.lod is True and off.render.lod is False
    assert build_scene(on, "field", 8, 6).integrator().lod is True
    assert build_scene(off, "field", 8, 6).integrator().lod is False
    with pytest.raises(SceneError, match="lod"):
        parse_scene(tomllib.loads(MINI.replace("spp = 4", "spp = 4\nlod = 3")), SCENES / "mini.toml")
