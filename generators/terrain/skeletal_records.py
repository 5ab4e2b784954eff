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

Point records. A set of points without noise or curves whose cores are all one radius
(the sea's carving spheres, 48,143 at the paper's scale) reads only ``a``, ``R`` and
``e`` per point: its 16-byte record (:func:`pack_point_records`, ``POINT_RECORD``
floats: ``a`` (0-2), ``R`` (3)) beside an array of energies, 20 bytes a point instead
of 64 (3.08 -> 0.96 MB at Sea scale). :func:`gather_point` returns the same
:class:`Primitive` with the constants a point implies: ``b - a = 0`` and
``1 / |b - a|^2 = 0`` (the projection ``t = 0``, as ``0 * 1e30`` gave), ``D_max = R``
(``R (1 + 0)``), no group, segment or noise factor, the set's core, and the bounds'
``D_min = R (1 - 1e-6)`` and ``L_d = (1 / R)(1 + 1e-6)`` computed in float32 from the
stored ``R`` (:func:`noise_free_constants`: every noise-free set stores the same numbers
in its records, so values and bounds keep their bits between both layouts).
"""

from __future__ import annotations

from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render.field.node import opaque_float
from arches_render.field.packed_columns import gather_columns, pack_columns, uint_column

#: Floats a record (one 64-byte cache line).
RECORD = 16
#: Floats a point record (a quarter of a cache line).
POINT_RECORD = 4
#: The shave of ``D_min`` and the growth of ``L_d`` of noise-free primitives (float32):
#: ``R`` and ``1 / R`` exactly, kept on the safe side of float32 rounding.
DMIN_SCALE, LD_SCALE = np.float32(1.0 - 1e-6), np.float32(1.0 + 1e-6)


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


def noise_free_constants(R):
    """``(D_min, L_d)`` (float32) of noise-free primitives of radii ``R``: ``R (1 - 1e-6)``
    and ``(1 / R)(1 + 1e-6)`` in float32 arithmetic from the float32 radii, as
    :func:`gather_point` computes them (IEEE products and quotient: the same bits).

    Parameters
    ----------
    R : ndarray
        ``(n,)`` radii of influence.

    Returns
    -------
    (ndarray, ndarray)
    """
    R = np.asarray(R, dtype=np.float32)
    return R * DMIN_SCALE, (np.float32(1.0) / R) * LD_SCALE


def pack_point_records(a, R) -> mi.Float:
    """The 16-byte records of ``n`` points without noise or curves (module docstring).

    Parameters
    ----------
    a : ndarray
        ``(n, 3)`` centres.
    R : ndarray
        ``(n,)`` radii of influence.

    Returns
    -------
    mi.Float
        ``n * POINT_RECORD`` floats, point after point.
    """
    records, width = pack_columns([a[:, 0], a[:, 1], a[:, 2], R])
    assert width == POINT_RECORD
    return records


class PointConstants(NamedTuple):
    """What a set of point records holds beside them: the points' energies, the set's
    core radius, and :data:`DMIN_SCALE` and :data:`LD_SCALE` (opaque: a literal might
    fold into a quotient)."""

    energies: mi.Float
    core: mi.Float
    dmin_scale: mi.Float
    ld_scale: mi.Float

    @classmethod
    def of(cls, e, core):
        """The constants of points of energies ``e`` (ndarray) and one ``core`` radius."""
        return cls(mi.Float(np.asarray(e, dtype=np.float32)), opaque_float(core),
                   opaque_float(float(DMIN_SCALE)), opaque_float(float(LD_SCALE)))


def gather_point(records, constants, k) -> Primitive:
    """:class:`Primitive` ``k`` (per lane) from :func:`pack_point_records`' records (one
    packet gather) and the energies (one gather), with the constants a point implies
    (module docstring).

    Parameters
    ----------
    records : mi.Float
        The records of :func:`pack_point_records`.
    constants : PointConstants
        The energies and the set's constants.
    k : mi.UInt32
        Point index per lane.

    Returns
    -------
    Primitive
    """
    v = gather_columns(records, k, POINT_RECORD, POINT_RECORD)
    R, zero = v[3], mi.Float(0.0)
    return Primitive(mi.Point3f(v[0], v[1], v[2]), mi.Vector3f(0.0), zero, R, constants.core,
                     dr.gather(mi.Float, constants.energies, k), mi.UInt32(0), R, zero, zero,
                     R * constants.dmin_scale, (1.0 / R) * constants.ld_scale)
