"""Per-sample columns stored side by side, read with one packet gather.

Why. A field step reads several numbers of one grid sample or one primitive (a
heightfield cell's window maxima, its derivative ranges). Stored as separate arrays,
each is its own scalar gather: on AVX2 two 8-lane ``vgatherdps`` of ~20 micro-ops
for a 16-lane packet, and its own cache line. Side by side, padded to a power of two,
they are one *packet gather* (``dr.gather(ArrayXf, ..., shape=(width, n))``:
contiguous vector loads and a transpose in registers; Dr.Jit's
:py:attr:`drjit.JitFlag.PacketOps`) and one cache line. The values are the same
float32 numbers, so every field and bound keeps its bits.

References
----------
Jakob, W. et al. (2024). Dr.Jit reference, ``drjit.gather`` (packet memory operations
for power-of-two sized records).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .node import jit_floats


def pack_columns(columns) -> tuple[mi.Float, int]:
    """Interleave equally sized arrays, sample after sample, padded with zeros.

    Parameters
    ----------
    columns : sequence of array_like
        ``m`` arrays of ``n`` values each (any shape; flattened in C order). Integer
        arrays (indices, counts, ids below 2^32) are stored as the float32 bits of
        their uint32 values: read them back with :func:`uint_column`.

    Returns
    -------
    records : mi.Float
        ``n * width`` float32 values: sample ``k``'s columns at ``k * width + c``, in
        64-byte-aligned memory (:func:`~.node.jit_floats`: Dr.Jit emits a packet gather
        only from aligned memory, else one gather a column).
    width : int
        The smallest power of two ``>= m`` (1 when ``m = 0``).
    """
    flat = [_float_bits(c).ravel() for c in columns]
    width = 1 << max(len(flat) - 1, 0).bit_length()
    n = len(flat[0]) if flat else 0
    rec = np.zeros((n, width), dtype=np.float32)
    for i, c in enumerate(flat):
        rec[:, i] = c
    return jit_floats(rec), width


def gather_columns(records, k, width: int, count: int) -> list:
    """The first ``count`` columns of sample ``k`` (per lane) of :func:`pack_columns`'
    ``records``.

    Parameters
    ----------
    records : mi.Float
        Packed columns.
    k : mi.UInt32
        Sample index per lane.
    width, count : int
        The records' width and how many of its columns to return.

    Returns
    -------
    list of mi.Float
    """
    if count == 0:
        return []
    if width == 1:
        return [dr.gather(mi.Float, records, k)]
    v = dr.gather(mi.ArrayXf, records, k, shape=(width, dr.width(k)))
    return [v[i] for i in range(count)]


def uint_column(column) -> mi.UInt32:
    """An integer column of :func:`pack_columns` read back: its bits as ``mi.UInt32``."""
    return dr.reinterpret_array(mi.UInt32, column)


def _float_bits(column) -> np.ndarray:
    """float32 values as they are; integers as the float32 view of their uint32 bits
    (the loads and shuffles of a packet gather move bits, never convert them)."""
    c = np.asarray(column)
    if c.dtype.kind in "iub":
        if c.size and (c.min() < 0 or c.max() > 0xFFFFFFFF):
            raise ValueError("integer columns must hold values in [0, 2^32)")
        return np.ascontiguousarray(c, dtype=np.uint32).view(np.float32)
    return np.asarray(c, dtype=np.float32)
