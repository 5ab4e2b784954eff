"""One 64-byte record a skeletal primitive, read by a single packet gather.

Why. A ray step over a skeletal set visits the primitives of its cell's list, and each
visit read a dozen per-primitive constants (end point, axis, radius, core, energy,
group, the bounds' constants) from as many arrays: a dozen scalar gathers on every
SIMD packet and as many cache lines. Side by side, the sixteen floats of a primitive
fill one cache line and are one packet gather (:mod:`arches_render.field.packed_columns`).
The values are the float32 numbers the separate arrays held, so fields and bounds
keep their bits. Goblins (160x90, 8 spp): the set's step 32 -> 24 ns a point, the
render 3.24 -> 2.83 s.

Layout (float32 slots): ``a`` (0-2), ``b - a`` (3-5), ``1 / |b - a|^2`` (6), ``R`` (7),
core ``c`` (8), energy ``e`` (9), group id (10, uint32 bits), ``R (1 + span)`` (11),
``[a != b]`` (12), the star noise's slope factor ``R A L_n`` (13), ``D_min`` (14), the
star distance's slope ``L_d`` (15) (:mod:`.skeletal_set`, :mod:`.skeletal_bounds`).
Slots a set has no use for hold 0.

Point records. A set of points without noise or curves (the sea's carving spheres, 48,143
at the paper's scale) reads only ``a``, ``R``, ``c``, ``e``, ``D_min`` and ``L_d``: its
32-byte record (:func:`pack_point_records`, ``POINT_RECORD`` floats: ``a`` (0-2), ``R``
(3), ``c`` (4), ``e`` (5), ``D_min`` (6), ``L_d`` (7)) halves the records' memory
(3.08 -> 1.54 MB at Sea scale). :func:`gather_point` returns the same
:class:`Primitive` with the constants a point implies: ``b - a = 0`` and
``1 / |b - a|^2 = 0`` (the projection ``t = 0``, as ``0 * 1e30`` gave), ``D_max = R``
(``R (1 + 0)``), no group, segment or noise factor; values and bounds keep their bits.
"""

from __future__ import annotations

from typing import NamedTuple

import mitsuba as mi
import numpy as np

from arches_render.field.packed_columns import gather_columns, pack_columns, uint_column

#: Floats a record (one 64-byte cache line).
RECORD = 16
#: Floats a point record (half a cache line).
POINT_RECORD = 8


class Primitive(NamedTuple):
    """The constants of primitive ``k`` on each lane (layout in the module docstring)."""

    a: mi.Point3f
    ba: mi.Vector3f
    inv_len2: mi.Float
    R: mi.Float
    core: mi.Float
    e: mi.Float
    group: mi.UInt32
    reach_R: mi.Float
    seg: mi.Float
    noise_K: mi.Float
    Dmin: mi.Float
    Ld: mi.Float


def pack_records(a, b, R, core, e, group, reach_R=None, seg=None, noise_K=None, Dmin=None, Ld=None) -> mi.Float:
    """The records of ``n`` primitives, 64-byte aligned (absent constants: 0).

    Parameters
    ----------
    a, b : ndarray
        ``(n, 3)`` skeleton end points.
    R, core, e : ndarray
        ``(n,)`` radii of influence, core radii and energies.
    group : ndarray
        ``(n,)`` integer group ids.
    reach_R, seg, noise_K, Dmin, Ld : ndarray, optional
        ``(n,)`` constants of the bounds (float32 values kept as given).

    Returns
    -------
    mi.Float
        ``n * RECORD`` floats, primitive after primitive.
    """
    zero = np.zeros(len(a), dtype=np.float32)
    ba = b - a
    columns = [a[:, 0], a[:, 1], a[:, 2], ba[:, 0], ba[:, 1], ba[:, 2],
               1.0 / np.maximum(np.sum(ba ** 2, axis=1), 1e-30), R, core, e,
               np.asarray(group, dtype=np.uint32)]
    columns += [zero if c is None else c for c in (reach_R, seg, noise_K, Dmin, Ld)]
    records, width = pack_columns(columns)
    assert width == RECORD
    return records


def gather_primitive(records, k) -> Primitive:
    """:class:`Primitive` ``k`` (per lane) from :func:`pack_records`' records, in one
    packet gather.

    Parameters
    ----------
    records : mi.Float
        The records of :func:`pack_records`.
    k : mi.UInt32
        Primitive index per lane.

    Returns
    -------
    Primitive
    """
    v = gather_columns(records, k, RECORD, RECORD)
    return Primitive(mi.Point3f(v[0], v[1], v[2]), mi.Vector3f(v[3], v[4], v[5]), v[6], v[7], v[8], v[9],
                     uint_column(v[10]), v[11], v[12], v[13], v[14], v[15])


def pack_point_records(a, R, core, e, Dmin, Ld) -> mi.Float:
    """The 32-byte records of ``n`` points without noise or curves (module docstring).

    Parameters
    ----------
    a : ndarray
        ``(n, 3)`` centres.
    R, core, e : ndarray
        ``(n,)`` radii of influence, core radii and energies.
    Dmin, Ld : ndarray
        ``(n,)`` float32 constants of the bounds (kept as given).

    Returns
    -------
    mi.Float
        ``n * POINT_RECORD`` floats, point after point.
    """
    records, width = pack_columns([a[:, 0], a[:, 1], a[:, 2], R, core, e, Dmin, Ld])
    assert width == POINT_RECORD
    return records


def gather_point(records, k) -> Primitive:
    """:class:`Primitive` ``k`` (per lane) from :func:`pack_point_records`' records, in one
    packet gather, with the constants a point implies (module docstring).

    Parameters
    ----------
    records : mi.Float
        The records of :func:`pack_point_records`.
    k : mi.UInt32
        Point index per lane.

    Returns
    -------
    Primitive
    """
    v = gather_columns(records, k, POINT_RECORD, POINT_RECORD)
    zero = mi.Float(0.0)
    return Primitive(mi.Point3f(v[0], v[1], v[2]), mi.Vector3f(0.0), zero, v[3], v[4], v[5], mi.UInt32(0),
                     v[3], zero, zero, v[6], v[7])
