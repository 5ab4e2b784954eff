"""Large sets of skeletal sculpting primitives (points, segments, curves) behind a grid.

Each primitive ``i`` has a skeleton (the segment ``[a_i, b_i]``; a point when
``a_i = b_i``), an optional constant-field core of radius ``c_i`` (a volumetric sphere
or capsule), a radius of influence ``R_i`` and a signed energy ``e_i``. With ``s(p)``
the projection of ``p`` on the skeleton and ``r = |p - s(p)|``, its field is the
compact falloff of Paris et al. (2019, Sec. 5.2) of the *anisotropic star* distance

    d~(p) = max(r - c_i, 0) / D(p),    D(p) = R_i (1 + A n(v(p) / lambda)),
    u(p) = (p - s(p)) / r,    v(p) = s(p) + (c_i + R_i) u(p),

``F_i(p) = e_i g(d~)``, ``g(x) = (1 - x^2)^3`` on ``[0, 1)``. The noise ``n`` (our fBm)
is evaluated on the boundary point ``v(p)`` so each ray from the skeleton sees one
radius: the shape stays star-shaped around its skeleton (no holes, no floating
pieces), as in the paper. The paper writes ``R + t(v(p))``; we scale the noise by
``R_i`` (``A`` relative) so one set can hold primitives of very different sizes.

A *curve* is a polyline whose segments share a ``group`` id; its field is
``e g(min_j d~_j) = max_j`` (for ``e >= 0``) of its segments, so joints do not bulge.

Combination (``combine``): ``"sum"`` is the paper's blend ``f_A + f_B`` (negative
energies carve when the set is summed with a terrain), ``"max"`` the union of
non-negative primitives. The node's value is ``F(p) - threshold``.

Acceleration: the primitives' support boxes (skeleton box grown by
``c_i + R_i (1 + A N)``, ``N`` the fBm range) are listed per cell of a uniform grid
(CSR lists built by :func:`arches_render.field.primitive_set.grid_lists`, the
grid of :class:`~arches_render.field.CapsuleSet`; the per-cell arrays are then
kept only in the bricks (8^3, thinner for a thin grid, smaller for a carving set's
band where that takes less memory) where some datum is not 0,
:class:`~arches_render.field.brick_grid.BrickLayout`); a point loops over its own
cell's list in one Dr.Jit ``while_loop``. Unlike the capsule set this is *exact*:
a primitive missing from the cell contributes exactly 0 there (compact support), so
the points of a carving set list only the cells their (grown) ball touches.
The noise of a listed primitive is evaluated only where ``max(r - c, 0) < R (1 + A N)``.

Lipschitz bound (derived). Inside the support (``d~ < 1``), with ``rho = max(r - c, 0)``,
``|grad rho| <= 1``, ``|grad u| <= 1/r``, ``|grad s| <= sigma_s`` (0 for a point, 1 for
a segment), ``D_min = R (1 - A N)``, ``D_max = R (1 + A N)``, ``L_n`` the fBm slope:

    |grad d~| <= 1/D_min + rho |grad D| / D_min^2,
    rho |grad D| <= (R A L_n / lambda) rho (sigma_s + (c + R)/r)
                 <= (R A L_n / lambda) (sigma_s D_max + c + R),

so ``|grad F_i| <= |e_i| G_SLOPE L_i`` (``G_SLOPE`` = max ``|g'|``), and ``g' = 0`` at the
support's edge makes this hold everywhere. For ``"sum"``, at any point only the
primitives of its cell act, one segment per curve at a time, so
``L = max_cells sum_groups max_members |e| G_SLOPE L_i``; for ``"max"``,
``L = max_i e_i G_SLOPE L_i``. ``value_max`` / ``value_min`` bound ``F`` the same way.

Local bounds: the per-cell sums, maximized over each cell's 3x3x3 neighbourhood,
bound the slope and the value of ``F`` in the ball of one cell edge around any point
of the cell (:meth:`SkeletalSet.local_lipschitz`); the erosion node and the sum use
them so that one crowded cluster does not slow rays everywhere.

Distance bounds below the threshold (the sum's caps), local slopes in small balls
and the cores of carving sets are per-primitive bounds, derived and computed in
:mod:`.skeletal_bounds`; the loop over a point's list here combines them.
The constructor's arguments are checked, and the primitives sorted by group, in
:mod:`.skeletal_params`.

Footprint level of detail (:mod:`arches_render.field.lod`): with a footprint the
star noise keeps the octaves the cone resolves. Its range is at most the full one
(``D_min``, ``D_max`` hold), the slope of the truncated noise is at most the full one
and the fade adds ``|grad n| <= L_n' kappa s`` (``s`` the footprint's rate), so
``|grad D| <= (R A L_n / lambda) (sigma_s + (c + R)/r + kappa s)`` and, with
``rho <= D_max < 2 (c + R)``, every slope bound above grows by at most the factor
``1 + 2 kappa s`` (:attr:`lod_kappa`); the geometric level bounds add ``kappa s`` to
their ``|grad D|`` term.

References
----------
Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
38(5), Sec. 3.3 (falloff), 5.2 (sculpting primitives, anisotropic star noise),
Sec. 6 (a hierarchy over primitive boxes for ~10^6 queries/s).
Crespin, B., Blanc, C., Schlick, C. (1996). Implicit sweep objects. CGF 15(3).
Wyvill, B., Guy, A., Galin, E. (1999). Extending the CSG tree. CGF 18(2).
"""

from __future__ import annotations


import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render.field.lod import OctaveLOD
from arches_render.field.node import Node, box_distance, opaque_float, refill
from arches_render.field.noise import fbm_lipschitz
from arches_render.field.brick_grid import BRICK, BrickLayout, list_entry
from arches_render.field.primitive_set import empty_distance, grid_lists, unlisted_gaps

from .falloff import G_SLOPE
from .skeletal_bounds import (FAR, below_all, cell_tables, core_bound, distance_slopes, footprint_error, level_bound,
                              level_shape, local_slope, quiet_within, slant_cap, slanted_bound, stored_tables)
from .skeletal_params import noise_params, primitive_arrays
from .skeletal_records import (POINT_RECORD, RECORD, PointConstants, gather_point, gather_primitive,
                               noise_free_constants, pack_point_records, pack_records)
from .star_falloff import star_falloff
from .support_distances import brick_centre_distances, centre_distances, centre_offsets

#: Largest radius of the balls in which ``eval_local`` bounds slopes, in cell edges.
SLOPE_REACH = 0.125

#: How far the near lists (the primitives the distance bounds below the threshold
#: loop over) reach beyond a cell, in cell edges: those bounds stop there. Shorter
#: lists cost less per step and longer ones allow longer steps; over the goblins'
#: hoodoos (160x90, 8 spp) 1.0 -> 0.5 -> 0.25 -> 0.125 took the near lists from 6.9 to
#: 4.6 and 3.7 primitives a point (1.0, 0.5, 0.25) and the render from 2.65 to 2.08,
#: 1.93 and 2.02 s (camera steps 43, 47, 53, 67). At least SLOPE_REACH: the near lists
#: hold the slope lists.
NEAR_REACH = 0.25

#: Cell edges past the near lists the level bounds may reach: each cell stores its gap to
#: the nearest support left out of its near list (:func:`~arches_render.field.primitive_set.unlisted_gaps`),
#: up to this. Goblins (320x180): camera steps 49.6 -> 39.9 a ray with the short lists
#: (lists grown by 2 cell edges: 33.5, but dearer steps); a reach of 4 bought nothing more.
UNLISTED_REACH = 2.0

#: List entries (cell, slope, near) from which a set of fewer than 2^16 primitives stores them
#: in 16 bits (Sea scale: 2.2 M); below, unpacking (a shift and a mask) is not worth it.
NARROW_LISTS = 1 << 20


class SkeletalSet(Node):
    """Sum (or union) of skeletal primitives with compact falloff (see module docstring).

    Parameters
    ----------
    a : array_like
        ``(N, 3)`` first skeleton end points (the centre of a point primitive).
    b : array_like, optional
        ``(N, 3)`` second end points; ``None`` or equal to ``a`` for points.
    radius : array_like
        ``(N,)`` radii of influence ``R_i > 0`` (or one number).
    energy : array_like
        ``(N,)`` energies ``e_i`` (field units, i.e. metres near a terrain surface).
    core : array_like
        ``(N,)`` core radii ``c_i >= 0`` (constant field within ``c_i`` of the skeleton).
    group : array_like, optional
        ``(N,)`` integer curve ids: a group's segments form one polyline primitive and
        must share their energy. The arrays (``a_np``, ...) are then stored sorted by
        group (stable), which is the order of ``group_np``.
    noise : dict, optional
        Star noise ``amplitude`` (A, relative to R), ``wavelength`` (lambda, metres),
        ``octaves``, ``lacunarity``, ``gain``, ``seed``; ``None`` for smooth primitives.
    combine : {"sum", "max"}
        Paper's blend (sum) or union (max, energies >= 0).
    threshold : float
        Subtracted from the combined field (0 for erosion/carving fields).
    cell_size : float, optional
        Grid cell edge (default: the median support radius, i.e. half the median
        support box edge, grown to fit ``max_cells``).
    max_cells : int
        Upper bound on the number of grid cells.
    """

    kind = "skeletal_set"

    def __init__(self, a, b=None, radius=1.0, energy=1.0, core=0.0, group=None, noise=None,
                 combine="sum", threshold=0.0, cell_size=None, max_cells=1 << 20):
        self.grouped = group is not None
        a, b, R, e, c, grp = primitive_arrays(a, b, radius, energy, core, group, combine)
        n = len(a)
        self.n, self.combine = n, combine
        self.a_np, self.b_np, self.radius_np, self.energy_np, self.core_np = a, b, R, e, c
        self.group_np = grp
        self.noise = noise_params(noise)
        span = self.noise["span"] if self.noise else 0.0
        self.threshold_np = float(threshold)

        lo_p, hi_p = self.primitive_boxes()
        self.support_lo, self.support_hi = lo_p.min(axis=0), hi_p.max(axis=0)
        cell = float(cell_size) if cell_size else 0.5 * float(np.median((hi_p - lo_p).max(axis=1)))
        if not cell > 0:
            raise ValueError("cell_size must be > 0")
        extent = self.support_hi - self.support_lo
        while np.prod(np.ceil(extent / cell) + 1) > max_cells:
            cell *= 1.25
        res = np.maximum(np.ceil(extent / cell).astype(np.int64), 1)
        self.grid_lo, self.cell, self.res = self.support_lo.copy(), cell, res
        start, count, index = grid_lists(lo_p, hi_p, self.grid_lo, cell, res)
        self.max_per_cell, self.list_len = int(count.max()), len(index)
        slopes = distance_slopes(self)
        prim_slope = np.abs(e) * G_SLOPE * slopes  # |e_i| G_SLOPE L_i (module docstring)
        # Slope of the star distance d~ per primitive (module docstring, "Local slopes").
        span0 = self.noise["span"] if self.noise else 0.0
        if self.noise:
            Dmin = np.ascontiguousarray(R * (1.0 - span0) * (1.0 - 1e-6), dtype=np.float32)
            Ld = np.ascontiguousarray(slopes, dtype=np.float32) * np.float32(1.0 + 1e-6)
        else:  # as point records compute them (.skeletal_records)
            Dmin, Ld = noise_free_constants(R)
        reach_R = seg = noise_K = None
        cell_l, cell_m, self._lipschitz, self.value_max, self.value_min = cell_tables(
            self, prim_slope, start, count, index)
        # Levels below the threshold ({F >= u}, u > 0) exist only with positive energies:
        # their distance bounds (module docstring) use the empty cells and, per
        # primitive, the region that holds {F_i >= u}, over lists of the support boxes
        # grown by NEAR_REACH cell edges (a primitive left out is that far away).
        # Local slopes (eval_local) are bounded in balls of up to SLOPE_REACH cell
        # edges: lists of the supports grown by that much hold every primitive that
        # can act there, and stay nearly as short as the cell lists (lists grown by a
        # whole cell were 5-10x longer in dense karst lattices, and a ball that
        # large holds the steepest point of some falloff anyway).
        self.local_radius = SLOPE_REACH * cell
        # The points of a carving set list only the cells their grown support, a ball,
        # touches (a primitive farther away adds exactly 0 to every value and bound of
        # the loop; Sea scale: 1.24 M -> 0.91 M entries). The other lists stay boxes:
        # the near lists' unlisted gaps and the cell tables are measured box to box.
        # The balls are a thousandth of the slope reach wider (an eight-thousandth of a
        # cell): a float32 point near a cell's face may be found in it, and a slope near
        # the edge of a grown support is not 0.
        points = self._points_only(a, b)
        balls = (a, c + R + self.local_radius * (1.0 + 1e-3)) if points and self.value_max <= 0 else None
        slope = grid_lists(lo_p - self.local_radius, hi_p + self.local_radius, self.grid_lo, cell, res, balls)
        # Cells are stored in bricks (below) only where some per-cell datum is not 0
        # (empty bricks read 0 and list nothing, as their cells held): along
        # a coast most of the box is air or rock that no primitive reaches.
        cell_L, cell_M, self._table = stored_tables(cell_l, cell_m)
        nonzero = (count > 0) | (slope[1] > 0) | (cell_L > 0) | (cell_M > 0)
        near = empty = None
        if self.value_max > 0:
            empty = empty_distance(lo_p, hi_p, self.grid_lo, cell, res).astype(np.float32)
            near = grid_lists(lo_p - NEAR_REACH * cell, hi_p + NEAR_REACH * cell, self.grid_lo, cell, res)
            nonzero |= near[1] > 0
            unlisted = unlisted_gaps(lo_p, hi_p, self.grid_lo, cell, res, NEAR_REACH * cell,
                                     UNLISTED_REACH * cell).astype(np.float32)
        entries = len(index) + len(slope[2]) + (len(near[2]) if near is not None else 0)
        self._narrow = self.n < 1 << 16 and entries >= NARROW_LISTS
        # Bricks that take the least memory (a carving set's band along a coast: 4^3).
        # A set that adds matter keeps bricks of 8^3: its unstored bricks answer the
        # smallest empty distance of their cells, and with smaller bricks some cells
        # that stored their own lose it (goblins: camera rays 37.5 -> 39.0 steps).
        edges = (BRICK,) if near is not None else (BRICK, BRICK // 2, BRICK // 4)
        self.layout = BrickLayout.of_cells(nonzero, self.grid_lo, cell, res, *self._stored_bytes(near is not None),
                                           edges)
        compact = self.layout.compact
        # Two lists a cell at most. The wide lists serve the bounds: the near lists of a
        # set that adds matter (a superset of the slope lists, which it then never
        # reads), the slope lists of a carving set. The values loop over the cell lists,
        # except in a carving set: over its slope lists (primitives listed but not touching
        # a point add exactly 0, in the same order: the same bits; Sea scale: 11.5 -> 8.6 MB).
        self._empty = self._near = None
        if near is not None:
            centres = centre_distances(a, b, self.support_reach(), self.grid_lo, cell, res, empty)
            self._empty = mi.Float(compact(centres))
            self._brick_empty = mi.Float(self.layout.brick_min(empty).astype(np.float32))
            self._brick_centre = mi.Float(brick_centre_distances(centres, self.layout))
            self._near = self._compact_lists(*near)
            self._unlisted = mi.Float(compact(unlisted))
            self._wide, self.wide_len = self._near, len(near[2])
            reach_R = np.ascontiguousarray(R * (1.0 + span), dtype=np.float32)
            if self.noise:
                nz = self.noise
                slope_n = fbm_lipschitz(int(nz["octaves"]), nz["lacunarity"], nz["gain"]) / nz["wavelength"]
                noise_K = np.ascontiguousarray(R * nz["amplitude"] * slope_n, dtype=np.float32)
                seg = (np.linalg.norm(b - a, axis=1) > 0).astype(np.float32)
            self._support_lo = [opaque_float(v) for v in self.support_lo]
            self._support_hi = [opaque_float(v) for v in self.support_hi]
            self._peak = opaque_float(self.value_max * (1.0 + 1e-6))  # float32 e may round up
        else:
            self._wide, self.wide_len = self._compact_lists(*slope), len(slope[2])
        # A carving set's value tables are 0 everywhere: not stored (local_lipschitz).
        self._cell_L = self._table(compact(cell_L))
        self._cell_M = self._table(compact(cell_M)) if self.value_max > 0 else None
        self._cell_edge = opaque_float(cell)
        self._near_reach = opaque_float(NEAR_REACH * cell)

        self._lists = self._compact_lists(start, count, index) if near is not None else self._wide
        # Points without noise or curves, of one core: 16-byte records and their energies
        # (.skeletal_records, "Point records").
        point_records = points and n > 0 and bool(np.all(c == c[0]))
        self._record_floats = POINT_RECORD if point_records else RECORD
        self._points = PointConstants.of(e, float(c[0])) if point_records else None
        self._records = (pack_point_records(a, R) if point_records else
                         pack_records(a, b, R, c, e, grp, reach_R, seg, noise_K, Dmin, Ld))
        self._glo_box = ([opaque_float(v) for v in self.grid_lo],
                         [opaque_float(v) for v in self.grid_lo + cell * res])
        self._threshold = opaque_float(self.threshold_np)
        # Opaque, as the records' energies are: a literal would fold u / e into
        # u * (1 / e) and move the bounds by an ulp.
        uniform = self.n and np.all(e == e[0])
        self._shared_energy = opaque_float(float(e[0])) if uniform else None
        if self.noise:
            nz = self.noise
            self._amp = opaque_float(nz["amplitude"])
            self._reach = opaque_float(1.0 + span)
            self._inv_wl = opaque_float(1.0 / nz["wavelength"])
            self._lac, self._gain = opaque_float(nz["lacunarity"]), opaque_float(nz["gain"])
            self._seed = dr.opaque(mi.UInt32, int(nz["seed"]) & 0xFFFFFFFF)
            # Levels of detail of the star noise (amplitude and wavelength of n itself).
            self._lod = OctaveLOD(nz["octaves"], nz["lacunarity"], nz["gain"], 1.0, nz["wavelength"])

    # -- bounds of the math -----------------------------------------------------
    @property
    def lipschitz(self):
        return max(self._lipschitz, 1e-12)

    @property
    def lod_kappa(self):
        # Module docstring, "Footprint level of detail".
        return 2.0 * self._lod.kappa if self.noise else 0.0

    def lod_error(self, radius):
        """Bound of ``|F_fp - F|`` for footprints up to ``radius`` (:func:`.skeletal_bounds.footprint_error`)."""
        return footprint_error(self, radius)

    # Zero (minus the threshold) outside the supports: no unit-rate falloff.
    unit_falloff = False

    def quiet_within(self, p, reach):
        """Whether no support lies within ``reach`` of ``p`` (:func:`.skeletal_bounds.quiet_within`)."""
        return quiet_within(self, p, reach)

    def box_range(self, lo, hi):
        """Exactly ``-threshold`` over a box no support reaches (:meth:`quiet_within` its
        centre by its half-diagonal), else the default."""
        zero = self.quiet_within(mi.Point3f((lo + hi) * 0.5), dr.norm(hi - lo) * 0.5)
        a, b = super().box_range(lo, hi)
        return dr.select(zero, -self._threshold, a), dr.select(zero, -self._threshold, b)

    def local_lod_error(self, p, reach, radius):
        """:meth:`lod_error` where some support may lie within ``reach`` of ``p``, else 0."""
        full = self.lod_error(radius)
        return dr.select(self.quiet_within(p, reach), 0.0, full) if full else 0.0

    def support_reach(self):
        """Per primitive, ``core + R (1 + noise span)``: farther from its segment its field is 0."""
        return self.core_np + self.radius_np * (1.0 + (self.noise["span"] if self.noise else 0.0))

    def primitive_boxes(self):
        """Per-primitive support boxes ``(lo (N, 3), hi (N, 3))``: outside its box a
        primitive's field is exactly 0 (:meth:`support_reach` around its segment)."""
        reach = self.support_reach()
        return (np.minimum(self.a_np, self.b_np) - reach[:, None],
                np.maximum(self.a_np, self.b_np) + reach[:, None])

    def support(self):
        """Box outside of which every primitive's field is exactly 0."""
        return self.support_lo.copy(), self.support_hi.copy()

    def bounds(self):
        if self.value_max > self.threshold_np:
            return self.support()
        return np.full(3, np.inf), np.full(3, -np.inf)  # never positive: empty

    @property
    def cost(self):
        per = 12.0 * int(self.noise["octaves"]) if self.noise else 2.0
        return 3.0 + per * min(self.max_per_cell, 8)

    def _compact_lists(self, start, count, index):
        """``(offsets, entries)`` over the stored cells, 16-bit where ``_narrow``
        (:meth:`~arches_render.field.brick_grid.BrickLayout.compact_lists`)."""
        offsets, entries = self.layout.compact_lists(start, count, index, self._narrow)
        return tuple(mi.UInt32(v) for v in offsets), mi.UInt32(entries)

    def _primitive(self, k):
        """:class:`~.skeletal_records.Primitive` ``k`` (per lane), from the set's records."""
        if self._points is not None:
            return gather_point(self._records, self._points, k)
        return gather_primitive(self._records, k)

    def _points_only(self, a, b):
        """Whether the set holds points without noise or curves (point records, and a
        carving set's lists by ball: :mod:`.skeletal_records`, ``__init__``)."""
        return not self.noise and not self.grouped and np.array_equal(a, b)

    def _stored_bytes(self, adds_matter):
        """Bytes a stored cell and a brick of the layout take (what the layout is chosen
        by): a list's offset (2 bytes in a narrow set, with 6 a brick for its base and
        end: :func:`~arches_render.field.brick_grid.relative_offsets`) and L; for a set
        that adds matter a second list, M, the centre's distance and the unlisted gap,
        and a brick's two empty distances (a brick's slot: 4 bytes)."""
        table = 2 if self._table is mi.Float16 else 4
        lists = 2 if adds_matter else 1
        offset, brick_offsets = (2, 6) if self._narrow else (4, 0)
        per_cell = lists * offset + table + (8 + table if adds_matter else 0)
        return per_cell, 4 + lists * brick_offsets + (8 if adds_matter else 0)

    def nbytes(self):
        """Bytes of the arrays the set holds (records, lists, per-cell and per-brick data)."""
        held = [self._records, self._points and self._points.energies, *self._lists[0], self._lists[1], *self._wide[0], self._wide[1], self.layout._slots]
        held += [getattr(self, k, None) for k in ("_cell_L", "_cell_M", "_empty", "_brick_empty", "_brick_centre",
                                                   "_unlisted")]
        unique = {id(a): a for a in held if a is not None}.values()
        return 64 + sum(dr.width(a) * (2 if isinstance(a, mi.Float16) else 4) for a in unique)

    # -- evaluation ---------------------------------------------------------------
    def _cell(self, p):
        """``(cell, stored, brick, inside)``: the stored cell of ``p`` (valid where
        ``stored``; elsewhere every per-cell datum is 0), its brick, and whether ``p``
        lies in the grid."""
        rx, ry, rz = (int(v) for v in self.res)
        fx, fy, fz = self.layout.cell_coordinates(p)
        inside = ((fx >= 0) & (fy >= 0) & (fz >= 0) & (fx < rx) & (fy < ry) & (fz < rz))
        cell, stored, brick = self.layout.lookup(p)
        return cell, stored, brick, inside

    def field(self, p):
        """Combined field ``F(p)`` (before the threshold) as ``mi.Float``."""
        return self._accumulate(p, self._lists)[0]

    def _accumulate(self, p, lists, us=(), footprint=None, radii=(), slants=(), direction=None):
        """``(F(p), ds, slopes)``: the field over the cell lists ``lists`` (``offsets, index``
        of :meth:`~arches_render.field.brick_grid.BrickLayout.compact_lists`); for each
        ``u`` of ``us``, the smallest :func:`.skeletal_bounds.level_bound` over
        them (``FAR`` where none acts) or, for a carving set (no positive energy), the
        largest :func:`.skeletal_bounds.core_bound`; for each radius of ``radii``, the local slope
        bound of :func:`.skeletal_bounds.local_slope` summed over the listed primitives (one member
        per curve: their maximum); for each ``(u0, slope, cap)`` of ``slants``, the smallest
        :func:`.skeletal_bounds.slanted_bound` (after the levels' bounds in ``ds``).
        With a ray's ``direction``, level bounds and (sets without noise) slopes along its line.
        Primitives listed but not touching ``p`` add exactly 0, so the near lists give
        the same ``F`` as the cell lists. With a ``footprint``, the footprint field
        (star noise truncated)."""
        level = self._lod.level(footprint) if self.noise else None
        rate = footprint.rate if level is not None else None
        carving = self.value_max <= 0
        n_u = len(us) + len(slants)
        # Bounds along the ray's line (skeletal_bounds, "Along a line"): the level bounds
        # of sets that add matter, the slopes of sets without noise.
        along = direction if direction is not None and ((n_u and not carving) or (radii and not self.noise)) else None
        offsets, index_a = lists
        cell, stored, _, inside = self._cell(p)
        start, count = self.layout.list_range(offsets, cell, stored)
        count = dr.select(inside, count, 0)
        # One energy for every primitive (the hoodoos preset): each level's shape is
        # per lane, not per primitive, and leaves the loop.
        shapes = [level_shape(self, self._shared_energy, u, carving) for u in us]
        slant_shapes = [level_shape(self, self._shared_energy, u0) for u0, _, _ in slants]

        def visit(prim, ds):
            """``(e, g, ds, slopes)`` of the primitive ``prim``."""
            e = prim.e
            if not n_u and not radii:
                return e, star_falloff(self, p, prim, level=level), ds, ()
            geometry = star_falloff(self, p, prim, True, level, along)
            out = []
            for u, d, shape in zip(us, ds, shapes):
                if carving:
                    out.append(dr.maximum(d, core_bound(self, prim, geometry, u)))
                    continue
                acts, bound = level_bound(self, prim, geometry, u, rate, shape)
                out.append(dr.select(acts, dr.minimum(d, bound), d))
            for (u0, slope, cap), d, shape in zip(slants, ds[len(us):], slant_shapes):
                out.append(dr.minimum(d, slanted_bound(self, prim, geometry, u0, slope, cap, rate, shape)))
            slopes = tuple(local_slope(self, prim, geometry, rad, rate) for rad in radii)
            return e, geometry[0], tuple(out), slopes

        far = tuple(mi.Float(0.0 if carving else FAR) for _ in us) + tuple(mi.Float(FAR) for _ in slants)
        zeros = tuple(mi.Float(0.0) for _ in radii)
        if self.combine == "max" or not self.grouped:
            def body(i, acc, *rest):
                prim = self._primitive(list_entry(index_a, start + i, self._narrow))
                e, gk, ds, sl = visit(prim, rest[:n_u])
                v = e * gk
                # Union (max): one primitive at a time sets the slope; sum: they add.
                join = dr.maximum if self.combine == "max" else (lambda a, b: a + b)
                sl = tuple(join(a, b) for a, b in zip(rest[n_u:], sl))
                return (i + 1, dr.maximum(acc, v) if self.combine == "max" else acc + v, *ds, *sl)

            _, acc, *rest = dr.while_loop((mi.UInt32(0), mi.Float(0.0), *far, *zeros), lambda i, *_: i < count,
                                          body, label="skeletal_set")
            return acc, rest[:n_u], rest[n_u:]

        def body_g(i, acc, cur_g, best, cur_e, *rest):
            prim = self._primitive(list_entry(index_a, start + i, self._narrow))
            grp = prim.group
            e, gk, ds, sl = visit(prim, rest[:n_u])
            new = grp != cur_g
            acc = acc + dr.select(new, cur_e * best, 0.0)
            best = dr.select(new, gk, dr.maximum(best, gk))
            cur_e = dr.select(new, e, cur_e)
            # Slopes: a curve is the maximum of its members (module docstring).
            n_r = len(radii)
            tot, cur = rest[n_u:n_u + n_r], rest[n_u + n_r:]
            tot = tuple(t + dr.select(new, c, 0.0) for t, c in zip(tot, cur))
            cur = tuple(dr.select(new, x, dr.maximum(c, x)) for c, x in zip(cur, sl))
            return (i + 1, acc, grp, best, cur_e, *ds, *tot, *cur)

        _, acc, _, best, cur_e, *rest = dr.while_loop(
            (mi.UInt32(0), mi.Float(0.0), mi.UInt32(0xFFFFFFFF), mi.Float(0.0), mi.Float(0.0), *far,
             *zeros, *zeros), lambda i, *_: i < count, body_g, label="skeletal_curves")
        n_r = len(radii)
        tot, cur = rest[n_u:n_u + n_r], rest[n_u + n_r:]
        return acc + cur_e * best, rest[:n_u], [t + c for t, c in zip(tot, cur)]

    def eval(self, p):
        return self.field(p) - self._threshold

    def local_lipschitz(self, p):
        """``(L, M, r)``: within the ball of radius ``r`` (one cell edge) around ``p``,
        ``|grad F| <= L`` and ``F <= M`` (maxima over the 3x3x3 cells around ``p``'s
        cell, which hold that ball; 0 far from every primitive)."""
        cell, stored, _, _ = self._cell(p)
        M = mi.Float(0.0) if self._cell_M is None else mi.Float(dr.gather(self._table, self._cell_M, cell, stored))
        return mi.Float(dr.gather(self._table, self._cell_L, cell, stored)), M, self._cell_edge

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        return self.eval_local(p, levels, direction, footprint)[:2]

    #: :meth:`eval_local` answers slanted levels (:mod:`.skeletal_bounds`).
    slanted_levels = True

    def eval_local(self, p, levels, direction=None, footprint=None, radii=(), slants=()):
        """``(f, ds, slopes)``: :meth:`eval_bounds` and, for each radius of ``radii``, a
        bound of ``|grad f|`` in the ball of that radius around ``p`` (module
        docstring, "Local slopes"; up to :attr:`local_radius` from the same loop over
        the primitives, up to a cell edge from the cell tables, beyond that global).

        ``slants``: triples ``(c, slope, reach)`` (per lane; ``reach``: the radius
        within which the caller's ``slope`` holds, ``None`` for everywhere); for each,
        a radius around ``p`` in which ``f(q) < -c - slope |q - p|``, appended to ``ds``
        (:func:`.skeletal_bounds.slanted_bound`). Sets that add matter only."""
        # Local Hart bounds: min(r, (-f - c) / L) where the ball of radius r has slope
        # <= L (the cell tables, and each radius of radii). Levels below the threshold
        # ({F >= u}, u > 0) add the geometric bounds of .skeletal_bounds, and carving
        # sets their cores, from the same loop that evaluates F.
        if not self.noise:
            footprint = None
        carving = self.value_max <= 0
        us = [self._threshold - c for c in levels] if self._near is not None or carving else []
        if slants and self._near is None:
            raise ValueError("slanted levels need a set that adds matter")
        slants = [(self._threshold - c, slope, slant_cap(self._threshold - c, slope, reach))
                  for c, slope, reach in slants]
        slopes, geo = (), []
        if us or radii or slants:
            # Caps need the near lists (a superset of the slope lists); cores need
            # only the primitives whose support holds p. Levels below every value keep
            # Hart's bound (below): no geometric bounds per primitive (:func:`below_all`).
            lists = self._wide
            skipped = [not carving and below_all(self.threshold_np, c) for c in levels] if us else []
            F, found, slopes = self._accumulate(p, lists, [u for u, s in zip(us, skipped) if not s], footprint,
                                                radii, slants, direction)
            geo = refill(found, skipped)
            f = F - self._threshold
        elif footprint is not None:
            f = self._accumulate(p, self._lists, (), footprint)[0] - self._threshold
        else:
            f = self.eval(p)
        cell, stored, brick, inside = self._cell(p)
        L, r = mi.Float(dr.gather(self._table, self._cell_L, cell, stored)), self._cell_edge  # (local_lipschitz)
        L_glob = self.lipschitz
        if footprint is not None:
            grow = 1.0 + self.lod_kappa * footprint.rate
            L, L_glob = L * grow, L_glob * grow
        if radii:
            # Outside the grid no primitive is listed: 0 where the supports' box is
            # out of reach, else the global bound. The slope lists answer balls of up
            # to local_radius; larger balls (a structure's cells) get the cell tables'
            # bound up to one cell edge, the global one beyond.
            outside = box_distance(p, self._glo_box[0], self._glo_box[1])
            slopes = [dr.select(inside, dr.select(rad <= self.local_radius, dr.minimum(s_, L_glob),
                                                  dr.select(rad <= self.cell, L, L_glob)),
                                dr.select(outside > rad, 0.0, L_glob))
                      for s_, rad in zip(slopes, radii)]
        inv, inv_glob = dr.rcp(dr.maximum(L, 1e-12)), 1.0 / L_glob
        ds = []
        for c in levels:
            d = dr.minimum(dr.maximum(-f - c, 0.0) * inv, r)
            ds.append(dr.maximum(d, dr.maximum(-f - c, 0.0) * inv_glob))
            for s_, rad in zip(slopes, radii):
                ds[-1] = dr.maximum(ds[-1], dr.minimum(dr.maximum(-f - c, 0.0) * dr.rcp(dr.maximum(s_, 1e-12)), rad))
        if us and carving:
            # Cores (.skeletal_bounds): where some primitive alone is below u; no
            # positive energy, so {F >= u} is empty for every u > 0.
            ds = [dr.select(u > 0.0, FAR, dr.select(u < 0.0, dr.maximum(d, g), d)) for d, g, u in zip(ds, geo, us)]
        elif us or slants:
            to_cell, to_brick = centre_offsets(self.layout, p, self._cell_edge)
            empty = dr.select(stored, dr.gather(mi.Float, self._empty, cell, stored) - to_cell,
                              dr.maximum(dr.gather(mi.Float, self._brick_empty, brick, ~stored),
                                         dr.gather(mi.Float, self._brick_centre, brick, ~stored) - to_brick))
            outside = box_distance(p, self._support_lo, self._support_hi)
            # A primitive left out of the near list is at least the cell's unlisted gap
            # away (NEAR_REACH cell edges at least; cells not stored list nothing).
            unlisted = dr.select(stored, dr.gather(mi.Float, self._unlisted, cell, stored), self._near_reach)
            geo = [dr.select(inside, dr.maximum(dr.minimum(dr.maximum(g, 0.0), unlisted), empty),
                             outside) for g in geo]
            ds = [dr.select(u > self._peak, FAR, dr.select(u > 0.0, dr.maximum(d, g), d))
                  for d, g, u in zip(ds, geo, us)]
            ds += [dr.minimum(g, cap) for g, (_, _, cap) in zip(geo[len(us):], slants)]
        return f, tuple(ds), tuple(slopes)

    def __repr__(self):
        return f"SkeletalSet(n={self.n}, combine={self.combine!r}, noise={bool(self.noise)})"
