"""Stabilization and the editing tools (Peytavie et al. 2009, 3.4 and 4): physics and invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest

from arches_render.generators.layers.deposit import deposit
from arches_render.generators.layers.erosion import erode
from arches_render.generators.layers.material_stacks import (AIR, BEDROCK, ROCK, SAND, SANDSTONE, SOLID,
                                                              MaterialStacks)
from arches_render.generators.layers.operations import apply_operations
from arches_render.generators.layers.sculpt import sculpt
from arches_render.generators.layers.stabilization import slope_excess, stabilize
from arches_render.generators.layers.sweep import sweep

# Heights are integer quanta and the flow threshold is floor(d tan(alpha) / dz) quanta,
# so a stable slope is <= tan(alpha) exactly; the only slack is the float rounding of
# the check itself (values of order 1).
SLOPE_TOL = 1e-9


def rough_terrain(seed=0, n=40):
    """Bedrock with a ledge, a cave with an open side, and random granular columns on top."""
    rng = np.random.default_rng(seed)
    H = 2.0 + rng.uniform(0, 0.5, (n, n))
    H[:, n // 2:] += 3.0
    S = MaterialStacks.from_heightfield(H, 0.5, z0=0.0, z1=14.0, dz=0.01)
    cols = rng.choice(S.ncol, 300, replace=False)
    block = np.full((len(cols), 1000), -1, dtype=np.int16)
    for r in range(len(cols)):
        a = rng.integers(0, 600)
        block[r, a:a + rng.integers(50, 400)] = rng.choice([SAND, ROCK])
    cave = np.arange(5, 15) * n + n // 2 + 1
    cblock = np.full((len(cave), 300), -1, dtype=np.int16)
    cblock[:, :100] = AIR                                # a cave under the ledge, 2.5..3.5 m
    S = S.rewrite(cave, 250, cblock)
    return S.rewrite(cols, 300, block)


def test_stabilization_conserves_mass_and_respects_repose():
    S = rough_terrain()
    assert slope_excess(S) > 0.5                      # really unstable to begin with
    T, stats = stabilize(S)
    for m in (SAND, ROCK, BEDROCK):
        assert T.levels((m,)) == S.levels((m,))       # exact, in quanta
    assert slope_excess(T) <= SLOPE_TOL
    assert stats["moved_levels"] > 0
    # Material hanging in the air fell: no granular layer lies on air.
    for c in range(T.ncol):
        m = T.material[T.offsets[c]:T.offsets[c + 1]]
        assert not np.any(np.isin(m[1:], (SAND, ROCK)) & (m[:-1] == AIR))


@pytest.mark.parametrize("sand, rock", [(30.0, 40.0), (35.0, 45.0)])
def test_repose_angles_are_the_final_slopes(sand, rock):
    """A tall sand column spreads into a cone whose flanks sit just under the angle."""
    S = MaterialStacks.from_heightfield(np.zeros((41, 41)), 0.25, z0=-1.0, z1=12.0, dz=0.005)
    block = np.full((1, 2000), -1, dtype=np.int16)
    block[0, :] = SAND
    S = S.rewrite([20 * 41 + 20], 200, block)
    T, _ = stabilize(S, {SAND: sand, ROCK: rock})
    assert T.levels((SAND,)) == 2000
    angles = {SAND: sand, ROCK: rock}
    assert slope_excess(T, angles) <= SLOPE_TOL
    # The pile is not flattened more than needed: its steepest side is within a few
    # quanta per cell of the angle of repose.
    H = T.heights()
    steep = np.abs(np.diff(H, axis=1)).max() / T.cell
    assert math.tan(math.radians(sand)) - 4 * T.dz / T.cell <= steep <= math.tan(math.radians(sand)) + 1e-9


def test_deposit_adds_exactly_what_it_reports_and_lands_in_caves():
    S = rough_terrain(1)
    before = S.levels((SAND,))
    T, added = deposit(S, (10.0, 5.0), 3.0, 1.5)
    assert added > 0 and T.levels((SAND,)) == before + added
    U, _ = stabilize(T)
    assert U.levels((SAND,)) == before + added
    assert slope_excess(U) <= SLOPE_TOL
    # Dropped from inside the cave (z = 3 m) the sand lands on the cave floor (2.5 m).
    c = 8 * 40 + 21
    V, added = deposit(S, (0.5 * 21 + 0.25, 0.5 * 8 + 0.25), 0.4, 0.3, z=3.0)
    assert added > 0
    col = V.column(21, 8)
    sand = [(a, b) for m, a, b in col if m == "sand"]
    assert any(a == pytest.approx(2.5, abs=0.011) for a, _ in sand)
    assert V.heights().ravel()[c] == S.heights().ravel()[c]    # the roof is untouched


def test_erosion_conserves_volume_and_makes_rocks_in_ratio():
    H = np.full((30, 30), 2.0)
    H[:, 15:] = 8.0                                         # a cliff
    S = MaterialStacks.from_heightfield(H, 0.5, z0=0.0, z1=10.0, dz=0.01,
                                        column=(("sandstone", 3.0), ("bedrock", None)))
    T, eroded = erode(S, (7.6, 7.5, 5.0), 2.0, rho=0.7, roughness=0.2, seed=4)
    assert eroded > 0
    assert T.levels(SOLID) == S.levels(SOLID)
    rocks, sand = T.levels((ROCK,)), T.levels((SAND,))
    assert rocks + sand == eroded
    # Rounded per stack: within half a quantum per touched stack.
    assert abs(rocks - 0.7 * eroded) <= 0.5 * 100
    U, _ = stabilize(T)
    assert U.levels(SOLID) == S.levels(SOLID)
    assert slope_excess(U) <= SLOPE_TOL
    # The debris left the cliff and piled at its foot (x < 7.5).
    foot = U.heights()[10:20, 10:15]
    assert foot.max() > 2.0 + 0.1
    # Surface erosion only touches the top of the bedrock.
    V, n = erode(S, (10.0, 7.5, 8.0), 3.0, mode="surface", depth=0.2)
    assert 0 < n and V.levels((SAND,)) == n
    top = V.column(20, 15)
    assert top[-1][0] == "sand" and top[-1][2] - top[-1][1] == pytest.approx(0.2, abs=0.011)


def test_sculpt_adds_and_carves_near_the_surface():
    """One stroke moves a flat surface by sigma g(|v - c|) at most: f saturates at +-1 a
    kernel half-side ``sigma`` from the surface, so ``f +- g = 0`` lies within sigma of
    it (the paper's progressive displacement); strokes accumulate."""
    S = MaterialStacks.from_heightfield(np.full((30, 30), 3.0), 0.5, z0=0.0, z1=8.0, dz=0.01)
    sigma = 0.25                                            # default: half a cell
    g_at_v = (1 - 0.5 ** 2) ** 2                            # |v - c| = delta = R / 2
    A = sculpt(S, (7.5, 7.5, 3.4), 2.0, mode="add")          # v is projected down to z = 3
    assert A.levels(SOLID) > S.levels(SOLID)
    assert A.heights().max() == pytest.approx(3.0 + sigma * g_at_v, abs=0.05)
    B = A
    for _ in range(3):
        B = sculpt(B, (7.5, 7.5, 3.4), 2.0, mode="add")
    assert B.heights().max() > A.heights().max() + 0.2
    # Only inside the primitive's ball (centre 1 m below the surface, radius 2).
    far = np.ones((30, 30), dtype=bool)
    far[9:21, 9:21] = False
    assert np.array_equal(A.heights()[far], S.heights()[far])
    R = sculpt(S, (7.5, 7.5, 2.8), 2.0, mode="remove")
    assert R.levels(SOLID) < S.levels(SOLID)
    assert R.heights().min() == pytest.approx(3.0 - sigma * g_at_v, abs=0.05)
    with pytest.raises(ValueError, match="no surface"):
        sculpt(S, (30.0, 30.0, 7.5), 0.5)
    with pytest.raises(ValueError, match="delta"):
        sculpt(S, (7.5, 7.5, 3.0), 1.0, delta=2.0)


def test_sweep_crack_follows_the_surface():
    H = np.full((30, 30), 4.0)
    S = MaterialStacks.from_heightfield(H, 0.5, z0=0.0, z1=6.0, dz=0.01, column=(("sandstone", 5.0),))
    vee = [[-0.8, 0.5], [0.8, 0.5], [0.0, -2.0]]
    T = sweep(S, [[2.0, 7.5, 0.0], [13.0, 7.5, 0.0]], vee, mode="crack")
    # The V-shaped crack reaches about 2 m below the surface on its axis, less aside.
    h = T.heights()
    assert h[15, 15] < 2.6 and h[15, 15] > 1.5
    assert h[13, 15] > h[15, 15] and h[5, 15] == pytest.approx(4.0)
    assert T.levels(SOLID) < S.levels(SOLID)


def test_operation_lists_are_deterministic():
    ops = [dict(tool="sweep", path=[[2, 7.5, 3], [13, 7.5, 3]], profile=[[-1, -1], [1, -1], [0, 1.5]],
                roughness=0.3),
           dict(tool="erode", center=[7.5, 7.5, 4.0], radius=2.0, rho=0.4, roughness=0.3),
           dict(tool="deposit", center=[4.0, 4.0], radius=2.0, amount=1.0)]
    S = MaterialStacks.from_heightfield(np.full((30, 30), 5.0), 0.5, z0=0.0, z1=8.0, dz=0.01)
    A, log = apply_operations(S, ops, seed=5)
    B, _ = apply_operations(S, ops, seed=5)
    C, _ = apply_operations(S, ops, seed=6)
    assert A == B and A != C
    assert [e["tool"] for e in log] == ["sweep", "erode", "deposit"]
    assert A.levels(SOLID) == S.levels(SOLID) - _carved(S, ops[0]) + log[2]["deposited"]


def _carved(S, op):
    op = dict(op)
    op.pop("tool")
    return S.levels(SOLID) - sweep(S, seed=5, **op).levels(SOLID)


@pytest.mark.parametrize("op, match", [
    (dict(tool="melt"), "unknown tool"),
    (dict(tool="deposit", center=[1, 1], radius=1, amount=1, material="bedrock"), "granular"),
    (dict(tool="deposit", center=[1, 1], radius=-1, amount=1), "> 0"),
    (dict(tool="erode", center=[1, 1, 1], radius=1, rho=2.0), "rho"),
    (dict(tool="sweep", path=[[1, 1, 1]], profile=[[0, 0], [1, 0], [0, 1]]), "at least 2"),
    (dict(tool="sweep", path=[[1, 1, 1], [2, 2, 2]], profile=[[0, 0], [1, 0]]), "profile"),
    (dict(tool="erode", center=[1, 1, 1], radius=1, colour="red"), "colour"),
])
def test_bad_operations(op, match):
    S = MaterialStacks.from_heightfield(np.full((8, 8), 2.0), 0.5, z0=0.0, z1=4.0, dz=0.01)
    with pytest.raises(ValueError, match=match):
        apply_operations(S, [op])


def test_angles_must_be_sane():
    S = MaterialStacks.from_heightfield(np.full((8, 8), 2.0), 0.5, z0=0.0, z1=4.0, dz=0.01)
    with pytest.raises(ValueError, match="angle of repose"):
        stabilize(S, {SAND: 95.0})
    assert SANDSTONE not in (SAND, ROCK)
