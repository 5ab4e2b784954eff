"""Sets of points in less memory (generators/terrain/skeletal_set.py, skeletal_records.py;
arches_render/field/brick_grid.py ``BrickLayout.of_cells``): 16-byte point records and their energies, a
carving set's lists by ball and without its cell lists, bricks of the least memory. The
same values and bounds, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant

variant()


def _coast_points(rng, n, energy_sign):
    """Points along a ragged band, radii skewed like the sea's carving spheres (2-25 m)."""
    x = rng.uniform(0, 600, n)
    a = np.stack([x, 40 * np.sin(x / 60) + rng.normal(0, 12, n), rng.uniform(-10, 20, n)], axis=1)
    R = np.clip(rng.lognormal(np.log(8), 0.6, n), 2, 25)
    return a, R, energy_sign * rng.uniform(6, 45, n)


def _dump(s, p, d):
    """Every value and bound a tracer asks of the set at ``p`` (rays along ``d``)."""
    import mitsuba as mi
    from arches_render.field.node import one_sided
    out = [s.eval(p), *s.local_lipschitz(p)[:2]]
    f, ds, sl = s.eval_local(p, [0.5, 2.0], d, None, radii=(0.1 * s.cell, 0.5, 3 * s.cell))
    out += [f, *ds, *sl]
    f, ds, sl = s.eval_local(p, [0.5], None, None, radii=(0.1 * s.cell,))
    out += [*ds, *sl]
    with one_sided(mi.Bool(True) | (p.x > 1e30)):
        out += list(s.eval_local(p, [0.5], d, None, radii=(0.1 * s.cell,))[1])
    return [np.asarray(x + 0 * p.x, dtype=np.float32) for x in out]


@pytest.mark.parametrize("energy_sign", [-1.0, 1.0], ids=["carving", "adding"])
def test_point_sets_keep_their_values_and_bounds_in_less_memory(monkeypatch, energy_sign):
    """A set of points (no noise, no curves) evaluates and bounds every point exactly as the
    same set stored with the general 64-byte records and box lists (``_points_only``
    patched to False), in less memory: 20 bytes a point instead of 64, and a carving
    set's lists list only the cells each grown ball touches."""
    import mitsuba as mi
    from arches_render.generators.terrain import skeletal_set as S
    rng = np.random.default_rng(5)
    a, R, e = _coast_points(rng, 3000, energy_sign)
    threshold = 0.0 if energy_sign < 0 else 5.0
    # Points by the spheres (inside, on and near the supports, by cell faces) and anywhere in the box.
    k = rng.integers(0, len(a), 40000)
    P = np.concatenate([a[k] + rng.normal(0, 1, (len(k), 3)) * R[k, None],
                        rng.uniform(a.min(0) - 30, a.max(0) + 30, (20000, 3))]).astype(np.float32)
    D = rng.normal(size=P.shape)
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    p = mi.Point3f(*(mi.Float(P[:, i]) for i in range(3)))
    d = mi.Vector3f(*(mi.Float(D[:, i].astype(np.float32)) for i in range(3)))

    compact = S.SkeletalSet(a, None, R, e, 0.0, threshold=threshold)
    monkeypatch.setattr(S.SkeletalSet, "_points_only", lambda self, a, b: False)
    general = S.SkeletalSet(a, None, R, e, 0.0, threshold=threshold)
    assert compact._record_floats == 4 and general._record_floats == 16
    for x, y in zip(_dump(general, p, d), _dump(compact, p, d)):
        assert np.array_equal(x.view(np.uint32), y.view(np.uint32))
    assert compact.nbytes() <= general.nbytes() - 40 * len(a)  # 20 bytes a point, not 64
    if energy_sign < 0:
        # Balls touch about three quarters of their boxes' cells.
        assert compact.wide_len < 0.85 * general.wide_len


def test_a_carving_set_stores_one_list_a_cell_and_no_value_table():
    """A carving set's values loop over its slope lists (the same bits as its cell lists:
    test_skeletal_narrow_lists and the set's own tests), so it keeps no cell lists, and its
    value table (0 everywhere) is not stored: ``local_lipschitz`` answers M = 0."""
    import mitsuba as mi
    from arches_render.generators.terrain.skeletal_set import SkeletalSet
    rng = np.random.default_rng(8)
    a, R, e = _coast_points(rng, 500, -1.0)
    s = SkeletalSet(a, a + rng.normal(0, 3, a.shape), R, e)  # segments: the general records
    assert s._lists is s._wide and s._cell_M is None
    P = rng.uniform(a.min(0), a.max(0), (5000, 3)).astype(np.float32)
    p = mi.Point3f(*(mi.Float(P[:, i]) for i in range(3)))
    L, M, _ = s.local_lipschitz(p)
    assert np.all(np.asarray(M + 0 * p.x) == 0) and np.asarray(L).max() > 0
    adding = SkeletalSet(a, None, R, -e, threshold=1.0)
    assert adding._lists is not adding._wide and adding._cell_M is not None


def test_bricks_take_the_least_memory_and_read_the_dense_grid():
    """``BrickLayout.of_cells`` stores the cells in the bricks (edge 8, 4 or 2, no deeper
    than the grid) that take the least memory, a dense grid in bricks of 8^3, and every
    point reads its cell's datum as from the dense grid."""
    import mitsuba as mi
    from arches_render.field import brick_grid
    rng = np.random.default_rng(4)
    res = np.array([64, 48, 4])
    n = int(np.prod(res))
    # A thin band of cells (a coast), and a grid where most cells hold a datum.
    iz, iy, ix = np.unravel_index(np.arange(n), res[::-1])
    band = np.abs(iy - 24 - 8 * np.sin(ix / 6)) < 1.5
    for nonzero, dense_grid in ((band, False), (rng.random(n) < 0.9, True)):
        layout = brick_grid.BrickLayout.of_cells(nonzero, np.zeros(3), 2.0, res, cell_bytes=8, brick_bytes=4)
        costs = {}
        for edge in (8, 4, 2):
            shape = tuple(min(edge, t) for t in brick_grid.brick_shape(res))
            occ = brick_grid.BrickLayout._bricked(nonzero, res, False, shape).any(axis=(1, 2, 3))
            costs[shape] = 4 * len(occ) + 8 * int(occ.sum()) * int(np.prod(shape))
        assert costs[layout.shape] == min(costs.values())
        assert (layout.shape == (8, 8, 4)) == dense_grid
        data = rng.uniform(1.0, 2.0, n)
        P = rng.uniform(0.0, 2.0 * res, (5000, 3))
        cell, stored, _ = layout.lookup(mi.Point3f(*P.T.astype(np.float32)))
        got = np.asarray(layout.compact(np.where(nonzero, data, 0.0)))[np.asarray(cell)[np.asarray(stored)]]
        jx, jy, jz = np.clip(np.floor(P / 2.0).astype(int), 0, res - 1).T
        dense = (jz * res[1] + jy) * res[0] + jx
        np.testing.assert_array_equal(got, np.where(nonzero, data, 0.0)[dense[np.asarray(stored)]])
        assert np.asarray(stored)[nonzero[dense]].all()


@pytest.mark.parametrize("energy_sign", [-1.0, 1.0], ids=["carving", "adding"])
def test_cell_tables_in_float16_are_rounded_up(monkeypatch, energy_sign):
    """The cells' slope (L) and value (M) tables in float16 bound from above what the
    float32 tables bound, within a part in 1024, in 2 bytes a cell less each; values and
    the primitives' own bounds do not read them."""
    import mitsuba as mi
    from arches_render.generators.terrain import skeletal_set as S
    rng = np.random.default_rng(6)
    a, R, e = _coast_points(rng, 2000, energy_sign)
    P = rng.uniform(a.min(0) - 10, a.max(0) + 10, (50000, 3)).astype(np.float32)
    p = mi.Point3f(*(mi.Float(P[:, i]) for i in range(3)))
    half = S.SkeletalSet(a, None, R, e, 0.0)
    from arches_render.generators.terrain import skeletal_bounds
    monkeypatch.setattr(skeletal_bounds, "half_up", lambda values: None)
    full = S.SkeletalSet(a, None, R, e, 0.0)
    assert half._table is mi.Float16 and full._table is mi.Float
    tables = list(zip(full.local_lipschitz(p)[:2], half.local_lipschitz(p)[:2]))
    for x, y in tables[:1 if energy_sign < 0 else 2]:  # (a carving set has no M: 0)
        x, y = np.asarray(x + 0 * p.x), np.asarray(y + 0 * p.x)
        assert np.all(y >= x) and np.all(y <= x * (1.0 + 2.0 ** -10) + 1e-30)
        assert np.mean(y > x) > 0.3  # (they were rounded)
    np.testing.assert_array_equal(np.asarray(full.eval(p)), np.asarray(half.eval(p)))
    # 2 bytes a cell for L, and for M in a set that adds matter (a carving set's bricks may
    # change edge with the bytes a cell takes: the least-memory choice).
    if energy_sign > 0:
        assert half.layout.stored_cells == full.layout.stored_cells
        assert half.nbytes() == full.nbytes() - 4 * half.layout.stored_cells
    else:
        assert half.nbytes() < full.nbytes()
