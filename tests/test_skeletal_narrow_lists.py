"""A skeletal set's lists in 16 bits (generators/terrain/skeletal_set.py, ``NARROW_LISTS``;
arches_render/field/brick_grid.py, ``list_entry``): the same field, in less memory."""

from __future__ import annotations

import numpy as np

from helpers import variant

variant()


def test_sixteen_bit_lists_give_the_same_values_and_bounds_bit_for_bit(monkeypatch):
    """A set whose lists are 16-bit (``NARROW_LISTS`` lowered so that this small set packs
    them) evaluates and bounds every point exactly as with 32-bit lists, in less memory."""
    import mitsuba as mi
    from arches_render.generators.terrain import skeletal_set as S
    rng = np.random.default_rng(12)
    n = 401  # an odd number of entries somewhere: the padded half-word is never read
    a = rng.uniform(0, 60, (n, 3)) * [1.0, 1.0, 0.2]
    b = a + rng.normal(0, 3, (n, 3))
    R, e = rng.uniform(2, 6, n), -rng.uniform(0.5, 2, n)
    P = rng.uniform(-5, 65, (20000, 3)).astype(np.float32)
    p = mi.Point3f(*(mi.Float(P[:, i]) for i in range(3)))

    def dump(s):
        f, bounds = s.eval_bounds(p, (0.0, 0.5))
        L = s.local_lipschitz(p)
        return [np.asarray(x) for x in (f, *bounds, L[0] if isinstance(L, tuple) else L)]

    wide = S.SkeletalSet(a, b, R, e)
    monkeypatch.setattr(S, "NARROW_LISTS", 0)
    narrow = S.SkeletalSet(a, b, R, e)
    assert narrow._narrow and not wide._narrow
    assert len(narrow._wide[0]) == 2 and len(wide._wide[0]) == 1  # offsets relative to each brick, 16-bit
    for x, y in zip(dump(wide), dump(narrow)):
        assert np.array_equal(x.view(np.uint32), y.view(np.uint32))
    assert narrow.nbytes() < wide.nbytes()
