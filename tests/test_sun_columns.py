"""Sun columns (issue 32): the map's tops hold no surface above them and its rock slices no
air; shadow rays towards the sun keep their answers with fewer steps; rays off the sun's
disk are not touched; the renderer gives its tracer the scene's sun when the scene asks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.render.sphere_tracer import SphereTracer  # noqa: E402
from arches_render.render.sun_columns import SUN_HALF_ANGLE, disk_directions, scene_sun, sun_frame  # noqa: E402

from test_surface_cells import TREES, _vec  # noqa: E402

#: Towards a low sun, and straight up (the frame's other helper axis).
SUNS = {"low": np.array([0.45, -0.55, 0.45]), "zenith": np.array([0.0, 0.0, 1.0])}


def _aimed(name, sun, half_angle=SUN_HALF_ANGLE, max_steps=512):
    tracer = SphereTracer(TREES[name], max_steps=max_steps)
    tracer.aim_at_sun(sun, half_angle)
    return tracer


def _cylinder_points(m, columns, w_lo, w_hi, rng):
    """Random points in the cylinders of ``columns`` between heights ``w_lo`` and ``w_hi``."""
    iu, iv = columns // m.nv, columns % m.nv
    u = m.u0 + (iu + 0.5) * m.s
    v = m.v0 + (iv + 0.5) * m.s
    radius = m.rho * np.sqrt(rng.random(len(columns)))
    phi = rng.uniform(0.0, 2.0 * np.pi, len(columns))
    w = rng.uniform(w_lo, w_hi)
    u, v = u + radius * np.cos(phi), v + radius * np.sin(phi)
    return u[:, None] * m.e1 + v[:, None] * m.e2 + w[:, None] * m.a


@pytest.mark.parametrize("sun", sorted(SUNS))
@pytest.mark.parametrize("name", sorted(TREES))
def test_tops_hold_no_surface_above_them_and_rock_slices_no_air(name, sun):
    tracer = _aimed(name, SUNS[sun])
    m = tracer.sun
    tol = tracer.eps_np * tracer.scale
    top = m.levels[0][0].ravel()
    rng = np.random.default_rng(3)
    lo, hi = np.asarray(tracer.lo), np.asarray(tracer.hi)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    w_box = float((corners @ m.a).max())
    full = np.nonzero(np.isfinite(top))[0]
    assert len(full) > 0.2 * len(top)  # tops found
    columns = rng.choice(full, 300_000)
    pts = _cylinder_points(m, columns, top[columns], np.maximum(top[columns], w_box), rng)
    inside = np.all((pts >= lo) & (pts <= hi), axis=1)
    f = tracer.field.eval_bounds(_vec(pts[inside], mi.Point3f), ())[0].numpy()
    assert np.all(f < -tol), f.max()
    # The tops are close: within a few cylinder radii of the surface in most columns.
    near = _cylinder_points(m, columns, top[columns] - 4 * m.rho, top[columns], rng)
    f_near = tracer.field.eval_bounds(_vec(near, mi.Point3f), ())[0].numpy()
    assert np.mean(f_near > -tol) > 0.02
    rock = np.nonzero(np.isfinite(m.solid_lo))[0]
    if name == "arch":  # its ground is rock under every top (the carved caves' bounds prove none)
        assert len(rock) > 0.05 * len(top)
    if not len(rock):
        return
    columns = rng.choice(rock, 300_000)
    pts = _cylinder_points(m, columns, m.solid_lo[columns], m.solid_hi[columns], rng)
    f = tracer.field.eval_bounds(_vec(pts, mi.Point3f), ())[0].numpy()
    assert np.all(f > 0.0), f.min()


def _surface_points(tracer, n, rng):
    """Points lifted off the surface (hits of rays from above the scene) and their normals."""
    lo, hi = np.asarray(tracer.lo), np.asarray(tracer.hi)
    o = rng.uniform(lo, hi, (n, 3))
    o[:, 2] = hi[2] + 5.0
    target = rng.uniform(lo, hi, (n, 3))
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    res = tracer.query(_vec(o, mi.Point3f), _vec(d, mi.Vector3f), mi.Float(1e5), mi.Bool(True))
    dr.eval(res.hit, res.t)
    p, normal = tracer.surface(_vec(o, mi.Point3f) + _vec(d, mi.Vector3f) * res.t, res.t, _vec(d, mi.Vector3f))
    hit = res.hit.numpy()
    lifted = p + normal * 1e-3
    dr.eval(lifted, normal)  # one kernel, not one a coordinate
    pts = np.stack([c.numpy() for c in (lifted.x, lifted.y, lifted.z)], 1)
    nrm = np.stack([c.numpy() for c in (normal.x, normal.y, normal.z)], 1)
    return pts[hit], nrm[hit]


# 0.1 rad: a wide light, whose rays drift by several columns over the scene (the
# drift terms of the caps are what keep those answers).
@pytest.mark.parametrize("half_angle", [SUN_HALF_ANGLE, 0.0, 0.1])
@pytest.mark.parametrize("name", sorted(TREES))
def test_shadow_rays_towards_the_sun_keep_their_answers_in_fewer_steps(name, half_angle):
    sun = SUNS["low"]
    # A short budget: the few rays of the carved caves that use up both budgets (with or
    # without the map) would otherwise take most of the test's time.
    plain, aimed = SphereTracer(TREES[name], max_steps=64), _aimed(name, sun, half_angle, max_steps=64)
    rng = np.random.default_rng(4)
    pts, _ = _surface_points(plain, 4000, rng)
    d = disk_directions(sun, half_angle, len(pts), rng)
    O, D = _vec(pts, mi.Point3f), _vec(d, mi.Vector3f)
    a = plain.query(O, D, mi.Float(dr.inf), mi.Bool(True), any_hit=True)
    b = aimed.query(O, D, mi.Float(dr.inf), mi.Bool(True), any_hit=True)
    t_cap, rock = aimed.sun.limits(O, D, mi.Float(dr.inf))
    dr.eval(a, b, t_cap, rock)
    # Rays the plain tracer resolved get the same answer; the map never leaves a ray
    # unresolved that was not (the carved caves hold a few rays that use up both budgets
    # without it: some finish with it, since it shortens them).
    resolved = ~a.unresolved.numpy()
    assert np.array_equal(a.hit.numpy()[resolved], b.hit.numpy()[resolved])
    assert not (b.unresolved.numpy() & resolved).any()
    steps_a, steps_b = a.steps.numpy(), b.steps.numpy()
    assert np.all(steps_b <= steps_a)
    assert steps_b.mean() < 0.97 * steps_a.mean()
    assert np.isfinite(t_cap.numpy()).mean() > 0.5
    if name == "arch" and half_angle <= SUN_HALF_ANGLE:  # points under the arch: rays through its rock
        assert rock.numpy().sum() > 10
        assert np.all(a.hit.numpy()[rock.numpy()])


def test_rays_off_the_sun_or_from_outside_the_box_are_not_helped():
    tracer = _aimed("arch", SUNS["low"])
    rng = np.random.default_rng(5)
    pts, _ = _surface_points(tracer, 4000, rng)
    off = disk_directions(SUNS["low"], 1.0 * SUN_HALF_ANGLE, len(pts), rng)
    # Tilt every direction 2 sun radii further off the axis.
    e1, _ = sun_frame(SUNS["low"])
    d = off + math.tan(2.0 * SUN_HALF_ANGLE) * e1
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t_cap, rock = tracer.sun.limits(_vec(pts, mi.Point3f), _vec(d, mi.Vector3f), mi.Float(dr.inf))
    assert np.all(np.isinf(t_cap.numpy())) and not rock.numpy().any()
    # Nor rays from outside the box, whose tolerance grows past what the tops keep clear of.
    outside = pts - 200.0 * SUNS["low"] / np.linalg.norm(SUNS["low"])
    sun = np.tile(SUNS["low"] / np.linalg.norm(SUNS["low"]), (len(pts), 1))
    t_cap, rock = tracer.sun.limits(_vec(outside, mi.Point3f), _vec(sun, mi.Vector3f), mi.Float(dr.inf))
    assert np.all(np.isinf(t_cap.numpy())) and not rock.numpy().any()


def test_the_renderer_aims_its_tracer_at_the_scenes_sun():
    assert scene_sun([{"type": "constant"}]) is None
    direction, radius = scene_sun([{"type": "point"}, {"type": "directional", "direction": [0, 0, -2]}])
    assert np.allclose(direction, [0, 0, 2]) and radius == 0.0
    direction, radius = scene_sun([{"type": "sunsky", "sun_direction": [0.1, 0.2, 0.9]}])
    assert np.allclose(direction, [0.1, 0.2, 0.9]) and radius == SUN_HALF_ANGLE
    from arches_render.render.renderer import build_scene
    from arches_render.scene import load_scene
    from arches_render.timing import REPO
    desc = load_scene(REPO / "scenes" / "gallery" / "fig23_arch_bridge.toml")
    assert build_scene(desc, "field", 32, 18).integrator().tracer.sun is None  # opt-in
    desc.render.sun_columns = True
    tracer = build_scene(desc, "field", 32, 18).integrator().tracer
    assert tracer.sun is not None
    assert np.allclose(tracer.sun.a, scene_sun(desc.lights)[0] / np.linalg.norm(scene_sun(desc.lights)[0]))
