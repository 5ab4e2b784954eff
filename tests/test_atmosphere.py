"""Aerial perspective (``[atmosphere]``): closed forms against quadrature, rendered
transmittance and in-scatter of walls at known distances against the analytic
integral, the fog-free limit, field against mesh with fog, the scene table, and with a
sky: the sky table against the emitter, the fade to the horizon, misses that see the sky."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest
from scipy.integrate import quad

from helpers import SCENES, variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.render import atmosphere as A  # noqa: E402
from arches_render.render import sky_table as S  # noqa: E402
from arches_render.render.renderer import build_scene, render_image, render_layers  # noqa: E402
from arches_render.scene import SceneError, load_scene, parse_scene  # noqa: E402
from arches_render.scene.loader import AtmosphereSettings  # noqa: E402


# -- an independent reference: the profile as the docstring defines it, by quadrature ---------
def _profile(z, ground, h):
    return math.exp(-max(z - ground, 0.0) / h)


def _column_quad(z0, z1, t, ground, h):
    kink = [t * (ground - z0) / (z1 - z0)] if (z0 - ground) * (z1 - ground) < 0 else None
    return quad(lambda u: _profile(z0 + (z1 - z0) * u / t, ground, h), 0.0, t, points=kink,
                epsabs=0.0, epsrel=1e-12, limit=200)[0]


def _components(st):
    """``[(beta RGB, H, albedo, phase kind)]`` of settings ``st``, from the published constants."""
    s = st.density
    out = [(np.array(A.RAYLEIGH_BETA) * s, st.rayleigh_height, 1.0, "rayleigh"),
           (np.array(A.aerosol_extinction(st.turbidity, st.aerosol_height)) * s, st.aerosol_height,
            st.aerosol_albedo, "hg")]
    if st.haze_density > 0:
        out.append((np.full(3, st.haze_density * s), st.haze_height, st.aerosol_albedo, "hg"))
    return out


def _reference(st, o, d, t, suns=(), ambient=(0.0, 0.0, 0.0), n=200001):
    """Transmittance and single-scattered in-scatter of a segment, by the trapezoidal rule on a
    fine grid (cumulative optical depth, then ``int Tr sum sigma_k omega_k S_k``)."""
    u = np.linspace(0.0, t, n)
    z = o[2] + d[2] * u
    sig_total = np.zeros((3, n))
    source = np.zeros((3, n))
    for beta, h, albedo, kind in _components(st):
        sig = beta[:, None] * np.exp(-np.maximum(z - st.ground, 0.0) / h)[None]
        s_k = np.array(ambient, float)
        for sd, e in suns:
            mu = float(np.dot(d, sd))
            if kind == "rayleigh":
                p = 3.0 / (16.0 * math.pi) * (1.0 + mu * mu)
            else:
                g = st.anisotropy
                p = (1.0 - g * g) / (4.0 * math.pi * (1.0 + g * g - 2.0 * g * mu) ** 1.5)
            s_k = s_k + np.asarray(e, float) * p
        sig_total += sig
        source += sig * albedo * s_k[:, None]
    tau = np.concatenate([np.zeros((3, 1)), np.cumsum(0.5 * (sig_total[:, 1:] + sig_total[:, :-1])
                                                       * np.diff(u), axis=1)], axis=1)
    return np.exp(-tau[:, -1]), np.trapezoid(np.exp(-tau) * source, u, axis=1)


# -- closed forms ------------------------------------------------------------------------------
def test_phi_has_no_cancellation_near_zero():
    y = np.array([0.0, 1e-9, 1e-6, 1e-4, 9.99e-3, 1.001e-2, 0.3, 1.0, 20.0, 200.0])
    got = np.array(A.phi(mi.Float(y)))
    ref = np.where(y > 0, -np.expm1(-y) / np.where(y > 0, y, 1), 1.0)
    assert np.all(np.abs(got / ref - 1) < 2e-6), got / ref - 1


# (z0, z1, t, ground, H): horizontal, near-horizontal, slanted down and up, crossing the
# ground level, steep and long (exp(+-x) would overflow in float32), all below ground.
COLUMNS = [(20, 20, 500, 0, 15), (20, 20.0001, 500, 0, 15), (1.0, 1.001, 1000, 0, 1),
           (20, 5, 300, 0, 15), (5, 300, 3000, 0, 15), (-10, 40, 100, 0, 15), (2000, 0, 2100, 0, 15),
           (0, 0, 20000, 0, 1200), (100, -50, 400, 10, 8000), (3000, 2950, 1e4, 0, 15),
           (-5, -5, 100, 0, 15), (900, 0, 5000, 0, 1200)]


def test_column_matches_quadrature():
    c = np.array(COLUMNS, float)
    got = np.array(A.column(mi.Float(c[:, 0]), mi.Float(c[:, 1]), mi.Float(c[:, 2]), mi.Float(c[:, 3]),
                            mi.Float(1.0 / c[:, 4])))
    assert np.all(np.isfinite(got))
    for case, v in zip(COLUMNS, got):
        ref = _column_quad(*case)
        assert abs(v - ref) <= 2e-6 * ref + 1e-30, (case, v, ref)


SUN = (np.array([0.3, 0.5, 0.6]) / np.linalg.norm([0.3, 0.5, 0.6]), np.array([1.2, 1.0, 0.8]))
AMBIENT = (0.05, 0.07, 0.1)


# The table's relative interpolation error as the sky_table docstring states it (15 skies,
# 100,000 directions each): 99th percentile 0.27 % for the worst sky, at most 0.81 % further
# than 5 degrees from the sun, 3.6 % within half a degree of it, 0.12 % on the horizon. The
# bounds below round these up (other random directions, other skies).
ERR_P99, ERR_AWAY_FROM_SUN, ERR_MAX = 0.003, 0.01, 0.04

SUNSKY = {"type": "sunsky", "sun_direction": [0.55, -0.45, 0.35], "turbidity": 3.0, "albedo": 0.3,
          "sun_scale": 1.0, "sky_scale": 1.0}
SKY_BOX = ([-3000.0, -3000.0, -50.0], [3000.0, 3000.0, 600.0])


def _segment(st, o, d, t, sky=False):
    """``(Tr, L_in)`` of a segment lit by ``SUN`` and ``AMBIENT`` or, with ``sky``, faded to ``SUNSKY``."""
    box = ([-1e5] * 3, [1e5] * 3)
    atm = A.Atmosphere.for_scene(st, [SUNSKY], box) if sky else A.Atmosphere(st, [SUN], AMBIENT, box)
    tr, L = atm.segment(mi.Point3f(*map(float, o)), mi.Vector3f(*map(float, d)), mi.Float(t))
    return np.array(tr).ravel(), np.array(L).ravel()


@pytest.mark.parametrize("z", [2.0, 20.0, 300.0])
def test_horizontal_segment_is_exact(z):
    """Horizontal: every component's density is constant, so the in-scatter is exact."""
    st = AtmosphereSettings(density=5.0, haze_density=0.002, haze_height=15.0)
    for t in (50.0, 500.0, 5000.0):
        tr, L = _segment(st, (0, 0, z), (1, 0, 0), t)
        tr_ref, L_ref = _reference(st, np.array([0, 0, z]), np.array([1.0, 0, 0]), t, [SUN], AMBIENT)
        assert np.all(np.abs(tr / tr_ref - 1) < 1e-5), (t, tr, tr_ref)
        assert np.all(np.abs(L / L_ref - 1) < 1e-4), (t, L, L_ref)


# Slanted segments through the haze layer: transmittance is exact; the in-scatter's
# optical-depth weighting is an approximation (module docstring). Its error at the physical
# density, measured against quadrature: < 0.15 % on segments up to 3 km, 1 % on a 5 km ray
# skimming the ground, 2 % on a 20 km ray climbing 2.8 km (bounds with some margin below).
SLANTED = [((0, 0, 20), (1, 0, -0.06), 300, 1e-3), ((0, 0, 2), (0.8, 0, 0.6), 3000, 1.5e-3),
           ((0, 0, 300), (1, 0, -0.3), 1000, 1.5e-3), ((0, 0, 20), (-0.2, -0.9, 0.01), 5000, 0.015),
           ((0, 0, 5), (0.99, 0, 0.14), 20000, 0.025)]


@pytest.mark.parametrize("o,d,t,tol", SLANTED)
def test_slanted_segment_against_quadrature(o, d, t, tol):
    st = AtmosphereSettings(density=1.0, haze_density=0.002, haze_height=15.0)
    d = np.array(d, float) / np.linalg.norm(d)
    tr, L = _segment(st, o, d, t)
    tr_ref, L_ref = _reference(st, np.array(o, float), d, t, [SUN], AMBIENT)
    assert np.all(np.abs(tr / tr_ref - 1) < 2e-5), (tr, tr_ref)
    assert np.all(np.abs(L / L_ref - 1) < tol), (L, L_ref)


@pytest.mark.parametrize("sky", [False, True])
def test_in_scatter_vanishes_with_density(sky):
    """Thin air: the in-scatter is linear in the density and exactly 0 at density 0, with suns
    (``phi(tau) sum tau_k omega_k S_k``) and with a sky (``tau phi(tau) L_bg``)."""
    prev = None
    # Optically thin from 1e-2 on (tau ~ 0.02): the in-scatter is linear in the density. At
    # 1e-8 (tau ~ 1e-8) a float32 1 - exp(-tau) would be 0 or 1.2e-7: phi keeps it linear.
    for s in (1e-2, 1e-4, 1e-6, 1e-8, 0.0):
        st = AtmosphereSettings(density=s, haze_density=0.002, haze_height=15.0)
        tr, L = _segment(st, (0, 0, 10), (0.9, 0, -0.02), 800.0, sky)
        if prev is not None and s > 0:
            assert np.allclose(L / prev, s / prev_s, rtol=0.02)
        prev, prev_s = L, s
    assert np.all(L == 0.0) and np.all(tr == 1.0)


# -- rendered walls at known distances ---------------------------------------------------------
# The field of view is narrow (0.1 degrees) and the test reads the central 2 x 2 pixels,
# whose rays are within 0.013 degrees of horizontal: at 500 m they span 0.1 m in height,
# so averaging them moves Tr by < 1e-4 even in a 10 m haze layer.
def _wall_camera(z, width=8, height=8):
    return {"type": "perspective", "fov": 0.1, "near_clip": 0.01, "far_clip": 1e5,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, z], target=[0, 1, z], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}}}


def _wall_to_world(z, distance):
    return (mi.ScalarTransform4f().translate([0, distance, z]).rotate([1, 0, 0], 90.0)
            .scale(0.01 * distance))


FOGGY = AtmosphereSettings(density=3.0, haze_density=0.0015, haze_height=10.0)


@pytest.mark.parametrize("z", [2.0, 25.0])
def test_rendered_transmittance_of_emissive_wall(z):
    """An emissive wall (radiance 1, black, the only light: nothing scatters into the air)
    seen horizontally at known distances: the image is exactly ``Tr(D)``, compared with the
    quadrature of the profile (1 %)."""
    for distance in (30.0, 120.0, 500.0):
        scene = mi.load_dict({"type": "scene", "integrator": {"type": "implicit_path", "max_depth": 3},
                              "sensor": _wall_camera(z),
                              "wall": {"type": "rectangle", "to_world": _wall_to_world(z, distance),
                                       "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                                       "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 1.0}}}})
        bbox = scene.bbox()
        scene.integrator().attach_atmosphere(A.Atmosphere(FOGGY, [], (0, 0, 0), (bbox.min, bbox.max)))
        img = render_image(scene, 4, seed=1)
        tau = sum(beta * _column_quad(z, z, distance, FOGGY.ground, h) for beta, h, _, _ in _components(FOGGY))
        expected = np.exp(-tau)
        assert 0.05 < expected.min() and expected.max() < 0.99  # Tr from 0.1 to 0.98: worth testing
        got = img[3:5, 3:5].reshape(-1, 3).mean(axis=0)
        assert np.all(np.abs(got / expected - 1) < 0.01), (distance, got, expected)


WALL = """
[render]
resolution = [8, 8]
max_depth = 3
[camera]
origin = [0.0, 0.0, {z}]
target = [0.0, 1.0, {z}]
fov = 0.1
[[lights]]
type = "directional"
direction = [0.0, 2.0, -1.0]
irradiance = 2.0
[materials.grey]
type = "diffuse"
color = 0.5
[[meshes]]
shape = "rectangle"
translate = [0.0, {distance}, {z}]
rotate = {{ axis = [1.0, 0.0, 0.0], angle = 90.0 }}
scale = {scale}
material = "grey"
[atmosphere]
density = 3.0
ground_albedo = 0.3
haze = {{ density = 0.0015, height = 10.0 }}
"""


@pytest.mark.parametrize("z", [2.0, 25.0])
def test_rendered_lit_wall_matches_analytic_aerial_perspective(z):
    """A constant-albedo wall lit by a directional sun, through the scene loader: beauty =
    ``Tr(D) L_wall + L_in(D)`` with ``L_wall = rho E cos / pi`` and ``L_in`` the quadrature of
    the single-scattering integral (1 %); the AOVs hold ``Tr`` and the fog-free wall."""
    s = np.array([0.0, -2.0, 1.0]) / math.sqrt(5.0)       # towards the sun
    e = np.full(3, 2.0)
    ambient = 2.0 * 0.3 * e * s[2] / (4.0 * math.pi)      # the ground's bounce light, lower half
    l_wall = 0.5 / math.pi * 2.0 * (2.0 / math.sqrt(5.0))
    share = []
    for distance in (30.0, 120.0, 500.0):
        desc = parse_scene(tomllib.loads(WALL.format(z=z, distance=distance, scale=0.01 * distance)),
                           SCENES / "wall.toml")
        rgb, layers = render_layers(build_scene(desc, aovs=True), 4, seed=1)
        tr, l_in = _reference(desc.atmosphere, np.array([0, 0, z]), np.array([0.0, 1.0, 0.0]), distance,
                              [(s, e)], ambient)
        expected = tr * l_wall + l_in
        share.append(l_in.min() / expected.min())
        got = rgb[3:5, 3:5].reshape(-1, 3).mean(axis=0)
        assert np.all(np.abs(got / expected - 1) < 0.01), (distance, got, expected)
        assert np.allclose(layers["transmittance"][0][3:5, 3:5].reshape(-1, 3).mean(axis=0), tr, rtol=0.01)
        assert np.allclose(layers["beauty_clear"][0][3:5, 3:5].reshape(-1, 3).mean(axis=0), l_wall, rtol=0.01)
    assert max(share) > 0.05  # the in-scatter matters at the far wall (a 1 % test sees it)


def test_rendered_shadow_rays_carry_transmittance():
    """A grey wall lit by a point light at the camera: light goes out and back over the same
    horizontal segment, and a point light scatters nothing into the air, so the image is
    ``rho I / (pi D^2) Tr(D)^2`` (1 %)."""
    for distance in (30.0, 120.0):
        text = (WALL.format(z=2.0, distance=distance, scale=0.01 * distance)
                .replace('type = "directional"\ndirection = [0.0, 2.0, -1.0]\nirradiance = 2.0',
                         'type = "point"\nposition = [0.0, 0.0, 2.0]\nintensity = 1000.0'))
        desc = parse_scene(tomllib.loads(text), SCENES / "wall.toml")
        img = render_image(build_scene(desc), 4, seed=1)
        tr, _ = _reference(desc.atmosphere, np.array([0, 0, 2.0]), np.array([0.0, 1.0, 0.0]), distance)
        expected = 0.5 / math.pi * 1000.0 / distance ** 2 * tr ** 2
        got = img[3:5, 3:5].reshape(-1, 3).mean(axis=0)
        assert tr.max() < 0.9 and np.all(np.abs(got / expected - 1) < 0.01), (distance, got, expected)


MINI = """
[render]
resolution = [40, 30]
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
type = "sphere"
center = [0.0, 0.0, 0.5]
radius = 1.0
"""


def test_fog_free_limit_and_absent_table():
    """Density -> 0: the image goes to the fog-free one linearly; density 0 gives its bits, and a
    scene without ``[atmosphere]`` attaches none (its kernels are the fog-free integrator's)."""
    plain_desc = parse_scene(tomllib.loads(MINI), SCENES / "mini.toml")
    assert plain_desc.atmosphere is None
    plain_scene = build_scene(plain_desc)
    assert plain_scene.integrator().atmosphere is None
    plain = render_image(plain_scene, 4, seed=1)
    diffs = []
    for s in (1e-2, 1e-4, 0.0):
        text = MINI + f"[atmosphere]\ndensity = {s}\nhaze = {{ density = 0.05, height = 1.0 }}\n"
        img = render_image(build_scene(parse_scene(tomllib.loads(text), SCENES / "mini.toml")), 4, seed=1)
        diffs.append(np.abs(img - plain).mean() / plain.mean())
    assert diffs[0] > 1e-3 and abs(diffs[1] / diffs[0] - 1e-2) < 2e-3
    assert diffs[2] == 0.0


def test_field_agrees_with_mesh_in_fog():
    """The default scene in dense low haze: sphere tracing and the marching-cubes mesh (both
    fogged by ``implicit_path``) agree within the cross-check allowances."""
    from helpers import assert_field_matches_mesh
    from arches_render.render.renderer import render_moments
    desc = load_scene(SCENES / "default.toml")
    desc.atmosphere = AtmosphereSettings(density=5.0, haze_density=0.004, haze_height=25.0)
    clear = load_scene(SCENES / "default.toml")
    clear.atmosphere = None
    w, h, spp = 96, 54, 32
    field_scene = build_scene(desc, "field", w, h, moments=True)
    mesh_scene = build_scene(desc, "mesh", w, h, moments=True)
    assert type(mesh_scene.integrator()).__name__ == "ImplicitPathIntegrator"
    # Two seeds: Welch's tests assume independent renders.
    field = render_moments(field_scene, spp, seed=1)
    mesh = render_moments(mesh_scene, spp, seed=2)
    assert_field_matches_mesh(field, mesh)
    # The fog is not negligible here (else the agreement says nothing about it).
    fogfree = render_image(build_scene(clear, "field", w, h), spp, seed=1)
    assert np.abs(field.mean - fogfree).mean() > 0.1 * fogfree.mean()


def test_sunsky_sources_follow_the_sky():
    """The sunsky's sun and sky, integrated apart, sum to the whole emitter; turbidity and
    ground albedo default to the sunsky's; more turbid skies bring denser aerosols."""
    sky = {"type": "sunsky", "sun_direction": [0.6, 0.0, 0.8], "turbidity": 4.0, "albedo": 0.2,
           "sun_scale": 1.0, "sky_scale": 1.0}
    suns, ambient = A.light_sources([sky], 0.0)
    (s, e_sun), = suns
    whole, _ = A._integrate_emitter(sky)
    assert np.allclose(e_sun + ambient * 4 * math.pi, whole, rtol=2e-3)
    desc = parse_scene(tomllib.loads(MINI.replace("elevation = 40.0", "elevation = 40.0\nturbidity = 6.0")
                                      + "[atmosphere]\n"), SCENES / "mini.toml")
    assert desc.atmosphere.turbidity == 6.0 and desc.atmosphere.ground_albedo == 0.3
    assert np.all(np.diff([A.aerosol_extinction(t)[1] for t in (2.0, 3.0, 6.0, 10.0)]) > 0)
    # Koschmieder's visibility at T = 3 is about 20 km (a clear day).
    sigma = A.aerosol_extinction(3.0)[1] + A.RAYLEIGH_BETA[1]
    assert 15e3 < 3.912 / sigma < 30e3


@pytest.mark.parametrize("table,key", [
    ("density = -1.0", "atmosphere.density"),
    ("turbidity = 12.0", "atmosphere.turbidity"),
    ("anisotropy = 1.0", "atmosphere.anisotropy"),
    ("aerosol_height = 0.0", "atmosphere.aerosol_height"),
    ("haze = { height = 5.0 }", "atmosphere.haze.density"),
    ("haze = { density = 0.01, hieght = 5.0 }", "atmosphere.haze.hieght"),
    ("fog = 1.0", "atmosphere.fog"),
])
def test_atmosphere_table_errors_name_the_key(table, key):
    with pytest.raises(SceneError) as err:
        parse_scene(tomllib.loads(MINI + "[atmosphere]\n" + table + "\n"), SCENES / "mini.toml")
    assert key in str(err.value)


def test_cli_layers_and_lookdev_edits_compile_nothing(tmp_path):
    """`render` writes the fog-free beauty and the transmittance as EXR layers; lookdev edits
    of the atmosphere and of the sun are parameter edits (no kernel compiled)."""
    from production_helpers import FLAT, assert_edits_compile_nothing, write_scene

    from arches_render import api
    from arches_render.cli import main
    from arches_render.imaging.exr import read_exr
    scene = write_scene(tmp_path, FLAT + "[atmosphere]\ndensity = 50.0\nhaze = { density = 0.02 }\n", "foggy")
    out = tmp_path / "foggy.exr"
    assert main(["render", str(scene), "-o", str(out), "--spp", "4", "-q"]) == 0
    img = read_exr(out)
    assert {"beauty_clear", "transmittance"} <= set(img.layers)
    tr = img.layers["transmittance"][0]
    assert np.all(np.isfinite(img.rgb)) and 0.0 < tr.min() and tr.max() < 0.9
    look = api.load(scene, resolution=(32, 18), spp=2)
    assert_edits_compile_nothing(look, {"atmosphere.density": 20.0, "atmosphere.haze.density": 0.05,
                                        "lights.0.elevation": 20.0}, look.render())
    assert look.rebuilds == 1


# -- with a sky: the haze fades to the sky (Koschmieder) ----------------------------------------
def _sky_atmosphere(st, light=SUNSKY, box=SKY_BOX):
    atm = A.Atmosphere.for_scene(st, [light], box)
    assert atm.sky is not None and atm.suns == []
    return atm


def _horizontal(azimuth_deg, dz=0.0):
    a = math.radians(azimuth_deg)
    d = np.array([math.cos(a), math.sin(a), dz])
    return d / np.linalg.norm(d)


def _rel(a, b):
    return np.abs(np.asarray(a) / np.asarray(b) - 1.0)


def test_sky_table_matches_the_emitter():
    """The table's bilinear value against Mitsuba's ``eval`` at random directions of the upper
    hemisphere (and below it: the horizon in their azimuth) within the error that the
    sky_table docstring states; a constant sky is exact."""
    rng = np.random.default_rng(5)
    n = 20000
    z = rng.uniform(0.0, 1.0, n)           # uniform over the hemisphere
    a = rng.uniform(0.0, 2.0 * math.pi, n)
    r = np.sqrt(1.0 - z * z)
    d = np.stack([r * np.cos(a), r * np.sin(a), z])
    for light in (SUNSKY, dict(SUNSKY, sun_direction=[-0.2, 0.1, 0.97], turbidity=6.0),
                  dict(SUNSKY, sun_direction=[0.3, 0.95, 0.08], turbidity=2.0)):
        table = S.SkyTable.for_lights([light])
        got = np.array(table.lookup(mi.Vector3f(d.astype(np.float32)))).reshape(3, -1)
        ref = S.emitter_radiance(S.sky_lights([light]), d)
        err = _rel(got, ref)
        s = np.asarray(light["sun_direction"]) / np.linalg.norm(light["sun_direction"])
        away = err[:, s @ d < math.cos(math.radians(5.0))]
        assert np.quantile(err, 0.99) < ERR_P99 and away.max() < ERR_AWAY_FROM_SUN and err.max() < ERR_MAX, \
            (np.quantile(err, 0.99), away.max(), err.max())
        # Below the horizon: the horizon in the same azimuth.
        below = np.array(table.lookup(mi.Vector3f(d[0], d[1], -d[2]))).reshape(3, -1)
        horizon = np.array(table.lookup(mi.Vector3f(d[0], d[1], 0.0))).reshape(3, -1)
        assert np.array_equal(below, horizon)
    constant = {"type": "constant", "radiance": {"type": "rgb", "value": [0.2, 0.5, 0.9]}}
    got = np.array(S.SkyTable.for_lights([constant]).lookup(mi.Vector3f(d.astype(np.float32)))).reshape(3, -1)
    assert np.allclose(got, np.array([0.2, 0.5, 0.9])[:, None], rtol=1e-6)


@pytest.mark.parametrize("azimuth,dz", [(17.0, 0.0), (-123.4, 0.0), (71.3, -0.04)])
def test_long_horizontal_segment_fades_to_the_horizon(azimuth, dz):
    """``L_in = (1 - Tr) L_bg(d)`` at every length (float rounding), and towards the horizon
    radiance in the ray's azimuth, as Mitsuba's sky gives it (the table's error), as the
    segment grows; a downward ray fades to the horizon in its azimuth."""
    st = AtmosphereSettings(density=3.0, haze_density=0.0015, haze_height=10.0)
    atm = _sky_atmosphere(st)
    d = _horizontal(azimuth, dz)
    o = mi.Point3f(0.0, 0.0, 12.0)
    horizon = S.emitter_radiance(S.sky_lights([SUNSKY]), _horizontal(azimuth)[:, None]).ravel()
    bg = np.array(atm.sky.lookup(mi.Vector3f(*map(float, d)))).ravel()
    assert np.all(_rel(bg, horizon) < ERR_AWAY_FROM_SUN)
    trs = []
    for t in (30.0, 300.0, 3000.0, 3e5):
        tr, L = atm.segment(o, mi.Vector3f(*map(float, d)), mi.Float(t))
        tr, L = np.array(tr).ravel(), np.array(L).ravel()
        # 1e-5: float32 rounding of tau phi(tau) against 1 - exp(-tau) in float64.
        assert np.all(_rel(L, (1.0 - tr) * bg) < 1e-5), (t, L, (1.0 - tr) * bg)
        trs.append(tr)
    assert 0.2 < trs[1].min() < 0.9 and trs[-1].max() < 1e-6  # intermediate, then fully fogged
    assert np.all(_rel(L, horizon) < ERR_AWAY_FROM_SUN), (L, horizon)


def _sky_camera(width=48, height=24):
    # Looking away from the sun (azimuth ~ -140 deg), pitched up 17 deg: a 60 x 31 degree view
    # whose lowest rays are 1.5 degrees above the horizon.
    a, p = math.radians(-140.0), math.radians(17.0)
    target = [math.cos(a) * math.cos(p), math.sin(a) * math.cos(p), 10.0 + math.sin(p)]
    return {"type": "perspective", "fov": 60.0,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 10.0], target=target, up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}}}


def test_rays_that_leave_the_scene_see_the_sky():
    """A scene of sky alone, fogged up to a 3 km box: the image is the fog-free sky (within
    the table's error, as ``L_sky Tr + (1 - Tr) L_bg``), although the rays near the horizon
    leave the box through thick haze (``Tr`` < 0.2)."""
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "implicit_path", "max_depth": 3},
                          "sensor": _sky_camera(), "light": SUNSKY})
    clear = render_image(scene, 4, seed=1)
    st = AtmosphereSettings(density=3.0, haze_density=0.0015, haze_height=10.0)
    atm = _sky_atmosphere(st)
    scene.integrator().attach_atmosphere(atm)
    fogged = render_image(scene, 4, seed=1)
    # The fog is thick where the rays graze the horizon (else the test says nothing).
    low = _horizontal(-140.0, math.tan(math.radians(1.5)))
    o, d = mi.Point3f(0.0, 0.0, 10.0), mi.Vector3f(*map(float, low))
    assert np.array(atm.transmittance(o, d, atm.exit_distance(o, d))).max() < 0.2
    err = _rel(fogged, clear)
    assert err.max() < ERR_AWAY_FROM_SUN, err.max()  # the sun is 100 degrees off the view


def test_a_white_ground_under_a_uniform_sky_is_a_furnace_in_any_haze():
    """A white Lambertian ground under a constant sky of radiance C: without air it has
    radiance C everywhere, and with the sky as the haze's background it still must,
    whatever the density (every path sees ``C Tr + (1 - Tr) C``). The in-scatter of the
    segment a path takes next is counted once, by the path; next-event shadow rays carry
    the sky's ``C Tr`` alone (adding the in-scatter to them too came out 11 % bright
    here). The haze is dense (``Tr`` to the box's exit below 0.5 at 15 degrees above the
    ground)."""
    sky = {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    ground = {"type": "disk", "to_world": mi.ScalarTransform4f().scale(2000.0),
              "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}}
    camera = {"type": "perspective", "fov": 40.0,
              "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 10.0], target=[0, 20.0, 0], up=[0, 0, 1]),
              "film": {"type": "hdrfilm", "width": 24, "height": 16, "rfilter": {"type": "box"}}}
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "implicit_path", "max_depth": 4},
                          "sensor": camera, "light": sky, "ground": ground})
    box = ([-2000.0, -2000.0, -1.0], [2000.0, 2000.0, 300.0])
    atm = _sky_atmosphere(AtmosphereSettings(density=3.0, haze_density=0.004, haze_height=60.0), sky, box)
    o, d = mi.Point3f(0.0, 0.0, 0.0), mi.Vector3f(*map(float, _horizontal(90.0, math.tan(math.radians(15.0)))))
    assert np.array(atm.transmittance(o, d, atm.exit_distance(o, d))).max() < 0.5
    scene.integrator().attach_atmosphere(atm)
    img = render_image(scene, 256, seed=3)
    # 24 x 16 pixels x 256 samples of a cosine-weighted ground: the mean's noise is ~0.2 %.
    assert abs(float(img.mean()) - 1.0) < 0.01, img.mean()
