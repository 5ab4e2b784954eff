"""The sparse brick grid behind large primitive sets (``arches_render.field.brick_grid``).

What must hold at any set size: the capsule set's value is the union of its capsules
clamped at ``-m`` inside the grid (no capsule lost from a cell's list), the
empty-space bound never exceeds the true distance to the set, and memory follows
the occupied bricks, not the grid's volume.
"""

import numpy as np
import pytest

from arches_render import field as F
from arches_render.field import brick_grid
from arches_render.field.node import evaluate


def _capsules(n, seed, spread=(100.0, 100.0, 10.0)):
    rng = np.random.default_rng(seed)
    a = rng.uniform(-1, 1, (n, 3)) * spread
    b = a + rng.normal(0, 1.0, a.shape)
    return a, b, rng.uniform(0.3, 1.2, n)


def _union(a, b, r, p):
    """Brute-force union of capsules at points ``p`` (float64)."""
    best = np.full(len(p), -np.inf)
    for ai, bi, ri in zip(a, b, r):
        ba = bi - ai
        t = np.clip(((p - ai) @ ba) / max(ba @ ba, 1e-20), 0.0, 1.0)
        best = np.maximum(best, ri - np.linalg.norm(p - ai - t[:, None] * ba, axis=1))
    return best


@pytest.fixture(params=["dense transform", "per-brick bound"])
def transform(request, monkeypatch):
    """Both ways of bounding empty space: the exact transform of a small grid, and
    the per-brick chessboard bound of a large one (forced here on a small set)."""
    if request.param == "per-brick bound":
        monkeypatch.setattr(brick_grid, "DENSE_EDT_CELLS", 0)
    return request.param


def test_value_is_the_clamped_union_everywhere_in_the_grid(transform):
    a, b, r = _capsules(600, 1)
    node = F.CapsuleSet(a, b, r)
    rng = np.random.default_rng(2)
    # Points near capsules (where lists matter) and anywhere in the grid.
    near = a[rng.integers(0, len(a), 4000)] + rng.normal(0, 1.5, (4000, 3))
    anywhere = rng.uniform(node.grid_lo, node.grid_hi, (4000, 3))
    p = np.concatenate([near, anywhere])
    p = p[np.all((p > node.grid_lo) & (p < node.grid_hi), axis=1)]
    want = np.maximum(_union(a, b, r, p), -node.margin_np)
    got = evaluate(node, p)
    # float32 evaluation of distances of at most ~200 m: a few ulps.
    np.testing.assert_allclose(got, want, atol=1e-4)


def test_empty_space_bound_is_a_lower_bound_of_the_distance(transform):
    import drjit as dr
    import mitsuba as mi
    a, b, r = _capsules(300, 3, spread=(150.0, 150.0, 40.0))
    node = F.CapsuleSet(a, b, r)
    rng = np.random.default_rng(4)
    p = rng.uniform(node.grid_lo, node.grid_hi, (20000, 3))
    bound = node.grid.empty_distance(mi.Point3f(*(mi.Float(p[:, i].astype(np.float32)) for i in range(3))))
    bound = np.asarray(dr.detach(bound), dtype=np.float64)
    # Distance to the set >= -union (the union of signed distances is exact outside).
    distance = np.maximum(-_union(a, b, r, p), 0.0)
    assert np.all(bound <= distance + 1e-3), float(np.max(bound - distance))
    if transform == "dense transform":
        # And it says something: most points of this sparse set get a stride beyond the
        # clamp (76 % measured). The per-brick bound stops at the brick's faces (a stride
        # of at most ~2 cells inside stored bricks); its use is the void between bricks,
        # tested below.
        assert np.mean(bound > node.margin_np) > 0.5


def test_memory_follows_the_occupied_bricks_not_the_volume(transform):
    """Two clusters 2 km apart: a dense grid of the same cells would need ~10^9 cells."""
    a1, b1, r1 = _capsules(2000, 5, spread=(20.0, 20.0, 5.0))
    shift = np.array([2000.0, 2000.0, 0.0])
    a = np.concatenate([a1, a1 + shift]); b = np.concatenate([b1, b1 + shift]); r = np.concatenate([r1, r1])
    node = F.CapsuleSet(a, b, r)
    dense_cells = int(np.prod(node.res))
    assert node.cell < 3.0, node.cell  # cells stay as small as the capsules
    assert dense_cells > 100 * node.grid.stored_cells, (dense_cells, node.grid.stored_cells)
    assert node.nbytes() < 20e6
    p = np.concatenate([a[:50], a[-50:]])
    assert np.all(evaluate(node, p) >= -1e-4)  # the segment ends are inside their capsules
    # The void between the clusters is crossed in long strides (a ray from one to the
    # other needs few steps), and the bound stays below the true distance.
    import mitsuba as mi
    t = np.linspace(0.2, 0.8, 200)[:, None]
    void = t * shift + [0.0, 0.0, 1.0]
    bound = np.asarray(node.grid.empty_distance(mi.Point3f(*(mi.Float(void[:, i].astype(np.float32)) for i in range(3)))))
    distance = np.maximum(-_union(a, b, r, void), 0.0)
    assert np.all(bound <= distance + 1e-3)
    assert np.median(bound) > 0.5 * np.median(distance), (np.median(bound), np.median(distance))


def _stored_capsules(node, a, b, r):
    """Indices into ``a, b, r`` of the capsules in the order the grid stores them (from its
    float32 records)."""
    from arches_render.field.primitive_set import CAPSULE_RECORD
    records = np.asarray(node._records, dtype=np.float32).reshape(-1, CAPSULE_RECORD)[:, :7]
    of_row = {row.tobytes(): i for i, row in enumerate(np.concatenate([a, b, r[:, None]], axis=1)
                                                       .astype(np.float32))}
    assert len(of_row) == len(a)  # distinct random capsules: a record names its capsule
    return np.array([of_row[row.tobytes()] for row in records])


def test_grid_is_the_same_for_the_same_set_in_another_order():
    """The grid sorts capsules by cell for locality: what it stores and what the field is must
    not depend on the order the caller gave them in. The values alone cannot show it (a max
    over a list is order-independent whatever the list holds); the stored set can:

    * the same stored bricks and cells, and lists of the same lengths (bitwise);
    * every cell's list names the same capsules;
    * the capsules are stored grouped by brick and, within a brick, by the cell of their box's
      centre (the locality the sort is for), in the same sequence of cells for both orders
      (capsules whose centres share a cell may come in either order);
    * and the field's values are bitwise equal."""
    a, b, r = _capsules(800, 6)
    perm = np.random.default_rng(7).permutation(len(a))
    one, two = F.CapsuleSet(a, b, r), F.CapsuleSet(a[perm], b[perm], r[perm])
    assert np.array_equal(one.grid.slots_np, two.grid.slots_np)
    assert np.array_equal(one.grid.offset_np, two.grid.offset_np)
    # Stored position -> capsule, as indices into (a, b, r) for both.
    ids_one, ids_two = _stored_capsules(one, a, b, r), perm[_stored_capsules(two, a[perm], b[perm], r[perm])]
    assert sorted(ids_one) == sorted(ids_two) == list(range(len(a)))
    # Each cell's list, as sorted capsule indices per cell (the offsets are the same).
    offset = one.grid.offset_np.astype(np.int64)
    owner = np.repeat(np.arange(len(offset) - 1), np.diff(offset))
    lists = [ids[grid.grid.index_np.astype(np.int64)] for ids, grid in ((ids_one, one), (ids_two, two))]
    lists = [lst[np.lexsort((lst, owner))] for lst in lists]
    assert np.array_equal(lists[0], lists[1]), "a cell lists other capsules in the other order"
    # Locality: the cell and brick of each capsule's box centre, in storage order.
    lo, hi = np.minimum(a, b) - r[:, None], np.maximum(a, b) + r[:, None]
    cell = np.clip(np.floor((0.5 * (lo + hi) - one.grid_lo) / one.cell).astype(np.int64), 0, one.res - 1)
    cell_id = (cell[:, 2] * one.res[1] + cell[:, 1]) * one.res[0] + cell[:, 0]
    brick = cell // brick_grid.BRICK
    brick_id = (brick[:, 2] * one.res[1] + brick[:, 1]) * one.res[0] + brick[:, 0]
    for ids in (ids_one, ids_two):
        for label in (brick_id[ids], cell_id[ids]):  # each group contiguous: one run per value
            assert np.count_nonzero(np.diff(label)) == len(np.unique(label)) - 1, "capsules not grouped by cell"
    assert np.array_equal(cell_id[ids_one], cell_id[ids_two]), "the cells come in another sequence"
    p = np.random.default_rng(8).uniform([-100, -100, -10], [100, 100, 10], (5000, 3))
    assert np.array_equal(evaluate(one, p), evaluate(two, p))


def test_cell_gaps_are_the_box_to_box_distance_to_the_occupied_cells():
    """``cell_gaps`` (the empty-space bound of the brick grid and of the skeletal sets):
    per cell, exactly the smallest box-to-box gap to an occupied cell (up to its
    1e-5 shave), never more, and never less than the centre distance less sqrt 3."""
    from scipy.ndimage import distance_transform_edt
    rng = np.random.default_rng(6)
    occupied = rng.uniform(size=(9, 11, 13)) < 0.02
    gaps = brick_grid.cell_gaps(occupied)
    idx = np.argwhere(occupied)
    cells = np.argwhere(np.ones_like(occupied))
    d = np.abs(cells[:, None, :] - idx[None, :, :])
    brute = np.sqrt(np.sum(np.maximum(d - 1, 0) ** 2, axis=2)).min(axis=1).reshape(occupied.shape)
    # cell_gaps shaves 1e-5 of every gap on purpose (its docstring): exact up to that,
    # rtol twice the shave; never above the brute force.
    assert np.all(gaps <= brute) and np.allclose(gaps, brute, rtol=2e-5, atol=0)
    # (equal where all three offsets are 2 apart: sqrt 3 both ways, less the shave)
    assert np.all(gaps >= (distance_transform_edt(~occupied) - np.sqrt(3.0)) * (1 - 1e-5) - 1e-9)
    # Measured: a quarter of a cell longer on average, half the cells by a quarter or more.
    old = np.maximum(distance_transform_edt(~occupied) - np.sqrt(3.0), 0.0)
    assert np.mean(gaps - old) > 0.2 and np.mean(gaps > old + 0.25) > 0.4
    assert np.all(brick_grid.cell_gaps(np.zeros((2, 2, 2), bool)) >= 1e10)


def test_unlisted_gaps_bound_the_distance_to_the_boxes_left_out_of_each_list():
    """``unlisted_gaps`` (how far a skeletal set's level bounds may step past its near
    lists): per cell, the smallest box-to-box distance to a box *not* on the cell's list
    of boxes grown by ``margin``, capped at ``reach``: never more (up to its shave, by
    brute force over every cell and box), and larger than ``margin`` in many cells
    (else it would buy nothing)."""
    from arches_render.field.primitive_set import grid_lists, unlisted_gaps
    rng = np.random.default_rng(3)
    lo = rng.uniform(0.0, 40.0, (60, 3))
    hi = lo + rng.uniform(0.5, 6.0, (60, 3))
    grid_lo, cell = lo.min(axis=0), 3.0
    res = np.ceil((hi.max(axis=0) - grid_lo) / cell).astype(np.int64)
    margin, reach = 0.25 * cell, 2.0 * cell
    start, count, index = grid_lists(lo - margin, hi + margin, grid_lo, cell, res)
    gaps = unlisted_gaps(lo, hi, grid_lo, cell, res, margin, reach)
    # Brute force: every cell against every box left out of its list.
    ix, iy, iz = np.meshgrid(*(np.arange(n) for n in res), indexing="ij")
    idx = np.stack([ix.ravel(), iy.ravel(), iz.ravel()], 1)
    cell_id = (idx[:, 2] * res[1] + idx[:, 1]) * res[0] + idx[:, 0]
    c_lo = grid_lo + idx * cell
    sep = np.maximum(np.maximum(lo[None] - (c_lo[:, None] + cell), c_lo[:, None] - hi[None]), 0.0)
    dist = np.sqrt(np.sum(sep * sep, axis=2))
    listed = np.zeros_like(dist, dtype=bool)
    for row, cid in enumerate(cell_id):
        listed[row, index[start[cid]:start[cid] + count[cid]]] = True
    brute = np.minimum(np.where(listed, np.inf, dist).min(axis=1), reach)
    got = gaps[cell_id]
    assert np.all(got <= brute), "a gap overstates the distance to a box left out"
    # Exactly the brute force less the documented shave (a part in 1e5 and 1e-4 cell edges);
    # atol 1e-9 m: float64 rounding of the box distances (gaps of 0.75-6 m).
    assert np.allclose(got, brute * (1 - 1e-5) - 1e-4 * cell, rtol=0, atol=1e-9)
    assert np.all(got >= margin - 1e-4 * cell - 1e-9)
    assert np.mean(got > 2 * margin) > 0.3


@pytest.mark.parametrize("res", [(37, 29, 3), (3, 40, 20), (30, 2, 9), (9, 17, 1), (12, 12, 12)])
def test_thin_grids_are_stored_in_bricks_as_deep_as_they_are(res):
    """A grid thinner than a brick on an axis is stored in bricks of the smallest power of
    two holding it there (a coast's sets are four cells deep: bricks of 8^3 stored twice
    their cells), and a point's cell reads the same datum as the dense grid's."""
    from helpers import variant
    variant()
    import mitsuba as mi
    rng = np.random.default_rng(3)
    res = np.array(res)
    n = int(np.prod(res))
    data = rng.uniform(1.0, 2.0, n)
    nonzero = rng.random(n) < 0.05
    # Bricks of edge 8 only (of_cells tries smaller ones too: test_skeletal_compact_points).
    layout = brick_grid.BrickLayout.of_cells(nonzero, np.zeros(3), 2.0, res, edges=(8,))
    assert layout.shape == tuple(min(8, 1 << int(r - 1).bit_length()) for r in res)
    cubic = brick_grid.BrickLayout._bricked(nonzero, res, False).any(axis=(1, 2, 3)).sum() * 512
    assert layout.stored_cells <= cubic and (layout.shape != (8, 8, 8) or layout.stored_cells == cubic)
    P = rng.uniform(0.0, 2.0 * res, (5000, 3))
    cell, stored, _ = layout.lookup(mi.Point3f(*P.T.astype(np.float32)))
    got = np.asarray(layout.compact(np.where(nonzero, data, 0.0)))[np.asarray(cell)[np.asarray(stored)]]
    ix, iy, iz = np.clip(np.floor(P / 2.0).astype(int), 0, res - 1).T
    dense = (iz * res[1] + iy) * res[0] + ix
    want = np.where(nonzero, data, 0.0)[dense[np.asarray(stored)]]
    np.testing.assert_array_equal(got, want)
    # Every nonzero cell's point is in a stored brick.
    assert np.asarray(stored)[nonzero[dense]].all()


def test_compact_lists_keep_every_stored_cells_list_in_order():
    """``BrickLayout.compact_lists``: each stored cell's list, read between its offset and
    the next, is its dense list, entry for entry (the sums over a list keep their order,
    so a skeletal set's values keep their bits)."""
    from helpers import variant
    variant()
    from arches_render.field.primitive_set import grid_lists
    rng = np.random.default_rng(5)
    lo = rng.uniform(0.0, 40.0, (300, 3)) * [1.0, 1.0, 0.1]
    hi = lo + rng.uniform(0.5, 6.0, (300, 3))
    res = np.array([23, 19, 3])
    start, count, index = grid_lists(lo, hi, np.zeros(3), 2.0, res)
    layout = brick_grid.BrickLayout.of_cells(count > 0, np.zeros(3), 2.0, res)
    (offset,), compact_index = layout.compact_lists(start, count, index)
    # The dense cell of each stored one (-1: a brick's padding past the grid).
    dense_of = layout.compact(np.arange(int(np.prod(res))) + 1) - 1
    listed = 0
    for c, d in enumerate(dense_of):
        got = compact_index[offset[c]:offset[c + 1]]
        want = index[start[d]:start[d] + count[d]] if d >= 0 else index[:0]
        np.testing.assert_array_equal(got, want)
        listed += d >= 0 and count[d] > 0
    assert listed == int((count > 0).sum()) and len(compact_index) == len(index)


def test_narrow_lists_read_back_every_entry():
    """16-bit list entries (``compact_lists(..., narrow=True)``): :func:`list_entry` reads
    entry for entry what the 32-bit lists hold, at even and odd positions and at the
    last entry of an odd count; entries of 2^16 or more are refused."""
    from helpers import variant
    variant()
    import drjit as dr
    import mitsuba as mi
    from arches_render.field.primitive_set import grid_lists
    rng = np.random.default_rng(6)
    lo = rng.uniform(0.0, 40.0, (301, 3)) * [1.0, 1.0, 0.1]
    hi = lo + rng.uniform(0.5, 6.0, (301, 3))
    res = np.array([23, 19, 3])
    if len(grid_lists(lo, hi, np.zeros(3), 2.0, res)[2]) % 2 == 0:  # one more entry: an odd count
        lo, hi = np.vstack([lo, [[1.0, 1.0, 1.0]]]), np.vstack([hi, [[1.5, 1.5, 1.5]]])
    start, count, index = grid_lists(lo, hi, np.zeros(3), 2.0, res)
    index = index.astype(np.int64) * 211 % 65536  # entries over the whole 16-bit range
    layout = brick_grid.BrickLayout.of_cells(count > 0, np.zeros(3), 2.0, res)
    (offset,), wide = layout.compact_lists(start, count, index)
    offsets_n, words = layout.compact_lists(start, count, index, narrow=True)
    assert len(offsets_n) == 2  # 16-bit offsets relative to each brick's base
    # Every stored cell's range read back from the relative offsets is its absolute one.
    cells = mi.UInt32(np.arange(layout.stored_cells, dtype=np.uint32))
    first, n = layout.list_range(tuple(mi.UInt32(v) for v in offsets_n), cells)
    np.testing.assert_array_equal(first.numpy(), offset[:-1])
    np.testing.assert_array_equal(n.numpy(), np.diff(offset))
    assert len(offsets_n[0]) * 4 < len(offset) * 4 * 0.6  # about 2 bytes a cell, not 4
    assert len(words) == (len(wide) + 1) // 2 and len(wide) % 2 == 1  # an odd count: the pad is read too
    k = mi.UInt32(np.arange(len(wide), dtype=np.uint32))
    got = brick_grid.list_entry(mi.UInt32(words), k, True).numpy()
    np.testing.assert_array_equal(got, wide)
    np.testing.assert_array_equal(brick_grid.list_entry(mi.UInt32(wide), k, False).numpy(), wide)
    assert int(np.max(wide)) > 60000
    with pytest.raises(ValueError):
        brick_grid.pack_narrow([3, 65536])


def test_relative_offsets_fall_back_where_a_brick_lists_too_many():
    """16-bit offsets relative to a brick's base hold while each brick lists fewer than
    2^16 entries; a brick with more keeps 32-bit offsets (``None``), and the read-back
    of either form gives every cell's range."""
    bricks, cells = 3, 8
    counts = np.full(bricks * cells, 1000)
    offset = np.concatenate([[0], np.cumsum(counts)])
    words, base = brick_grid.relative_offsets(offset, cells)
    np.testing.assert_array_equal(base, [0, 8000, 16000])
    halves = np.stack([words & 0xFFFF, words >> 16], axis=1).reshape(-1)[:bricks * (cells + 1)]
    rel = halves.reshape(bricks, cells + 1)
    np.testing.assert_array_equal(rel[:, -1], [8000] * 3)  # each brick's end
    np.testing.assert_array_equal((rel[:, :-1] + base[:, None]).reshape(-1), offset[:-1])
    counts[cells + 3] = 60000  # the second brick now lists 67,000 entries
    offset = np.concatenate([[0], np.cumsum(counts)])
    assert brick_grid.relative_offsets(offset, cells) is None


def test_half_up_rounds_every_value_up_within_a_part_in_1024():
    """Per-cell upper bounds stored as float16 stay upper bounds (skeletal sets' L and M)."""
    rng = np.random.default_rng(4)
    v = np.concatenate([np.minimum(rng.lognormal(0.0, 4.0, 100_000), 6e4), [0.0, 1e-9, 6e-8, 1.0, 65504.0]])
    v = v.astype(np.float32)
    h = brick_grid.half_up(v)
    assert h.dtype == np.float16
    back = h.astype(np.float32)
    assert np.all(back >= v)
    # Above float16's smallest normal (6.1e-5) the step is a part in 1024 of the value.
    normal = v >= 6.2e-5
    assert np.all(back[normal] <= v[normal] * (1.0 + 2.0 ** -10) * (1.0 + 1e-7))
    assert back[np.flatnonzero(v == 0.0)[0]] == 0.0
    assert brick_grid.half_up(np.float32([1.0, 70000.0])) is None
    assert brick_grid.half_up(np.float32([1.0, np.inf])) is None
