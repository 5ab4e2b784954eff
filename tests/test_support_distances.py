"""The skeletal set's distances from cell and brick centres to its supports
(``generators.terrain.support_distances``) and the empty-space bounds built on them."""

from __future__ import annotations

import numpy as np

from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.field import evaluate  # noqa: E402
from arches_render.generators.terrain.skeletal_set import SkeletalSet  # noqa: E402
from arches_render.generators.terrain.support_distances import (REACH_CELLS, brick_centre_distances,  # noqa: E402
                                                                  centre_distances)


def _clusters(seed=3):
    """Upright segments (hoodoos) in two clusters 300 m apart, star noise on: most of the
    grid is air far from every support, in bricks that store no cell."""
    rng = np.random.default_rng(seed)
    centres = np.array([[0.0, 0.0, 0.0], [300.0, 40.0, 10.0]])
    a = np.concatenate([c + rng.uniform([-40, -40, 0], [40, 40, 5], (60, 3)) for c in centres])
    b = a + np.column_stack([rng.normal(0, 1, len(a)), rng.normal(0, 1, len(a)), rng.uniform(4, 20, len(a))])
    radius = rng.uniform(2.0, 5.0, len(a))
    return SkeletalSet(a, b, radius, energy=np.full(len(a), 2.0), core=0.6 * radius, combine="max", cell_size=4.0,
                       noise={"amplitude": 0.12, "wavelength": 5.0, "octaves": 2, "seed": 4})


SET = _clusters()


def _support_distance(p):
    """Exact distance from each point to the union of the supports (capsules)."""
    reach = SET.core_np + SET.radius_np * (1.0 + SET.noise["span"])  # (written out: the test's own)
    a, ba = SET.a_np, SET.b_np - SET.a_np
    best = np.full(len(p), np.inf)
    for i in range(len(a)):
        pa = p - a[i]
        t = np.clip(pa @ ba[i] / max(ba[i] @ ba[i], 1e-20), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(pa - np.outer(t, ba[i]), axis=1) - reach[i])
    return best


def _cell_centres():
    rx, ry, rz = SET.res
    z, y, x = np.meshgrid(np.arange(rz), np.arange(ry), np.arange(rx), indexing="ij")
    return SET.grid_lo + (np.column_stack([x.ravel(), y.ravel(), z.ravel()]) + 0.5) * SET.cell


def _dense_centre_bounds():
    from arches_render.field.primitive_set import empty_distance
    lo, hi = SET.primitive_boxes()
    gaps = empty_distance(lo, hi, SET.grid_lo, SET.cell, SET.res).astype(np.float32)
    return centre_distances(SET.a_np, SET.b_np, SET.support_reach(), SET.grid_lo, SET.cell, SET.res, gaps)


def test_centre_bounds_hold_and_are_exact_near_the_supports():
    """``D(c) <= d(c)`` at every cell centre, equal to it (but the float32 shave) where
    the nearest support is within ``REACH_CELLS`` cells, and never below the gap's bound."""
    D = _dense_centre_bounds().astype(np.float64)
    exact = _support_distance(_cell_centres())
    assert np.all(D <= np.maximum(exact, 0.0) + 1e-9)
    near = (exact > 0.0) & (exact < REACH_CELLS * SET.cell)
    assert near.sum() > 300
    # float32 and the shave (1e-5 relative, 16 ulps of 400 m): a few millimetres.
    np.testing.assert_allclose(D[near], exact[near], atol=5e-3)
    # Far away the gap rules: more than the near reach, though below the truth.
    far = exact > 3 * REACH_CELLS * SET.cell
    assert far.sum() > 100 and np.all(D[far] >= REACH_CELLS * SET.cell)


def test_brick_centre_bounds_hold():
    """Each brick's bound lies below the exact distance from the brick's centre."""
    D = _dense_centre_bounds()
    layout = SET.layout
    Db = brick_centre_distances(D, layout).astype(np.float64)
    bx, by, bz = (int(v) for v in layout.bricks)
    z, y, x = np.meshgrid(np.arange(bz), np.arange(by), np.arange(bx), indexing="ij")
    edge = np.asarray(layout.shape) * SET.cell
    centres = SET.grid_lo + (np.column_stack([x.ravel(), y.ravel(), z.ravel()]) + 0.5) * edge
    exact = _support_distance(centres)
    assert np.all(Db <= np.maximum(exact, 0.0) + 1e-9)
    # Most bricks lie in the air between the clusters, and their bound is most of the way.
    air = exact > np.linalg.norm(edge)
    assert air.sum() > 20 and np.median(Db[air] / exact[air]) > 0.8


def _air_points(n=4000, seed=8):
    rng = np.random.default_rng(seed)
    lo, hi = SET.support()
    p = rng.uniform(lo, hi, (8 * n, 3))
    d = _support_distance(p)
    keep = np.flatnonzero(d > 0.5)[:n]
    return p[keep], d[keep]


def _bounds(p):
    pts = mi.Point3f(*(mi.Float(p[:, i].astype(np.float32)) for i in range(3)))
    f, (d,) = SET.eval_bounds(pts, (-1e-3,))
    dr.eval(f, d)
    return d.numpy().astype(np.float64)


def test_empty_space_bounds_are_free_and_reach_most_of_the_distance():
    """Below the threshold ({F >= 1e-3}) the set's bound in the air is free (no point of
    its ball is in a support) and most of the distance to the supports: the box-to-box
    gaps of the cells gave about half of it (goblins: 0.55)."""
    p, exact = _air_points()
    d = _bounds(p)
    # (Next to a support the primitives' own level bounds may pass its edge: {F >= u} lies
    # inside it. So freeness is checked on the balls themselves.)
    rng = np.random.default_rng(9)
    for _ in range(4):
        u = rng.normal(size=p.shape)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        q = p + u * (0.999 * d)[:, None]
        assert np.all(evaluate(SET, q) < 1e-3)
    # Measured at points more than a cell from the supports: median 0.69 of the distance,
    # a quarter below 0.50; with the cells' gaps alone (before) 0.54 and 0.29.
    far = exact > SET.cell
    ratio = d[far] / exact[far]
    assert np.median(ratio) > 0.62 and np.percentile(ratio, 25) > 0.4
