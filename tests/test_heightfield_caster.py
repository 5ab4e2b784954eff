"""Exact heightfield ray casting (maximum mipmaps) against a brute-force dense sampling
of the field along the rays; cast plans, the blend-excess and leaf bounds they rest on,
shadow rays, determinism, and rendered images against the sphere tracer."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render import field as F  # noqa: E402
from arches_render.field.heightfield_mipmap import (MaxMipmap, blend_excess, far_leaves,  # noqa: E402
                                                    heightfield_cast_plan)
from arches_render.field.node import evaluate  # noqa: E402
from arches_render.field.operators import smooth_max  # noqa: E402
from arches_render.render.heightfield_caster import HeightfieldCaster, make_tracer  # noqa: E402
from arches_render.render.sphere_tracer import SphereTracer  # noqa: E402

STEP = 2e-3      # brute-force sample spacing along rays (m)
GRAZE = 2e-3     # |f| below which a ray only grazes the surface (float32 rounding, m)


def rough_terrain(seed=0, shape=(33, 41)):
    """Steep random ground over 40 m x 32 m (1 m cells, slopes up to ~5)."""
    rng = np.random.default_rng(seed)
    H = rng.normal(0, 3, shape).cumsum(0) * 0.3 + rng.normal(0, 1, shape)
    return F.Heightfield(H, (-20.0, -15.0, 20.0, 17.0))


def _vec(a, cls):
    a = np.asarray(a, np.float32)
    return cls(*(mi.Float(np.ascontiguousarray(a[:, i])) for i in range(3)))


def ray_families(hf, n, seed=1):
    """Rays of several kinds: from outside, grazing the relief, starting inside or
    under the solid, vertical and axis-aligned (far rays: see the test)."""
    rng = np.random.default_rng(seed)
    lo, hi = (np.asarray(b) for b in hf.bounds())
    fam = {}
    o = rng.uniform(lo - 8, hi + 8, (n, 3))
    fam["outside"] = (o, rng.uniform(lo, hi, (n, 3)) - o)
    # Grazing: start just above the surface, nearly horizontal.
    xy = rng.uniform(lo[:2] + 2, hi[:2] - 2, (n, 2))
    h = _heights(hf, xy)
    az = rng.uniform(0, 2 * np.pi, n)
    el = rng.uniform(-0.03, 0.03, n)
    d = np.column_stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
    fam["grazing"] = (np.column_stack([xy, h + rng.uniform(0.01, 0.5, n)]), d)
    # Inside the solid (under the surface) and under its base, any direction.
    o = np.column_stack([xy, h - rng.uniform(0.05, 2.0, n)])
    o[: n // 2, 2] = hf.base_np - rng.uniform(0.5, 5.0, n // 2)
    d = rng.normal(size=(n, 3))
    d[: n // 2, 2] = np.abs(d[: n // 2, 2]) + 0.2
    fam["inside"] = (o, d)
    # Vertical rays from above, horizontal rays along x or y.
    o = np.column_stack([rng.uniform(lo[:2], hi[:2], (n, 2)), np.full(n, hi[2] + 3.0)])
    d = np.tile([0.0, 0.0, -1.0], (n, 1))
    m = n // 2
    o[m:, 2] = rng.uniform(lo[2], hi[2], n - m)
    d[m:] = 0.0
    d[m:][np.arange(n - m), rng.integers(0, 2, n - m)] = np.where(rng.random(n - m) < 0.5, -1.0, 1.0)
    fam["axis"] = (o, d)
    return {k: (o, d / np.linalg.norm(d, axis=1, keepdims=True)) for k, (o, d) in fam.items()}


def _heights(hf, xy):
    import mitsuba as mi
    h = hf.height(mi.Float(xy[:, 0].astype(np.float32)), mi.Float(xy[:, 1].astype(np.float32)))
    return h.numpy().astype(np.float64)


def brute_force(node, o, d, t_max):
    """Dense samples ``f(o + t d)`` on ``[0, t_max]`` (float32, like the renderer)."""
    ts = np.arange(0.0, t_max + STEP, STEP, dtype=np.float32)
    o32, d32 = o.astype(np.float32), d.astype(np.float32)
    f = np.empty((len(o), len(ts)), np.float32)
    rows = max(1, (1 << 22) // len(ts))  # one launch per few million samples
    for i in range(0, len(o), rows):
        pts = o32[i:i + rows, None] + ts[None, :, None] * d32[i:i + rows, None]
        f[i:i + rows] = evaluate(node, pts.reshape(-1, 3)).reshape(-1, len(ts))
    return ts, f


def check_first_hits(node, o, d, hit, t, t_max, tol_t=STEP + 1e-3, hit_tol=None):
    """Every cast answer agrees with the dense samples; returns the number of grazes.

    A hit at ``t`` must have no sampled matter before ``t - tol_t`` and must lie on
    the surface (``f >= -hit_tol``, default a graze); a miss, no sampled matter
    beyond a graze. Hit/miss disagreements are allowed only where ``max f`` along
    the ray is within :data:`GRAZE` of 0.
    """
    ts, f = brute_force(node, o, d, t_max)
    grazes = 0
    for i in range(len(o)):
        inside = np.nonzero(f[i] >= 0.0)[0]
        tb = ts[inside[0]] if len(inside) else np.inf
        if hit[i]:
            assert t[i] <= tb + tol_t, (i, t[i], tb)
            fc = evaluate(node, (o[i] + t[i] * d[i])[None].astype(np.float32))[0]
            tol = GRAZE if hit_tol is None else hit_tol(t[i])
            assert fc >= -tol, (i, t[i], fc)
            if not len(inside):
                grazes += 1
        else:
            if len(inside):
                assert f[i].max() <= GRAZE, (i, tb, f[i].max())
                grazes += 1
    return grazes


def test_mipmap_levels_bound_the_bilinear_surface():
    hf = rough_terrain(3, (20, 27))
    mm = MaxMipmap(hf.heights_np)
    assert mm.shapes[0] == (19, 26) and mm.shapes[-1] == (1, 1)
    rng = np.random.default_rng(0)
    x0, y0 = hf.extent[:2]
    xy = rng.uniform([x0, y0], hf.extent[2:], (20000, 2))
    h = _heights(hf, xy)
    i = np.minimum(((xy[:, 0] - x0) / hf.dx).astype(int), hf.nx - 2)
    j = np.minimum(((xy[:, 1] - y0) / hf.dy).astype(int), hf.ny - 2)
    for lvl in range(mm.levels):
        hi, lo = mm.level(lvl, "max"), mm.level(lvl, "min")
        assert np.all(h <= hi[j >> lvl, i >> lvl]) and np.all(h >= lo[j >> lvl, i >> lvl])
    # The top cell holds the extremes of the samples (a tight pyramid).
    assert abs(mm.level(mm.levels - 1)[0, 0] - hf.heights_np.max()) < 1e-4 * (1 + abs(hf.heights_np.max()))


def _trace(tracer, o, d, tmax=1e5):
    hit, t = tracer.trace(_vec(o, mi.Point3f), _vec(d, mi.Vector3f), mi.Float(tmax), mi.Bool(True))
    return hit.numpy(), t.numpy()


@pytest.mark.parametrize("family", ["outside", "grazing", "inside", "axis"])
def test_cast_matches_brute_force(family):
    hf = rough_terrain()
    tracer = make_tracer(hf)
    assert isinstance(tracer, HeightfieldCaster) and not tracer.hybrid
    o, d = ray_families(hf, 160)[family]
    hit, t = _trace(tracer, o, d)
    assert hit.mean() > 0.2
    if family == "inside":
        under = o[:, 2] >= hf.base_np
        assert np.all(hit[under]) and np.all(t[under] == 0.0)  # inside matter: a hit at the start
    assert check_first_hits(hf, o, d, hit, t, 120.0) <= 0.02 * len(o)


def test_cast_from_far_away():
    """Rays from kilometres away find the hits of the same rays started nearby
    (to float32 precision at that distance)."""
    hf = rough_terrain(2)
    tracer = make_tracer(hf)
    rng = np.random.default_rng(5)
    lo, hi = (np.asarray(b) for b in hf.bounds())
    target = rng.uniform(lo, hi, (400, 3))
    d = rng.normal(size=(400, 3))
    d[:, 2] = -np.abs(d[:, 2]) - 0.05
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    far = rng.uniform(2000.0, 5000.0, 400)
    hit_f, t_f = _trace(tracer, target - d * far[:, None], d)
    hit_n, t_n = _trace(tracer, target - d * 60.0, d)
    assert hit_n.mean() > 0.5
    assert np.array_equal(hit_f, hit_n)
    assert np.all(np.abs((t_f - (far - 60.0))[hit_n] - t_n[hit_n]) < 5e-3)


def test_cast_through_a_clipping_box():
    hf = rough_terrain(5)
    node = F.Intersection(hf, F.Box([2.0, 1.0, 0.0], [9.0, 6.0, 40.0]))
    tracer = make_tracer(node)
    assert isinstance(tracer, HeightfieldCaster)
    o, d = ray_families(hf, 160, seed=4)["outside"]
    hit, t = _trace(tracer, o, d)
    assert 0.05 < hit.mean() < 0.95
    assert check_first_hits(node, o, d, hit, t, 120.0) <= 2


def test_shadow_rays_agree_with_first_hits():
    hf = rough_terrain(7)
    tracer = make_tracer(hf)
    rng = np.random.default_rng(2)
    o, d = ray_families(hf, 2000, seed=6)["grazing"]
    o = o + np.array([0.0, 0.0, 0.5])
    d = np.column_stack([d[:, :2], rng.uniform(-0.2, 0.6, len(d))])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tmax = rng.uniform(0.5, 40.0, len(d))
    O, D, T = _vec(o, mi.Point3f), _vec(d, mi.Vector3f), mi.Float(tmax.astype(np.float32))
    hit, t = tracer.trace(O, D, T, mi.Bool(True))
    blocked = tracer.occluded(O, D, T, mi.Bool(True)).numpy()
    hit, t = hit.numpy(), t.numpy()
    assert 0.1 < blocked.mean() < 0.9
    # A certain hit is a hit; only first hits within rounding of tmax may differ.
    differ = blocked != hit
    assert np.all(np.abs(t[differ] - tmax[differ]) < 1e-3)


def arch_scene(kind="blend"):
    """A heightfield blended with a displaced arch of capsules, or (``'union'``) in
    union with a displaced box and a ball (leaves without exact ray spans)."""
    hf = rough_terrain(9)
    if kind == "union":
        rock = F.Displace(F.Box([6.0, 2.0, 2.0], [3.0, 2.0, 4.0], rounding=0.5), amplitude=0.3, wavelength=2.0,
                          octaves=2, seed=2)
        return F.Union(hf, rock, F.Sphere([-6.0, 0.0, 6.0], 2.5)), hf
    caps = [F.Capsule([-8.0, 0.0, 0.0], [-4.0, 0.0, 7.0], 1.5), F.Capsule([-4.0, 0.0, 7.0], [4.0, 0.0, 7.5], 1.3),
            F.Capsule([4.0, 0.0, 7.5], [8.0, 0.0, 0.0], 1.5)]
    arch = F.Displace(F.Blend(*caps, radius=1.0), amplitude=0.3, wavelength=2.0, octaves=2, seed=1)
    return F.Blend(hf, arch, radius=3.0), hf


@pytest.mark.parametrize("kind", ["blend", "union"])
def test_hybrid_matches_brute_force_and_sphere_tracer(kind):
    root, hf = arch_scene(kind)
    tracer = make_tracer(root)
    assert isinstance(tracer, HeightfieldCaster) and tracer.hybrid
    rng = np.random.default_rng(3)
    n = 240
    o = rng.uniform([-25, -30, 5], [25, -20, 25], (n, 3))
    d = rng.uniform([-12, -4, -4], [12, 4, 9], (n, 3)) - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    O, D = _vec(o, mi.Point3f), _vec(d, mi.Vector3f)
    hit, t = tracer.trace(O, D, mi.Float(1e5), mi.Bool(True))
    hit, t = hit.numpy(), t.numpy()
    assert hit.mean() > 0.5
    eps = float(tracer.eps[0])
    # Near the 3-D operands the caster takes sphere steps: a hit is within their tolerance.
    grazes = check_first_hits(root, o, d, hit, t, 80.0, hit_tol=lambda ti: eps * ti + GRAZE)
    assert grazes <= 0.03 * n
    sphere = SphereTracer(root)
    hs, ts = sphere.trace(O, D, mi.Float(1e5), mi.Bool(True))
    hs, ts = hs.numpy(), ts.numpy()
    both = hs & hit
    assert (hs != hit).mean() <= 0.03
    # The sphere tracer stops up to its tolerance in front of the surface.
    assert np.all(t[both] >= ts[both] - 5 * eps * ts[both] - 1e-3)
    assert np.median(np.abs(t[both] - ts[both])) < 10 * eps * np.median(ts[both])
    # Shadow rays: blocked exactly where a first hit lies within tmax.
    tmax = rng.uniform(5.0, 60.0, n).astype(np.float32)
    hit2, t2 = tracer.trace(O, D, mi.Float(tmax), mi.Bool(True))
    blocked = tracer.occluded(O, D, mi.Float(tmax), mi.Bool(True)).numpy()
    assert np.array_equal(blocked, hit2.numpy())


def test_cast_plans():
    hf = rough_terrain()
    box = F.Box([0.0, 0.0, 0.0], [5.0, 5.0, 30.0])
    cap = F.Capsule([0, 0, 0], [0, 0, 5], 1.0)
    assert heightfield_cast_plan(hf).others == ()
    assert heightfield_cast_plan(F.Intersection(box, hf)) is not None
    assert heightfield_cast_plan(F.Intersection(hf, F.Box([0, 0, 0], [5, 5, 30], rounding=1.0))) is None
    assert heightfield_cast_plan(F.Union(cap, box, hf)).radius == 0.0
    assert heightfield_cast_plan(F.Blend(cap, hf, radius=2.0)).others == (cap,)
    # A blend folds left to right: only its first two operands commute bitwise.
    assert heightfield_cast_plan(F.Blend(cap, box, hf, radius=2.0)) is None
    assert heightfield_cast_plan(F.Blend(hf, hf, radius=2.0)) is None
    assert heightfield_cast_plan(F.Difference(hf, cap)) is None
    assert isinstance(make_tracer(F.Difference(hf, cap)), SphereTracer)
    assert isinstance(make_tracer(hf, cast=False), SphereTracer)


def test_blend_excess_is_the_tight_fold_bound():
    rng = np.random.default_rng(0)
    k = 2.0
    for n in range(2, 10):
        e = blend_excess(n, k)
        assert 0 < e < k
        vals = rng.uniform(-3, 0, (20000, n)).astype(np.float32)
        vals[:1000] = -1.0  # equal operands reach the bound
        g = mi.Float(vals[:, 0])
        for j in range(1, n):
            g = smooth_max(g, mi.Float(vals[:, j]), k)
        excess = g.numpy() - vals.max(axis=1)
        assert excess.max() <= e + 1e-5
        assert excess[:1000].min() >= e - 1e-5


def test_far_leaves_bound_their_operand():
    root, _ = arch_scene()
    arch = root.children[1]
    leaves = far_leaves(arch)
    assert len(leaves) == 3 and all(isinstance(node, F.Capsule) for node, _ in leaves)
    pts = np.random.default_rng(1).uniform([-15, -8, -4], [15, 8, 14], (50000, 3))
    b = evaluate(arch, pts)
    bound = np.max([evaluate(node, pts) + g for node, g in leaves], axis=0)
    assert np.all(b <= bound + 1e-5)


@pytest.mark.parametrize("leaf", [F.Capsule([1.0, -2.0, 0.5], [-3.0, 4.0, 2.0], 1.2), F.Sphere([0.5, 1.0, 2.0], 1.5),
                                  F.Box([0.0, 0.0, 1.0], [2.0, 1.0, 0.5], rounding=0.3)])
def test_leaf_spans_contain_the_grown_leaf(leaf):
    """Every sampled point of a ray inside ``{leaf >= -grow}`` lies in its span."""
    from arches_render.render.heightfield_caster import _grown_box, _leaf_span
    grow = 2.5
    rng = np.random.default_rng(4)
    n = 3000
    o = rng.normal(size=(n, 3)) * 12.0
    o[: n // 3] *= 300.0  # far origins
    d = rng.normal(0, 4.0, (n, 3)) - o
    d[n // 3: n // 2] = [0.0, 0.0, 1.0]  # some axis-aligned and axis-parallel rays
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    e0, e1 = _leaf_span(leaf, mi.Float(grow), _grown_box(leaf, grow), _vec(o, mi.Point3f), _vec(d, mi.Vector3f))
    e0, e1 = e0.numpy(), e1.numpy()
    # Sample around the leaf only: from the closest approach to the origin of the ray.
    t_mid = np.maximum(-(o * d).sum(1), 0.0)
    ts = t_mid[:, None] + np.linspace(-25.0, 25.0, 2001)[None]
    pts = o[:, None] + ts[..., None] * d[:, None]
    inside = (evaluate(leaf, pts.reshape(-1, 3)) >= -grow).reshape(ts.shape) & (ts >= 0.0)
    assert inside.any(1).mean() > 0.2
    covered = (ts >= e0[:, None]) & (ts <= e1[:, None])
    assert np.all(covered[inside])


def test_cast_is_bitwise_deterministic():
    root, hf = arch_scene()
    o, d = ray_families(hf, 3000, seed=8)["outside"]
    for node in (hf, root):
        runs = []
        for _ in range(2):
            runs.append(_trace(make_tracer(node), o, d))
        assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])


def test_rendered_heightfield_cast_matches_sphere_tracing():
    """The integrator hook: a cast heightfield renders as the sphere-traced one."""
    import tomllib

    from arches_render.imaging.compare import flip_error
    from arches_render.render.renderer import build_scene, render_image
    from arches_render.scene import parse_scene

    from helpers import SCENES
    text = """
[render]
resolution = [64, 40]
[camera]
origin = [-30.0, -40.0, 25.0]
target = [0.0, 0.0, 0.0]
[[lights]]
type = "sunsky"
elevation = 30.0
[materials.rock]
type = "triplanar"
preset = "terrain"
[field]
root = "ground"
material = "rock"
[nodes.ground]
type = "heightfield"
extent = [-40.0, -40.0, 40.0, 40.0]
resolution = [81, 81]
amplitude = 12.0
wavelength = 30.0
seed = 2
"""
    desc = parse_scene(tomllib.loads(text), SCENES / "mini_hf.toml")
    scene = build_scene(desc)
    assert isinstance(scene.integrator().tracer, HeightfieldCaster)
    cast = render_image(scene, 16, seed=1)
    integ = scene.integrator()
    integ.tracer = SphereTracer(desc.field, eps=integ.eps, omega=integ.omega, max_steps=integ.max_steps)
    sphere = render_image(scene, 16, seed=1)
    assert abs(cast.mean() / sphere.mean() - 1) < 0.01
    assert flip_error(sphere, cast)[1] < 0.03


def test_kernels_do_not_depend_on_where_numpy_put_the_arrays():
    """``mi.Float(ndarray)`` wraps numpy's memory, and Dr.Jit emits a packet gather
    (four floats at once) only from 64-byte-aligned memory and aligned vector loads only
    from aligned inputs; numpy aligns to 16 bytes. A heightfield's patch corners and a
    field evaluation's points went through plain conversions, so a scene traced one of
    several kernels by chance and a warm kernel cache missed (seconds of LLVM).
    ``jit_floats`` copies into aligned memory: the same kernel at every offset."""
    from arches_render.field.node import jit_floats, jit_points
    base = np.arange(64, dtype=np.float32)

    def kernels(offset):
        buf = np.zeros(64 + 16, np.float32)
        a = buf[offset:offset + 64]
        a[:] = base
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            v = dr.gather(mi.Vector4f, jit_floats(a), mi.UInt32(0, 1, 2))
            p = jit_points(a[:63].reshape(-1, 3))
            w = p.x * 2.0 + p.y - p.z
            dr.eval(v, w)
            jit = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
        assert np.allclose(v.numpy(), base[:12].reshape(3, 4).T)
        return {k["hash"] for k in jit}, [k["ir"].getvalue() for k in jit]

    hashes, irs = kernels(0)
    assert any("gather_4x" in ir for ir in irs), "the Vector4f gather is not a packet gather"
    for offset in range(1, 8):
        assert kernels(offset)[0] == hashes, f"at an offset of {offset * 4} bytes: other kernels"
