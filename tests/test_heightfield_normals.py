"""Shading normals of heightfields (``arches_render.field.heightfield``, "Shading normals").

The bilinear surface's slope jumps across cell edges; the normals the tracers give it
come from its elevation averaged over a square of ``SMOOTH_WIDTH`` cells, which is C1,
equal to the bilinear elevation away from the edges, and never steeper than the
bilinear slopes around. Hits keep the bilinear surface.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant


def _roofs(n=9, cell=10.0):
    """Ridges and valleys 10 m apart whose slopes jump at every grid line (in x and y)."""
    i = np.arange(n)
    H = 20.0 * (i % 2)[None, :] + 12.0 * (i % 2)[:, None] + 5.0
    extent = (0.0, 0.0, cell * (n - 1), cell * (n - 1))
    return H.astype(np.float32), extent


@pytest.fixture(scope="module")
def roofs():
    variant()
    from arches_render.field import Heightfield
    H, extent = _roofs()
    return Heightfield(H, extent)


def _numpy(*values):
    return [np.asarray(v.numpy(), float) for v in values]


def test_smooth_slopes_are_continuous_across_cell_edges_and_bilinear_inside(roofs):
    import mitsuba as mi
    from arches_render.field.heightfield import SMOOTH_WIDTH
    hf = roofs
    rng = np.random.default_rng(3)
    # Points a hundredth of a cell either side of the x = 10 k lines.
    k = rng.integers(1, 7, 500)
    y = rng.uniform(5.0, 75.0, 500)
    for side in (-1.0, 1.0):
        hx, hy = _numpy(*hf.smooth_slopes(mi.Float(10.0 * k + side * 0.1), mi.Float(y)))
        if side < 0:
            left = hx
    jump = np.abs(hx - left)
    # Bilinear slopes along x jump by 4 (20 m over 10 m, up then down): the smooth ones
    # move by at most their largest rate (4 / (SMOOTH_WIDTH cell)) times the 0.2 m apart.
    assert np.max(jump) <= 4.0 / (SMOOTH_WIDTH * 10.0) * 0.2 * 1.05, np.max(jump)
    # Never steeper than the bilinear slopes around (|h_x| <= 2 + 1.2 here: the x
    # slope 2 and the y ridge's twist).
    xs, ys = rng.uniform(0.0, 80.0, 4000), rng.uniform(0.0, 80.0, 4000)
    hx, hy = _numpy(*hf.smooth_slopes(mi.Float(xs), mi.Float(ys)))
    assert np.max(np.abs(hx)) <= 2.0 * 1.001 and np.max(np.abs(hy)) <= 1.2 * 1.001
    # Farther than half the square from every grid line, the square lies in one cell,
    # where the bilinear elevation's mean is its centre value: the bilinear surface.
    fx, fy = (xs / 10.0) % 1.0, (ys / 10.0) % 1.0
    inside = (np.minimum(fx, 1 - fx) > 0.51 * SMOOTH_WIDTH) & (np.minimum(fy, 1 - fy) > 0.51 * SMOOTH_WIDTH)
    smooth, bilinear = _numpy(hf.smooth_height(mi.Float(xs), mi.Float(ys)), hf.height(mi.Float(xs), mi.Float(ys)))
    assert inside.sum() > 1000
    # (float32 rounding of heights up to 40 m: ulp 4e-6, a few operations)
    np.testing.assert_allclose(smooth[inside], bilinear[inside], atol=2e-5 * 40.0)
    assert np.max(np.abs(smooth - bilinear)[~inside]) > 0.05  # (the edges are rounded)
    # It is the mean of the bilinear elevation over the square (midpoint rule, 64^2).
    m = 64
    off = ((np.arange(m) + 0.5) / m - 0.5) * SMOOTH_WIDTH * 10.0
    ox, oy = (a.ravel() for a in np.meshgrid(off, off))
    px, py = xs[:200, None] + ox[None], ys[:200, None] + oy[None]
    mean = _numpy(hf.height(mi.Float(px.ravel()), mi.Float(py.ravel())))[0].reshape(200, -1).mean(axis=1)
    # (the midpoint rule's error where the square holds a kink: a slope jump of 4 sampled
    # every 2.5 m / 64 = 4 cm, under 4 x 0.04 / 8 x its share of the square; ~1e-3 seen)
    np.testing.assert_allclose(smooth[:200], mean, atol=5e-3)


@pytest.mark.parametrize("tracer", ["sphere", "cast"])
def test_tracers_give_heightfields_smooth_normals_and_keep_their_hits(roofs, tracer):
    """Both tracers' ``surface`` normals turn continuously across a cell edge (the
    bilinear normal jumps by 2 there), and the sphere tracer's hit point stays on the
    bilinear surface."""
    import drjit as dr
    import mitsuba as mi
    from arches_render.render.heightfield_caster import make_tracer
    from arches_render.render.sphere_tracer import SphereTracer
    hf = roofs
    tr = SphereTracer(hf) if tracer == "sphere" else make_tracer(hf)
    assert type(tr).__name__ == ("SphereTracer" if tracer == "sphere" else "HeightfieldCaster")
    y = np.linspace(12.0, 68.0, 57)
    normals = []
    for x in (29.99, 30.01):
        X, Y = mi.Float(np.full_like(y, x)), mi.Float(y)
        p = mi.Point3f(X, Y, hf.height(X, Y))
        q, n = tr.surface(p, mi.Float(100.0), mi.Vector3f(0.0, 0.0, -1.0))
        dr.eval(q, n)
        normals.append(np.stack(_numpy(n.x, n.y, n.z), axis=1))
        if tracer == "sphere":
            # (the points start on the bilinear surface, f = 0 up to float32 rounding of
            # 40 m heights, so the Newton step f / |g| along the smooth normal is tiny; it
            # may move up to eps t = 2 cm, and 2 mm catches a step from a wrong f)
            np.testing.assert_allclose(_numpy(q.z)[0], _numpy(hf.height(q.x, q.y))[0], atol=2e-3)
    turn = np.degrees(np.arccos(np.clip(np.sum(normals[0] * normals[1], axis=1), -1, 1)))
    # The bilinear normals either side are ~(-2, ., 1) and ~(2, ., 1): 127 degrees apart;
    # the smooth slope moves by at most 4 / (SMOOTH_WIDTH cell) a metre: 0.032 (1.8 degrees).
    assert np.max(turn) < 2.5, np.max(turn)
