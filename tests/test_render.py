"""The renderer as a whole: estimator correctness against Mitsuba's ``path``,
field against mesh geometry, determinism, and parameters that do not recompile."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import SCENES, assert_field_matches_mesh, variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render import field as F  # noqa: E402
from arches_render.imaging.welch import PixelMoments, power_check, welch_compare  # noqa: E402
from arches_render.render.renderer import (build_scene, moments_of, render_image, render_layers,  # noqa: E402
                                           render_moments)
from arches_render.scene import load_scene, parse_scene  # noqa: E402


def _scene(integrator, sphere_mesh=True, width=64, height=48):
    if integrator["type"] == "implicit_path":
        integrator = {**integrator, "aovs": True, "moments": True}
    d = {"type": "scene", "integrator": integrator,
         "sensor": {"type": "perspective", "fov": 40,
                    "to_world": mi.ScalarTransform4f().look_at(origin=[0, -5, 2], target=[0, 0, 0.4], up=[0, 0, 1]),
                    "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}}},
         "env": {"type": "constant", "radiance": {"type": "rgb", "value": 0.4}},
         "sun": {"type": "directional", "direction": [-0.3, 0.5, -0.8], "irradiance": {"type": "rgb", "value": 3.0}},
         "ground": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(4),
                    "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}}}
    if sphere_mesh:
        d["ball"] = {"type": "sphere", "center": [0, 0, 0.5], "radius": 0.5,
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}}}
    return mi.load_dict(d)


def _same_image(ref, test, geometry=True):
    """Welch's two-sample tests (per pixel, 8x8 window, image mean; coverage and depth):
    the two renders converge to the same image."""
    res = welch_compare(ref, test, geometry=geometry)
    assert res.passed, res.summary() + "\n" + "\n".join(res.failures)
    assert power_check(ref, test) == [], "too few samples to tell a 1 % shift or a 25 % patch"
    return res


def test_implicit_path_matches_stock_path_on_meshes():
    # Mitsuba's path returns no second moments: eight independent 32-spp renders give them.
    ref = PixelMoments.from_batches([render_image(_scene({"type": "path", "max_depth": 6}), 32, seed=s)
                                     for s in range(1, 9)], 32)
    ours = render_moments(_scene({"type": "implicit_path", "max_depth": 6}), 128, seed=20)
    _same_image(ref, ours, geometry=False)


def test_implicit_path_matches_stock_path_with_multiple_bounces():
    """A Cornell box, where most light arrives after several diffuse bounces. The
    sampler is loop state: with it captured by the loop body instead, every bounce
    reused the first bounce's random numbers, and the box came out 2.6 % darker in
    red and up to 10 % in an 8x8 window (issue 32's review of the loop state)."""
    from arches_render.render.plugins import ensure_registered
    ensure_registered()

    def box(integrator):
        d = mi.cornell_box()
        d["integrator"] = integrator
        d["sensor"]["film"].update(width=48, height=48, rfilter={"type": "box"})
        return mi.load_dict(d)

    ref = PixelMoments.from_batches([render_image(box({"type": "path", "max_depth": 6}), 32, seed=s)
                                     for s in range(1, 9)], 32)
    ours = render_moments(box({"type": "implicit_path", "max_depth": 6, "aovs": True, "moments": True}), 128,
                          seed=20)
    res = welch_compare(ref, ours, geometry=False)
    assert res.passed, res.summary() + "\n" + "\n".join(res.failures)
    # The test has the power to see the bias it guards against (1 % would need ~2700 spp).
    assert not welch_compare(ref, ours.brightened(0.975), geometry=False).passed


def test_field_sphere_matches_analytic_sphere():
    """Same integrator, the ball as Mitsuba's analytic sphere or as a sphere-traced
    field: the same image, coverage and depth within noise (no offset or inflation)."""
    ref = render_moments(_scene({"type": "implicit_path", "max_depth": 6}), 128, seed=1)
    scene = _scene({"type": "implicit_path", "max_depth": 6}, sphere_mesh=False)
    bsdf = mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}})
    scene.integrator().attach(F.Sphere([0, 0, 0.5], 0.5), bsdf)
    _same_image(ref, render_moments(scene, 128, seed=3))


MINI = """
[render]
resolution = [40, 30]
spp = 4
[camera]
origin = [0.0, -6.0, 2.0]
target = [0.0, 0.0, 0.5]
[[lights]]
type = "sunsky"
elevation = 40.0
[materials.rock]
type = "triplanar"
preset = "basalt"
[field]
root = "ball"
material = "rock"
[nodes.ball]
type = "displace"
child = { type = "sphere", center = [0.0, 0.0, 0.5], radius = 1.0 }
amplitude = 0.1
wavelength = 0.5
seed = 3
"""


def test_same_seed_same_bits_other_seed_differs():
    import tomllib
    desc = parse_scene(tomllib.loads(MINI), SCENES / "mini.toml")
    scene = build_scene(desc)
    a = render_image(scene, 4, seed=7)
    b = render_image(build_scene(desc), 4, seed=7)
    c = render_image(scene, 4, seed=8)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


#: A heightfield blended with a ball: the hybrid caster's loops (cast, probe, near).
MINI_HYBRID = """
[render]
resolution = [48, 30]
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
[nodes.hills]
type = "heightfield"
extent = [-40.0, -40.0, 40.0, 40.0]
resolution = [81, 81]
amplitude = 12.0
wavelength = 30.0
seed = 2
[nodes.ground]
type = "blend"
radius = 2.0
children = ["hills", { type = "sphere", center = [0.0, 0.0, 8.0], radius = 6.0 }]
"""


@pytest.mark.parametrize("case", ["sphere", "wavefront", "cells", "hybrid", "mesh"])
def test_a_render_traces_each_loop_body_once(case, monkeypatch):
    """Python traces each symbolic loop's body once (the path loop, the marches, the
    queue, the heightfield caster's loops, the cavity's and the sets' lists): Dr.Jit
    records a loop again when its state holds a variable that the body leaves
    unchanged (the loop optimisation; a width-1 parameter of the integrator, the
    scene or a tracer; a side effect's target), and loops in loops multiplied it:
    a quarter to a third of a small render was tracing (sample_megakernel)."""
    import tomllib
    text = MINI_HYBRID if case == "hybrid" else MINI
    if case in ("wavefront", "cells"):
        option = "wavefront" if case == "wavefront" else "surface_cells"
        text = text.replace("[render]\n", f"[render]\n{option} = true\n", 1)
    desc = parse_scene(tomllib.loads(text), SCENES / "mini.toml")
    scene = build_scene(desc, "mesh" if case == "mesh" else "field", 48, 30)
    render_image(scene, 2, seed=1)  # kernels compiled; the counts below are tracing only
    loops, bodies = {}, {}
    while_loop = dr.while_loop

    def counted(state, cond, body, *args, label=None, **kwargs):
        loops[label] = loops.get(label, 0) + 1

        def traced(*state):
            bodies[label] = bodies.get(label, 0) + 1
            return body(*state)
        return while_loop(state, cond, traced, *args, label=label, **kwargs)
    monkeypatch.setattr(dr, "while_loop", counted)
    render_image(scene, 2, seed=1)
    expected = {"sphere": "sphere_trace", "wavefront": "queued_march", "cells": "cell_trace",
                "hybrid": "heightfield_hybrid", "mesh": "implicit_path"}[case]
    assert loops.get(expected, 0) >= 1, loops
    assert bodies == loops


@pytest.mark.parametrize("geometry", ["field", "mesh"])
def test_a_render_traces_the_material_once(geometry, monkeypatch):
    """The field's material is shaded once a vertex (``shade``), and its tracing too: the
    calls of every BSDF on the lanes it did not shade reach it with none, and return
    zeros untraced (``shaded_elsewhere``); they traced its shading twice more."""
    import tomllib
    from arches_render.materials.triplanar import TriplanarBSDF
    desc = parse_scene(tomllib.loads(MINI), SCENES / "mini.toml")
    scene = build_scene(desc, geometry, 48, 30)
    before = render_image(scene, 2, seed=1)
    shade, calls = TriplanarBSDF.shade, []

    def counted(self, *args, **kwargs):
        calls.append(self)
        return shade(self, *args, **kwargs)
    monkeypatch.setattr(TriplanarBSDF, "shade", counted)
    assert np.array_equal(render_image(scene, 2, seed=1), before)
    assert len(calls) == 1


def test_changing_parameters_does_not_recompile():
    import tomllib
    desc = parse_scene(tomllib.loads(MINI), SCENES / "mini.toml")
    scene = build_scene(desc)
    render_image(scene, 2, seed=1)
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        a = render_image(scene, 2, seed=1)
        seen = {k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT}
        # Move the sphere and shrink it: opaque parameters, same kernels.
        sphere = desc.field.children[0]
        sphere.r = dr.opaque(mi.Float, 0.8)
        sphere.c = mi.Point3f(*(dr.opaque(mi.Float, v) for v in (0.1, 0.0, 0.4)))
        dr.kernel_history_clear()
        b = render_image(scene, 2, seed=1)
        new = {k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT} - seen
    # Without the history flag both sets are empty and the test would pass vacuously.
    assert seen, "the kernel history recorded no kernels"
    assert not np.array_equal(a, b)
    assert not new, f"{len(new)} kernels were compiled for a parameter change"


# Scenes with a [field]: mesh-only scenes have nothing to cross-check.
SHIPPED_FIELDS = sorted(p.stem for p in SCENES.glob("*.toml") if "\n[field]" in p.read_text())
# Independent sample streams: Welch's test assumes the two renders' noise is uncorrelated
# (one shared seed made every window's difference smaller than its stated noise).
FIELD_SEED, MESH_SEED = 1, 2
# Known disagreements, kept visible: strict, so a fix turns them into failures to remove here.
KNOWN_FIELD_MESH_BUGS: dict[str, str] = {}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=KNOWN_FIELD_MESH_BUGS[n]))
                                  if n in KNOWN_FIELD_MESH_BUGS else n for n in SHIPPED_FIELDS])
def test_shipped_scene_field_agrees_with_mesh(name):
    """Sphere tracing and the marching-cubes mesh of the same field, same rays:

    * every pixel that the mesh covers fully (with its 3x3 neighbourhood:
      silhouettes move by the mesh's voxel) is covered by the field in every
      sample (noise-free: a ray that gives up in rock would show the sky there,
      issue 21), and no camera ray used up both step budgets;
    * the beauty agrees window by window and in the mean, within the mesh's
      discretization and the noise (``helpers.assert_field_matches_mesh``)."""
    from scipy.ndimage import minimum_filter
    desc = load_scene(SCENES / f"{name}.toml")
    w, h, spp = 96, 54, 32
    f_rgb, f_layers = render_layers(build_scene(desc, "field", w, h, moments=True), spp, seed=FIELD_SEED)
    m_rgb, m_layers = render_layers(build_scene(desc, "mesh", w, h, moments=True), spp, seed=MESH_SEED)
    field, mesh = moments_of(f_rgb, f_layers, spp), moments_of(m_rgb, m_layers, spp)
    solid = minimum_filter(mesh.coverage, size=3, mode="nearest") > 0.999
    holes = solid & (field.coverage < 0.999)
    assert solid.mean() > 0.05
    assert not holes.any(), f"{holes.sum()} pixels the mesh covers show no field"
    unresolved, letters = f_layers["unresolved"]
    assert unresolved[..., letters.index("primary")].sum() == 0
    assert_field_matches_mesh(field, mesh)


def test_material_mask_and_other_lights(tmp_path):
    """A noise mask changes a triplanar layer's coverage; point and envmap lights render."""
    import tomllib

    from arches_render.imaging.exr import write_exr
    env = np.ones((8, 16, 3), np.float32) * np.array([0.3, 0.4, 0.6], np.float32)
    write_exr(tmp_path / "sky.exr", env, half=False)
    text = MINI.replace('[[lights]]\ntype = "sunsky"\nelevation = 40.0', '''[[lights]]
type = "envmap"
file = "sky.exr"
[[lights]]
type = "point"
position = [2.0, -3.0, 4.0]
intensity = 30.0''').replace('preset = "basalt"', 'preset = "terrain"')
    plain = parse_scene(tomllib.loads(text), tmp_path / "s.toml")
    masked = parse_scene(tomllib.loads(text.replace('preset = "terrain"', '''preset = "terrain"
masks = [{ layer = "snow", node = "cover", lo = -1.0, hi = -0.5 }]''') + '''
[nodes.cover]
type = "noise"
'''), tmp_path / "s.toml")
    # The terrain preset's snow is absent at these heights: masking it changes
    # nothing. Where snow is forced everywhere, a mask (noise ~0 < lo) removes it.
    inverted = parse_scene(tomllib.loads(text.replace('preset = "terrain"', '''preset = "terrain"
overrides = { "snow.height_min" = 0.0, "snow.slope_max" = 90.0 }
masks = [{ layer = "snow", node = "cover", lo = 0.5, hi = 1.0 }]''') + '''
[nodes.cover]
type = "noise"
'''), tmp_path / "s.toml")
    snowy = parse_scene(tomllib.loads(text.replace('preset = "terrain"', '''preset = "terrain"
overrides = { "snow.height_min" = 0.0, "snow.slope_max" = 90.0 }''')), tmp_path / "s.toml")
    imgs = [render_image(build_scene(d), 16, seed=1) for d in (plain, masked, snowy, inverted)]
    for img in imgs:
        assert np.all(np.isfinite(img)) and img.mean() > 0.01
    assert abs(imgs[1].mean() / imgs[0].mean() - 1) < 1e-3  # masking an absent layer
    assert imgs[2].mean() > 1.1 * imgs[3].mean()     # snow removed by the inverted mask


@pytest.mark.parametrize("omega", [1.0, 1.6, 1.9])
def test_relaxed_step_cannot_skip_a_surface_before_tmax(omega):
    """A relaxed step that would jump past ``tmax`` is still checked before the ray
    leaves (regression: such rays used to miss a surface lying just before a mesh)."""
    from arches_render.render.sphere_tracer import SphereTracer
    ball = F.Union(F.Sphere([10.0, 0.0, 0.0], 0.05), F.Sphere([0.0, 30.0, 0.0], 1.0))
    tracer = SphereTracer(ball, omega=omega)
    o = mi.Point3f(0.0, 0.0, 0.0)
    d = mi.Vector3f(1.0, 0.0, 0.0)
    for tmax in (10.2, 11.0, 16.0):
        hit, t = tracer.trace(o, d, mi.Float(tmax), True)
        assert bool(hit[0]) and abs(t[0] - 9.95) < 0.01, (tmax, hit, t)
    hit, _ = tracer.trace(o, d, mi.Float(9.9), True)
    assert not bool(hit[0])
