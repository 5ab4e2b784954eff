"""Material stacks (Peytavie et al. 2009, 3.2): layout, conversions, files, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from arches_render.generators.layers.material_stacks import (AIR, BEDROCK, SAND, SANDSTONE, SOLID,
                                                              MaterialStacks)


def bumpy(n=24, m=20, seed=0):
    rng = np.random.default_rng(seed)
    x = np.linspace(0, 1, m)
    y = np.linspace(0, 1, n)
    return 2.0 + 3.0 * np.outer(np.sin(3 * y), np.cos(2 * x)) + rng.uniform(0, 0.3, (n, m))


def test_heightfield_round_trip_within_half_a_quantum():
    H = bumpy()
    S = MaterialStacks.from_heightfield(H, 0.5, origin=(1.0, -2.0), column=(("sand", 0.4), ("bedrock", None)))
    H2, extent = S.to_heightfield()
    assert H2.shape == H.shape
    assert np.abs(H2 - H).max() <= 0.5 * S.dz + 1e-9
    assert extent == pytest.approx((1.25, -1.75, 1.0 + 19.5 * 0.5, -2.0 + 23.5 * 0.5))
    # Through a Heightfield node of the language and back.
    from helpers import variant
    variant()
    from arches_render.field import Heightfield
    hf = Heightfield(H2, extent)
    assert np.array_equal(hf.heights_np, H2)


def test_material_column_bands_from_the_surface_down():
    H = np.full((3, 4), 5.0)
    S = MaterialStacks.from_heightfield(H, 1.0, z0=0.0, z1=8.0, dz=0.01,
                                        column=(("sand", 0.5), ("sandstone", 2.0), ("bedrock", None)))
    layers = S.column(2, 1)
    assert [m for m, _, _ in layers] == ["bedrock", "sandstone", "sand"]
    assert layers[0][2] == pytest.approx(2.5)
    assert layers[1][2] == pytest.approx(4.5)
    assert layers[2][2] == pytest.approx(5.0)
    assert S.volume((SAND,)) == pytest.approx(12 * 0.5)
    assert S.volume((SANDSTONE,)) == pytest.approx(12 * 2.0)


def test_layout_is_compact_csr():
    S = MaterialStacks.from_heightfield(bumpy(), 0.5, column=(("sand", 0.4), ("bedrock", None)))
    assert S.offsets.dtype == np.uint32 and S.material.dtype == np.uint8 and S.count.dtype == np.uint16
    assert S.nbytes() == 4 * (S.ncol + 1) + 3 * len(S.material)
    # Canonical: no empty layer, no two equal neighbours, no trailing air.
    assert np.all(S.count > 0)
    for c in range(S.ncol):
        m = S.material[S.offsets[c]:S.offsets[c + 1]]
        assert np.all(m[1:] != m[:-1]) and m[-1] != AIR


def test_rewrite_cuts_a_cave_and_keeps_the_rest():
    S = MaterialStacks.from_heightfield(np.full((4, 4), 3.0), 1.0, z0=0.0, z1=4.0, dz=0.01)
    block = np.full((1, 100), -1, dtype=np.int16)
    block[0, 20:60] = AIR
    S2 = S.rewrite([5], 100, block)
    col = S2.column(1, 1)
    assert [m for m, _, _ in col] == ["bedrock", "air", "bedrock"]
    assert [z for _, a, b in col for z in (a, b)] == pytest.approx([0.0, 1.2, 1.2, 1.6, 1.6, 3.0])
    assert S2.levels() == S.levels() - 40
    assert S2.column(0, 0) == S.column(0, 0)
    off, bot, top = S2.intervals(SOLID)
    assert list(np.diff(off)).count(2) == 1
    assert bot[off[5] + 1] == pytest.approx(1.6) and top[off[5]] == pytest.approx(1.2)


def test_voxelize_a_field_node():
    from helpers import variant
    variant()
    from arches_render import field as F
    arch = F.Difference(F.Box([2.0, 2.0, 1.5], [1.5, 0.5, 1.5]), F.Sphere([2.0, 2.0, 0.0], 1.0))
    S = MaterialStacks.from_field(arch, (0.0, 0.0, 4.0, 4.0), 0.25, (0.0, 4.0), 0.005)
    # The column through the sphere's top: bedrock from 1.0 (sphere top) to 3.0 (box top).
    layers = S.column(7, 7)   # axis at (1.875, 1.875), 0.177 m from the sphere's axis
    solid = [(a, b) for m, a, b in layers if m != "air"]
    assert len(solid) == 1
    assert solid[0][0] == pytest.approx(np.sqrt(1 - 2 * 0.125 ** 2), abs=0.01)
    assert solid[0][1] == pytest.approx(3.0, abs=0.01)
    # Outside the box nothing.
    assert S.column(0, 0) == []


def test_save_load_round_trip_and_determinism(tmp_path):
    S = MaterialStacks.from_heightfield(bumpy(), 0.5, column=(("sand", 0.4), ("bedrock", None)))
    S.save(tmp_path / "s.npz")
    T = MaterialStacks.load(tmp_path / "s.npz")
    assert T == S and T.digest() == S.digest()
    assert MaterialStacks.from_heightfield(bumpy(), 0.5, column=(("sand", 0.4), ("bedrock", None))) == S
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="cannot read material stacks"):
        MaterialStacks.load(tmp_path / "bad.npz")


@pytest.mark.parametrize("kwargs, match", [
    (dict(column=(("air", 1.0), ("bedrock", None))), "air"),
    (dict(column=(("lava", 1.0),)), "unknown material"),
    (dict(column=(("bedrock", None), ("sand", 1.0))), "only the last"),
    (dict(column=(("sand", -1.0), ("bedrock", None))), "> 0"),
    (dict(dz=1e-6), "n_levels"),
    (dict(z0=10.0, z1=5.0), "z1 must exceed z0"),
])
def test_bad_input_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MaterialStacks.from_heightfield(bumpy(), 0.5, **kwargs)


def test_bad_heights():
    H = bumpy()
    H[2, 3] = np.nan
    with pytest.raises(ValueError, match="finite"):
        MaterialStacks.from_heightfield(H, 0.5)
    assert BEDROCK in SOLID
