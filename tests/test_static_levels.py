"""Levels known before tracing to hold every point are not bounded (issue 32): the bounds of
a terrain summed with hoodoos are bitwise those of the same levels given per lane, which
nothing can skip."""

from __future__ import annotations

import numpy as np

from arches_render import backend
from arches_render.timing import REPO


def test_static_levels_bound_exactly_as_per_lane_levels():
    backend.set_variant()
    import drjit as dr
    import mitsuba as mi
    from arches_render.scene import load_scene
    desc = load_scene(REPO / "scenes" / "gallery" / "fig23_goblins.toml")
    root = desc.field
    lo, hi = (np.asarray(v, float) for v in root.bounds())
    rng = np.random.default_rng(7)
    # Points over the hoodoos' ground (within 40 m of the terrain's top), random directions.
    pts = rng.uniform([lo[0], lo[1], lo[2]], [hi[0], hi[1], min(hi[2], lo[2] + 0.3 * (hi[2] - lo[2]))], (20000, 3))
    dirs = rng.normal(size=(20000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    p = mi.Point3f(*(mi.Float(pts[:, k].astype(np.float32)) for k in range(3)))
    d = mi.Vector3f(*(mi.Float(dirs[:, k].astype(np.float32)) for k in range(3)))
    for c in (0.0, 0.5, -0.25):
        f_a, (d_a,) = root.eval_bounds(p, (c,), d)
        f_b, (d_b,) = root.eval_bounds(p, (mi.Float(c),), d)
        dr.eval(f_a, d_a, f_b, d_b)
        a, b = d_a.numpy(), d_b.numpy()
        assert np.array_equal(f_a.numpy(), f_b.numpy())
        assert np.array_equal(a, b), (c, int(np.sum(a != b)))
        assert np.mean(a > 0.0) > 0.1  # not all 0: many points lie in the air


def test_levels_shaped_once_for_a_shared_energy_bound_as_per_primitive():
    """The goblins' hoodoos share one energy, so each level's shape (``x`` and whether a
    primitive reaches it) is computed once a lane outside the loop over the primitives
    (skeletal_bounds.level_shape): the sum's bounds, slanted levels included, are
    bitwise those computed per primitive."""
    backend.set_variant()
    import drjit as dr
    import mitsuba as mi
    from arches_render.scene import load_scene
    root = load_scene(REPO / "scenes" / "gallery" / "fig23_goblins.toml").field
    hoodoos = root.children[1]
    assert hoodoos._shared_energy is not None
    lo, hi = (np.asarray(v, float) for v in root.bounds())
    rng = np.random.default_rng(8)
    pts = rng.uniform(lo, [hi[0], hi[1], lo[2] + 0.3 * (hi[2] - lo[2])], (20000, 3))
    dirs = rng.normal(size=(20000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    p = mi.Point3f(*(mi.Float(pts[:, k].astype(np.float32)) for k in range(3)))
    d = mi.Vector3f(*(mi.Float(dirs[:, k].astype(np.float32)) for k in range(3)))
    shared = hoodoos._shared_energy
    try:
        out = []
        for energy in (shared, None):
            hoodoos._shared_energy = energy
            f, ds = root.eval_bounds(p, (0.0, mi.Float(0.3)), d)
            dr.eval(f, ds)
            out.append([f.numpy()] + [x.numpy() for x in ds])
    finally:
        hoodoos._shared_energy = shared
    for a, b in zip(*out):
        assert np.array_equal(a, b), int(np.sum(a != b))
    assert np.mean(out[0][1] > 0.0) > 0.1
