"""Surface cells (issue 32): air cells hold no surface, rock cells no air, for every
footprint of their class; the cell tracer finds the sphere tracer's hits; memory
follows the surface."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render import field as F  # noqa: E402
from arches_render.field.lod import Footprint  # noqa: E402
from arches_render.field.surface_cells import SurfaceCells  # noqa: E402
from arches_render.render.cell_tracer import CellTracer  # noqa: E402
from arches_render.render.cover_tracer import CoverTracer  # noqa: E402
from arches_render.render.sphere_tracer import SphereTracer  # noqa: E402

from test_terrain_field_nodes import SCULPTED, TREE  # noqa: E402


def _arch():
    x = np.linspace(0, 1, 65)
    X, Y = np.meshgrid(x, x)
    ground = F.Heightfield(6 * np.sin(5 * X) * np.cos(3 * Y) + 3 * X, (-40, -40, 40, 40))
    caps = [F.Capsule([-15, 0, 0], [-8, 0, 14], 3.0), F.Capsule([-8, 0, 14], [8, 0, 15], 2.5),
            F.Capsule([8, 0, 15], [15, 0, 0], 3.0)]
    arch = F.Displace(F.Blend(*caps, radius=2.0), amplitude=0.6, wavelength=3.0, octaves=3, seed=1)
    return F.Blend(ground, arch, radius=2.0)


TREES = {"arch": _arch(), "sculpted": SCULPTED, "carved": TREE}


def _vec(a, cls):
    a = np.asarray(a, np.float32)
    return cls(*(mi.Float(np.ascontiguousarray(a[:, i])) for i in range(3)))


@pytest.mark.parametrize("name", sorted(TREES))
def test_air_cells_hold_no_surface_and_rock_no_air(name):
    tracer = CellTracer(TREES[name])
    cells, field = tracer.cells, tracer.field
    lo, hi = np.asarray(tracer.sphere.lo), np.asarray(tracer.sphere.hi)
    pts = np.random.default_rng(1).uniform(lo, hi, (400_000, 3))
    p = _vec(pts, mi.Point3f)
    air, solid, _, _, _ = cells.lookup(p)
    air, solid = air.numpy(), solid.numpy()
    assert (air > 0).mean() > 0.2 and (solid > 0).mean() > 0.05
    for k, radius in enumerate(cells.radii, 1):
        for fp in (None, Footprint(mi.Float(radius), mi.Float(0.0)), Footprint(mi.Float(0.3 * radius), mi.Float(0.0))):
            f = field.eval_bounds(p, (), footprint=fp)[0].numpy()
            assert np.all(f[air >= k] < -cells.slack + 1e-4), (k, fp)
            assert np.all(f[solid >= k] > -1e-4), (k, fp)
    if name == "arch":
        # Memory follows the surface: most bricks (air above, rock below) hold no leaf.
        assert cells.stats["stored_bricks"] < 0.5 * len(cells.layout.slots_np)


def _grazes(sphere, o, d, t, cone, lanes):
    """Whether each ray of ``lanes`` only grazes the surface around ``t``: its value stays
    below 0 on ``[t - 8 tol, t + 0.5]`` (sampled every tenth of the tolerance), so a
    hit there is one within the tolerance, which tracers whose steps differ may find or
    step over alike (a crossing would reach ``f >= 0`` within a few tolerances)."""
    out = []
    for i in lanes:
        # (The test's cones start at a point: r0 = 0.)
        c = None if cone is None else (mi.Float(0.0), mi.Float(float(cone[1].numpy()[i])))
        tol = float(sphere.tolerance(mi.Float(float(t[i])), c).numpy()[0])
        ts = np.arange(t[i] - 8 * tol, t[i] + 0.5, 0.1 * tol)
        p = _vec(o[i] + d[i] * ts[:, None], mi.Point3f)
        fp = sphere.footprint(None if c is None else (c[0] + 0.0 * p.x, c[1] + 0.0 * p.x), mi.Float(ts.astype(np.float32)))
        out.append(np.max(sphere.field.eval_bounds(p, (), footprint=fp)[0].numpy()) < 0.0)
    return np.asarray(out, dtype=bool)


@pytest.mark.parametrize("structure", [CellTracer, CoverTracer])
@pytest.mark.parametrize("name", sorted(TREES))
def test_structure_tracers_find_the_sphere_tracers_hits(name, structure):
    """Cells jumped over (CellTracer) or a cover's free stretches (CoverTracer) hold no
    hit: both tracers agree on every ray but those that only graze the surface within
    the hit tolerance, where their different steps may find the graze or step over it."""
    root = TREES[name]
    sphere, cells = SphereTracer(root), structure(root)
    lo, hi = np.asarray(sphere.lo), np.asarray(sphere.hi)
    rng = np.random.default_rng(2)
    n = 6000
    o = rng.uniform(lo, hi, (n, 3))
    o[: n // 2, 2] = hi[2] + rng.uniform(1, 30, n // 2)      # half from above the scene
    target = rng.uniform(lo, hi, (n, 3))
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    O, D = _vec(o, mi.Point3f), _vec(d, mi.Vector3f)
    rate = mi.Float(rng.uniform(0.0, 0.05, n).astype(np.float32))
    for cone in (None, (mi.Float(0.0), rate)):
        a = sphere.query(O, D, mi.Float(1e5), mi.Bool(True), cone)
        b = cells.query(O, D, mi.Float(1e5), mi.Bool(True), cone)
        ha, hb, ta, tb = a.hit.numpy(), b.hit.numpy(), a.t.numpy(), b.t.numpy()
        assert not b.unresolved.numpy().any()
        # Both stop within the hit tolerance of the surface (their steps differ).
        tol = sphere.tolerance(mi.Float(np.maximum(ta, tb)), cone).numpy()
        differ = (ha != hb) | (ha & hb & (np.abs(ta - tb) > 4.0 * tol + 1e-4))
        assert differ.mean() < 1e-3
        # Where they differ, the first of their hits is a graze, not a crossing.
        first = np.where(ha & (~hb | (ta < tb)), ta, tb)
        lanes = np.flatnonzero(differ)
        assert _grazes(sphere, o, d, first, cone, lanes).all(), lanes
        # Shadow rays: occluded exactly where a first hit lies within tmax (the rock
        # probes only shortcut what the march would find), grazes aside.
        tmax = rng.uniform(1.0, 60.0, n).astype(np.float32)
        sa = sphere.query(O, D, mi.Float(tmax), mi.Bool(True), cone)
        blocked = cells.query(O, D, mi.Float(tmax), mi.Bool(True), cone, any_hit=True)
        lanes = np.flatnonzero(sa.hit.numpy() != blocked.hit.numpy())
        assert len(lanes) < 1e-3 * n
        t_either = np.where(sa.hit.numpy(), sa.t.numpy(), blocked.t.numpy())
        assert _grazes(sphere, o, d, t_either, cone, lanes).all(), lanes


@pytest.mark.parametrize("structure", [CellTracer, CoverTracer])
def test_jumps_replace_field_evaluations(structure):
    """Rays from far above a terrain jump over the air instead of stepping through it."""
    root = TREES["arch"]
    sphere, cells = SphereTracer(root), structure(root)
    n = 2000
    rng = np.random.default_rng(5)
    o = np.column_stack([rng.uniform(-35, 35, (n, 2)), np.full(n, 60.0)])
    d = np.column_stack([rng.uniform(-0.3, 0.3, (n, 2)), -np.ones(n)])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    O, D = _vec(o, mi.Point3f), _vec(d, mi.Vector3f)
    a = sphere.query(O, D, mi.Float(1e5), mi.Bool(True))
    b = cells.query(O, D, mi.Float(1e5), mi.Bool(True))
    dr.eval(a.steps, b.steps, b.cells)
    assert b.cells.numpy().mean() >= 1.0
    assert b.steps.numpy().mean() < a.steps.numpy().mean()


def test_structure_rejects_bad_classes():
    with pytest.raises(ValueError):
        SurfaceCells(TREES["arch"], [-1, -1, -1], [1, 1, 1], 0.1, classes=())
