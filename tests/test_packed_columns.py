"""Packed per-sample columns and skeletal primitive records: the same numbers, one packet gather."""

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from arches_render import backend

backend.set_variant()

from arches_render.field.packed_columns import gather_columns, pack_columns, uint_column  # noqa: E402
from arches_render.generators.terrain.skeletal_records import (  # noqa: E402
    RECORD, Primitive, gather_primitive, pack_records)


def _jit_kernels(fn):
    """``(outputs, IR of the JIT kernels)`` that evaluating ``fn()`` launched."""
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        out = fn()
        dr.eval(out)
        irs = [k["ir"].getvalue() for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    return out, irs


@pytest.mark.parametrize("m", [1, 2, 3, 4, 5, 8, 11])
def test_columns_read_back_bit_for_bit(m):
    rng = np.random.default_rng(m)
    n = 257
    cols = [rng.normal(size=n).astype(np.float32) for _ in range(m)]
    cols[0][:3] = [np.inf, -0.0, 1e-42]  # an infinity, a negative zero, a subnormal
    records, width = pack_columns(cols)
    assert width == 1 << (m - 1).bit_length() and dr.width(records) == n * width
    k = rng.integers(0, n, 1000).astype(np.uint32)
    got, irs = _jit_kernels(lambda: gather_columns(records, mi.UInt32(k), width, m))
    for c, g in zip(cols, got):
        assert np.array_equal(c[k].view(np.uint32), g.numpy().view(np.uint32))
    if width > 1:
        # Aligned records: Dr.Jit emits a packet gather, not one gather a column.
        assert any("gather_" in ir and "xf32" in ir for ir in irs), "not a packet gather"


def test_integer_columns_keep_their_bits():
    """Ids stored as float bits, including patterns that are NaNs and subnormals as floats."""
    ids = np.array([0, 1, 5, 0x7FC00001, 0x7F800001, 0xFFFFFFFF, 0x80000000, 123456789], dtype=np.int64)
    records, width = pack_columns([np.arange(len(ids), dtype=np.float32), ids])
    _, v = gather_columns(records, mi.UInt32(np.arange(len(ids), dtype=np.uint32)[::-1].copy()), width, 2)
    assert np.array_equal(uint_column(v).numpy(), ids[::-1].astype(np.uint32))
    with pytest.raises(ValueError):
        pack_columns([np.array([-1, 2])])


def test_primitive_records_hold_the_constants():
    rng = np.random.default_rng(7)
    n = 100
    a, b = rng.normal(size=(n, 3)) * 50, rng.normal(size=(n, 3)) * 50
    b[:10] = a[:10]  # points: |b - a| = 0
    R, core, e = rng.uniform(1, 9, n), rng.uniform(0, 2, n), rng.normal(size=n)
    group = rng.integers(0, 2 ** 32, n)
    extra = [rng.uniform(0, 5, n).astype(np.float32) for _ in range(5)]
    records = pack_records(a, b, R, core, e, group, *extra)
    assert dr.width(records) == n * RECORD
    k = rng.integers(0, n, 500).astype(np.uint32)
    # (a tuple: Dr.Jit's eval does not traverse a NamedTuple)
    fields, irs = _jit_kernels(lambda: tuple(gather_primitive(records, mi.UInt32(k))))
    prim = Primitive(*fields)
    f32 = lambda x: np.asarray(x, dtype=np.float32)[k]  # noqa: E731
    want = {
        "a": [f32(a[:, i]) for i in range(3)], "ba": [f32(b[:, i] - a[:, i]) for i in range(3)],
        "inv_len2": f32(1.0 / np.maximum(np.sum((b - a) ** 2, axis=1), 1e-30)), "R": f32(R),
        "core": f32(core), "e": f32(e), "reach_R": extra[0][k], "seg": extra[1][k],
        "noise_K": extra[2][k], "Dmin": extra[3][k], "Ld": extra[4][k],
    }
    for name, w in want.items():
        g = getattr(prim, name)
        got = [g.x, g.y, g.z] if isinstance(w, list) else [g]
        for gi, wi in zip(got, w if isinstance(w, list) else [w]):
            assert np.array_equal(gi.numpy().view(np.uint32), wi.view(np.uint32)), name
    assert np.array_equal(prim.group.numpy(), group[k].astype(np.uint32))
    assert any("gather_" in ir and "xf32" in ir for ir in irs), "not a packet gather"


def test_heightfield_lookups_read_the_grid():
    """A cell's packed corners are its four samples in order (h00, h10, h01, h11), and the
    packed window maxima are each window's maximum: on a grid that is not symmetric, at
    every cell's centre."""
    from arches_render.field import Heightfield
    from arches_render.field.heightfield import _window_max
    rng = np.random.default_rng(3)
    H = rng.normal(size=(9, 140)) * 10  # ny != nx: rows and columns cannot be swapped
    hf = Heightfield(H, (0.0, 0.0, 139.0, 16.0))
    j, i = np.meshgrid(np.arange(8), np.arange(139), indexing="ij")
    x = (i + 0.5) * hf.dx
    y = (j + 0.5) * hf.dy
    h00, h10, h01, h11, _, _ = hf.patch(mi.Float(x.ravel().astype(np.float32)),
                                        mi.Float(y.ravel().astype(np.float32)))
    f32 = lambda a: a.astype(np.float32).ravel()  # noqa: E731
    for got, want in ((h00, H[:-1, :-1]), (h10, H[:-1, 1:]), (h01, H[1:, :-1]), (h11, H[1:, 1:])):
        assert np.array_equal(got.numpy(), f32(want))
    k = mi.UInt32((j * hf.nx + i).ravel().astype(np.uint32))
    assert len(hf.windows) == 4
    for w, got in zip(hf.windows, hf.window_maxima(k)):
        assert np.array_equal(got.numpy(), f32(_window_max(H, w)[:-1, :-1]))
