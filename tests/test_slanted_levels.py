"""Slanted levels: a terrain summed with steep sculpting primitives steps by the
primitives' geometry near their walls (generators/terrain/skeletal_bounds.py,
"Slanted levels"; the sum in generators/terrain/operators.py).

* Free: no point of a ball (or two-sided segment) the sum declares free near the
  pillars' walls holds matter, at full detail and at footprints.
* Not vacuous: near the walls the bound is several times Hart's with the sum's
  local slopes, which is all the sum had before.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.field import evaluate  # noqa: E402
from arches_render.field.lod import Footprint  # noqa: E402
from test_terrain_field_nodes import PILLARS, SCULPTED  # noqa: E402


def _points(arr):
    arr = np.asarray(arr, dtype=np.float32)
    return mi.Point3f(*(mi.Float(arr[:, i]) for i in range(3)))


def _near_walls(n=3000, seed=4):
    """Points in the air around the pillars, within their supports, where the
    pillars' field is steep: ``-f`` between 0 and 8 (the terrain's T is 10)."""
    rng = np.random.default_rng(seed)
    k = rng.integers(0, PILLARS.n, 40 * n)
    a, b = PILLARS.a_np[k], PILLARS.b_np[k]
    s = a + (b - a) * rng.uniform(0, 1, (len(k), 1))
    v = rng.normal(size=(len(k), 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    R, c = PILLARS.radius_np[k], PILLARS.core_np[k]
    p = s + v * (c + R * rng.uniform(0.0, 1.3, len(k)))[:, None]
    f = evaluate(SCULPTED, p)
    keep = (f < 0) & (f > -8) & (evaluate(PILLARS, p) > 0)
    assert keep.sum() >= n
    return p[keep][:n]


def _bounds(p, direction=None, footprint=None, slants=True, monkeypatch=None):
    if not slants:
        monkeypatch.setattr(type(SCULPTED), "_steep_child", lambda self: None)
    dv = None if direction is None else mi.Vector3f(*(float(x) for x in direction))
    f, (d,) = SCULPTED.eval_bounds(_points(p), (0.0,), dv, footprint)
    dr.eval(f, d)
    return f.numpy().astype(np.float64), d.numpy().astype(np.float64)


def _footprint(p, rate):
    r = 0.05 + rate * np.linalg.norm(p - np.array([50.0, -40.0, 60.0]), axis=1)
    return Footprint(mi.Float(r.astype(np.float32)), mi.Float(np.full(len(r), rate, np.float32)))


def _field(p, footprint_rate):
    if footprint_rate is None:
        return evaluate(SCULPTED, p)
    f = SCULPTED.eval_bounds(_points(p), (), footprint=_footprint(p, footprint_rate))[0]
    dr.eval(f)
    return f.numpy().astype(np.float64)


def _in_the_air(n=3000, seed=5):
    """Points in the air among the pillars, outside every support: the bounds there
    were capped at the near lists' reach (a quarter cell edge) before the unlisted gaps."""
    rng = np.random.default_rng(seed)
    lo, hi = PILLARS.support()
    p = rng.uniform(lo, hi, (40 * n, 3))
    keep = (evaluate(PILLARS, p) <= 0) & (evaluate(SCULPTED, p) < 0)
    assert keep.sum() >= n
    return p[keep][:n]


@pytest.mark.parametrize("rate", [None, 0.1])
@pytest.mark.parametrize("direction", [None, (0.6, -0.7, -0.39), (0.0, 0.0, 1.0)])
@pytest.mark.parametrize("where", ["walls", "air"])
def test_sum_bounds_among_pillars_are_free(where, rate, direction):
    """Near the pillars' walls (slanted levels) and in the air among them (level
    bounds that step past the near lists by the cells' unlisted gaps)."""
    p = _near_walls() if where == "walls" else _in_the_air()
    fp = None if rate is None else _footprint(p, rate)
    if direction is not None:
        direction = np.asarray(direction) / np.linalg.norm(direction)
    _, d = _bounds(p, direction, fp)
    rng = np.random.default_rng(12)
    worst = -np.inf
    if direction is None:
        # Toward the wall: the ball's point where the field climbs fastest.
        h = 1e-3
        grad = np.stack([(_field(p + h * e, rate) - _field(p - h * e, rate)) / (2 * h) for e in np.eye(3)], 1)
        up = grad / np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), 1e-12)
        for shrink in (0.999, 0.9, 0.5):
            q = p + up * (d * shrink)[:, None]
            worst = max(worst, float(np.max(np.where(d > 0, _field(q, rate), -np.inf))))
    for _ in range(16):
        if direction is None:
            v = rng.normal(size=p.shape)
            v /= np.linalg.norm(v, axis=1, keepdims=True)
            q = p + v * (d * 0.999 * rng.uniform(0, 1, len(d)) ** (1 / 3))[:, None]
        else:
            q = p + direction * (d * 0.999 * rng.uniform(-1, 1, len(d)))[:, None]
        # The footprint field at q is that of q's own footprint (a field of position).
        # (Points inside the footprint field, bound 0, are not asked about.)
        worst = max(worst, float(np.max(np.where(d > 0, _field(q, rate), -np.inf))))
    assert worst < 1e-4, f"f = {worst:.3g} inside a ball declared free"


def test_slanted_bounds_beat_hart_near_the_walls(monkeypatch):
    p = _near_walls()
    _, with_slants = _bounds(p)
    _, without = _bounds(p, slants=False, monkeypatch=monkeypatch)
    assert np.all(with_slants >= without)
    # Measured on these points: median ratio 1.66, 24 % of them at least 2x (the
    # goblins' hoodoos, steeper against their terrain: bounce steps 90 -> 41). The
    # baseline (Hart's bound with the local slopes) tightened when a ball that misses
    # a primitive's support stopped counting that primitive's slope: 38 % were at
    # least 2x before, median 1.73.
    ratio = with_slants / np.maximum(without, 1e-9)
    assert np.median(ratio) > 1.4
    assert np.mean(ratio > 2.0) > 0.2



def test_bounds_in_the_air_among_pillars_reach_past_the_near_lists():
    """Past the near lists' reach for many points in the air (the cells' unlisted gaps,
    ``skeletal_set.UNLISTED_REACH``: before them no bound there exceeded a quarter cell
    edge); that those balls are free is tested above."""
    from generators.terrain.skeletal_set import NEAR_REACH
    _, d = _bounds(_in_the_air())
    # Measured: 54 % of the points beyond the near reach and 17 % beyond 1.5 times it
    # (mean bound 3.00 m against 2.29 m with the gaps set to the reach); with the gaps
    # at the reach, none.
    reach = NEAR_REACH * PILLARS.cell
    assert np.mean(d > 1.01 * reach) > 0.4 and np.mean(d > 1.5 * reach) > 0.1


def _walls_with_frames(n=2000, seed=6):
    """Points near the pillars' noisy walls (``-f`` in (0, 8), inside a support), with
    the unit vector ``u`` from their pillar's skeleton and a horizontal tangent ``w``
    (the pillars stand upright: ``w`` grazes the wall)."""
    rng = np.random.default_rng(seed)
    k = rng.integers(0, PILLARS.n, 40 * n)
    a, b = PILLARS.a_np[k], PILLARS.b_np[k]
    s = a + (b - a) * rng.uniform(0.05, 0.95, (len(k), 1))
    ang = rng.uniform(0, 2 * np.pi, len(k))
    u = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(len(k))])
    w = np.column_stack([-np.sin(ang), np.cos(ang), np.zeros(len(k))])
    R, c = PILLARS.radius_np[k], PILLARS.core_np[k]
    p = s + u * (c + R * rng.uniform(0.3, 1.3, len(k)))[:, None]
    f = evaluate(SCULPTED, p)
    keep = np.flatnonzero((f < 0) & (f > -8) & (evaluate(PILLARS, p) > 0))[:n]
    assert len(keep) == n
    return p[keep], u[keep], w[keep]


def _line_bounds(p, w, ahead=False):
    from arches_render.field.node import one_sided
    dv = mi.Vector3f(*(mi.Float(w[:, i].astype(np.float32)) for i in range(3)))
    with one_sided(mi.Bool(True) if ahead else None):
        f, (d,) = SCULPTED.eval_bounds(_points(p), (0.0,), dv)
    dr.eval(f, d)
    return d.numpy().astype(np.float64)


@pytest.mark.parametrize("ray", ["grazing", "tilted", "leaving ahead"])
def test_line_bounds_past_noisy_walls_are_free_and_longer_than_balls(ray):
    """Level bounds along a ray's line (skeletal_bounds, "Along a line": ``rho`` falls no
    faster than ``|grad r . u|`` on the line, ``max(-grad r . u, 0)`` ahead only): a ray
    grazing a pillar's noisy wall, one tilted off it, and one leaving it outward,
    traced ahead only, as a tracer's first step from a surface. Dense samples of each
    segment declared free hold no matter, and the lengths beat the free balls."""
    p, u, w = _walls_with_frames()
    ahead = ray == "leaving ahead"
    if ray == "tilted":
        w = w + 0.5 * u + np.array([0.0, 0.0, 0.3])
        w /= np.linalg.norm(w, axis=1, keepdims=True)
    elif ahead:
        w = u
    d = _line_bounds(p, w, ahead)
    _, ball = _bounds(p)
    t = np.linspace(0.0 if ahead else -1.0, 1.0, 97) * 0.999
    q = p[:, None, :] + w[:, None, :] * (np.minimum(d, 1e3)[:, None] * t)[..., None]
    worst = float(evaluate(SCULPTED, q.reshape(-1, 3)).max())
    assert worst < 1e-4, f"f = {worst:.3g} on a segment declared free"
    # Not vacuous: measured medians of d / ball 1.50 grazing, 1.25 tilted, 1.54 leaving
    # (1.03 grazing with the balls alone, the terrain's lines aside). Not every point
    # gains: the slanted bound's second pass sits at a lower level when its first is
    # longer (skeletal_bounds.slanted_bound).
    ratio = d / np.maximum(ball, 1e-9)
    assert np.median(ratio) > (1.12 if ray == "tilted" else 1.3)


def test_line_bounds_by_a_rough_star_noise_are_free():
    """Where the star noise is rough (amplitude 0.3 of R, wavelength under R) the line
    bound near the surface is held by how fast the noise can swell along the line
    (skeletal_bounds, "Along a line": ``r`` stays above ``r (1 - |lean| / 2)``); grazing and
    tilted segments declared free, sampled densely, hold no matter."""
    from arches_render.generators.terrain.skeletal_set import SkeletalSet
    from arches_render.field.node import one_sided
    rng = np.random.default_rng(17)
    a = np.column_stack([rng.uniform(0, 60, 12), rng.uniform(0, 60, 12), np.zeros(12)])
    # Points as skeletons: the noise's swell is all the boundary point's turn, (c + R) / r.
    rough = SkeletalSet(a, None, 4.0, 2.0, core=1.0, combine="max", threshold=1.0,
                        noise=dict(amplitude=0.3, wavelength=1.5, octaves=2, seed=5))
    k = rng.integers(0, 12, 200000)
    ang = rng.uniform(0, 2 * np.pi, len(k))
    u = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(len(k))])
    p = a[k] + u * rng.uniform(1.5, 6.5, (len(k), 1))
    f = evaluate(rough, p)
    keep = np.flatnonzero((f < 0.0) & (f > -0.3))[:8000]
    p, u = p[keep], u[keep]
    w = np.column_stack([-u[:, 1], u[:, 0], np.zeros(len(u))])
    worst = -np.inf
    for tilt in (0.0, 0.4, 0.8):
        d = w + tilt * u
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        dv = mi.Vector3f(*(mi.Float(d[:, i].astype(np.float32)) for i in range(3)))
        for ahead in (False, True):
            with one_sided(mi.Bool(True) if ahead else None):
                _, (b,) = rough.eval_bounds(_points(p), (0.0,), dv)
            dr.eval(b)
            b = np.minimum(b.numpy().astype(np.float64), 1e3)
            t = np.linspace(0.0 if ahead else -1.0, 1.0, 129) * 0.999
            q = p[:, None, :] + d[:, None, :] * (b[:, None] * t)[..., None]
            worst = max(worst, float(evaluate(rough, q.reshape(-1, 3)).max()))
    assert worst < 1e-4, f"f = {worst:.3g} on a segment declared free"
