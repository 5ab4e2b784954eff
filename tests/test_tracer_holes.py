"""The tracers' conservative answers where they cannot prove a miss (issue 32, part 4).

Each test creates the condition a read-only review found unhandled and checks that the
ray is counted unresolved and resolved as a hit (a shadow ray occluded), never
returned as a miss, which would show the sky through rock or let light through it:

(a) a pure heightfield cast stopped by its iteration guard;
(b) a NaN field value, in the sphere tracer and in the hybrid caster's sphere steps;
(c) a hybrid lane stopped by the cast's guard (it used to repeat one cast until the
    round limit);
(d) a ray whose budget runs out reports its verified frontier, not a relaxed point
    beyond it;
(e) a pure cast counts its cell visits apart from sphere steps;
(f) a ray starting exactly on the surface (tolerance 0 at t = 0) stops at once.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render import field as F  # noqa: E402
from arches_render.render.heightfield_caster import HeightfieldCaster, make_tracer  # noqa: E402
from arches_render.render.march import SECOND_PASS_FACTOR  # noqa: E402
from arches_render.render.mipmap_traversal import MipmapTraversal  # noqa: E402
from arches_render.render.sphere_tracer import SphereTracer  # noqa: E402


def _rays(o, d):
    o, d = np.asarray(o, np.float32), np.asarray(d, np.float32)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    return (mi.Point3f(*(mi.Float(np.ascontiguousarray(o[:, i])) for i in range(3))),
            mi.Vector3f(*(mi.Float(np.ascontiguousarray(d[:, i])) for i in range(3))))


def _query(tracer, o, d, tmax=1e4, any_hit=False):
    r = tracer.query(o, d, mi.Float(tmax), mi.Bool(True), any_hit=any_hit)
    dr.eval(r.hit, r.t, r.steps, r.unresolved, r.exhausted, r.cells)
    return {k: getattr(r, k).numpy() for k in ("hit", "t", "steps", "unresolved", "exhausted", "cells")}


def _terrain():
    x = np.linspace(0.0, 1.0, 65)
    X, Y = np.meshgrid(x, x)
    return F.Heightfield(2.0 * np.sin(7 * X) * np.cos(5 * Y), (-32.0, -32.0, 32.0, 32.0))


def _long_rays(n=64):
    """Rays from one side of the terrain to the other, a little above it (many cells)."""
    y = np.linspace(-28.0, 28.0, n)
    o = np.column_stack([np.full(n, -31.0), y, np.full(n, 2.5)])
    d = np.column_stack([np.ones(n), np.zeros(n), np.full(n, -0.02)])
    return _rays(o, d)


@pytest.fixture
def guard_of_three(monkeypatch):
    monkeypatch.setattr(MipmapTraversal, "max_iterations", property(lambda self: 3))


def test_a_pure_cast_stopped_by_its_guard_is_unresolved_not_a_miss(guard_of_three):
    tracer = make_tracer(_terrain())
    assert isinstance(tracer, HeightfieldCaster) and not tracer.hybrid
    o, d = _long_rays()
    for any_hit in (False, True):
        r = _query(tracer, o, d, any_hit=any_hit)
        assert r["unresolved"].all() and r["hit"].all() and r["exhausted"].all()
        # Reported at the point the cast proved free up to, inside the terrain's box.
        assert np.all(np.isfinite(r["t"])) and np.all(r["t"] < 70.0)


class _NanBall(F.Sphere):
    """A ball whose value is NaN in the slab ``|x| < 0.5`` (a node bug, or a bad input)."""

    def eval(self, p):
        return dr.select(dr.abs(p.x) < 0.5, dr.nan, super().eval(p))


def test_a_nan_field_value_is_unresolved_not_a_miss():
    tracer = SphereTracer(F.Union(_NanBall([0.0, 0.0, 0.0], 3.0), F.Sphere([0.0, 40.0, 0.0], 1.0)))
    o, d = _rays([[-10.0, 0.2, 0.1]] * 4 + [[-10.0, 20.0, 0.0]], [[1.0, 0.0, 0.0]] * 4 + [[1.0, 0.0, 0.0]])
    r = _query(tracer, o, d)
    # The first four rays meet the ball's surface at x = -3 first: plain hits.
    assert r["hit"][:4].all() and not r["unresolved"][:4].any()
    # Rays along the NaN slab prove nothing from where they enter the field's box.
    o, d = _rays([[0.0, -10.0, 0.1], [0.2, -10.0, 1.0]], [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    r = _query(tracer, o, d)
    assert r["unresolved"].all() and r["hit"].all(), r
    assert np.all(r["t"] <= 7.0)  # resolved where nothing was proven: before the ball
    assert np.all(r["steps"] == 1)


def test_a_nan_in_the_hybrid_casters_sphere_steps_is_unresolved_not_a_miss():
    root = F.Union(_terrain(), _NanBall([0.0, 0.0, 6.0], 2.0))
    tracer = make_tracer(root)
    assert isinstance(tracer, HeightfieldCaster) and tracer.hybrid
    o, d = _rays([[0.0, -20.0, 6.0], [0.2, -20.0, 6.3]], [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    for any_hit in (False, True):
        r = _query(tracer, o, d, any_hit=any_hit)
        assert r["unresolved"].all() and r["hit"].all(), r
        # Resolved before the NaN slab is crossed, at or before the ball's near side.
        assert np.all(r["t"] <= 18.0 + 1e-3)


def test_a_hybrid_lane_at_the_cast_guard_is_unresolved_at_once(guard_of_three):
    root = F.Union(_terrain(), F.Sphere([0.0, 0.0, 30.0], 1.0))
    tracer = make_tracer(root)
    assert isinstance(tracer, HeightfieldCaster) and tracer.hybrid
    o, d = _long_rays()
    r = _query(tracer, o, d)
    assert r["unresolved"].all() and r["hit"].all()
    # One capped cast, not a cast repeated up to the round limit.
    assert np.all(r["cells"] <= 3 + 4), r["cells"].max()


def test_an_unresolved_ray_reports_its_verified_frontier():
    """Grazing rays over a plane-like slab exhaust a tiny budget; the point each reports
    must lie before the thin wall across their way (a relaxed point may lie past it)."""
    wall_x = 3.0
    root = F.Union(F.Box([0.0, 0.0, -1.0], [50.0, 50.0, 1.0]), F.Box([wall_x, 0.0, 5.0], [0.002, 50.0, 5.0]))
    rng = np.random.default_rng(4)
    n = 400
    o = np.column_stack([rng.uniform(-5.0, 2.9, n), rng.uniform(-5, 5, n), rng.uniform(1e-3, 0.05, n)])
    d = np.column_stack([np.ones(n), rng.uniform(-0.1, 0.1, n), rng.uniform(-1e-3, 1e-3, n)])
    O, D = _rays(o, d)
    for omega in (1.6, 1.95):
        r = _query(SphereTracer(root, omega=omega, max_steps=1), O, D)
        u = r["unresolved"]
        assert u.mean() > 0.5
        dn = d / np.linalg.norm(d, axis=1, keepdims=True)
        x_at = o[u, 0] + dn[u, 0] * r["t"][u]
        assert np.all(x_at <= wall_x - 0.002 + 1e-4), x_at.max()
        assert np.all(r["steps"][u] == 1 + SECOND_PASS_FACTOR)


def test_a_pure_cast_counts_cells_not_steps():
    tracer = make_tracer(_terrain())
    o, d = _long_rays()
    r = _query(tracer, o, d)
    assert np.all(r["steps"] == 0) and np.all(r["cells"] > 3)
    assert not r["exhausted"].any() and not r["unresolved"].any()


@pytest.mark.parametrize("hybrid", [False, True])
def test_a_ray_starting_exactly_on_the_surface_stops_at_once(hybrid):
    box = F.Box([0.0, 0.0, 0.0], [2.0, 2.0, 2.0])
    tracer = make_tracer(F.Union(_terrain(), F.Transform.translate(box, [0.0, 0.0, 10.0]))) if hybrid \
        else SphereTracer(box)
    z = 12.0 if hybrid else 2.0   # exactly on the box's top face: f = 0, tolerance 0 at t = 0
    o, d = _rays([[0.5, 0.25, z], [-1.0, 1.0, z]], [[0.3, 0.1, -1.0], [0.0, 0.0, -1.0]])
    r = _query(tracer, o, d)
    assert r["hit"].all() and not r["unresolved"].any() and np.all(r["t"] == 0.0), r
    assert np.all(r["steps"] <= 2)
