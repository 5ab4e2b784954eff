"""Where a scene's meshes lie: rays that cannot meet one skip Mitsuba's ray query.

A far field (``[[far_field]]``) is a skirt of some 130k triangles around the tile,
reaching to the horizon. Against it one Embree query cost 250-500 ns a ray on 2 CPU
cores (``ray_test`` and ``ray_intersect``, 1M random rays from inside the default
gorge), about three field steps; and the integrator asks it for every camera, shadow
and bounce ray. Most of those rays leave the tile upwards and pass over the skirt:
the default scene rendered in 5.2 s without its far field and 8.7 s with it, while
the far field filled a few per cent of the picture. Mitsuba's query costs in
proportion to its active lanes (half the lanes masked, random or contiguous: half
the time), so a ray that provably meets no mesh is simply masked off.

The region is the union of

- a **box** holding every shape that no scene item claims (rock piles, mesh files,
  the field's own mesh in mesh mode), and
- a **skirt**: the points between heights ``z0`` and ``z1`` outside the open column
  over the rectangle ``hole`` (scene items with ``ray_region()``, :mod:`arches_render.extensions`:
  a far field's hole is its tile less the frame band its mesh covers inside the tile).

A ray segment ``o + t d``, ``t in [0, tmax]``, may meet a mesh only where it meets
the region:

- box: the slab test, ``max_i min(t0_i, t1_i) <= min_i max(t0_i, t1_i)`` within
  ``[0, tmax]``, with ``t{0,1}_i = (lo_i - o_i) / d_i, (hi_i - o_i) / d_i``;
- skirt: the z slab gives the stretch ``S = [max(0, ta), min(tmax, tb)]`` between the
  heights; the x and y slabs of the hole give the open stretch ``(ha, hb)`` the ray
  spends over the hole. The ray misses the skirt if ``S`` is empty or lies inside
  ``(ha, hb)``.

Every test is written as "certainly misses" with ordered comparisons, so a NaN reaching
the last comparison keeps the lane asked. (A ray lying exactly in a slab's plane gives
``0 * inf``; where ``minimum``/``maximum`` drop that NaN, the box's test reads the ray as
missing, right since the grown box's faces touch no mesh, and the skirt's as meeting.)
Both parts are grown by :data:`MARGIN` of the coordinates' magnitude: Mitsuba stores
vertices in float32.

The bounds are opaque Dr.Jit values: every scene with a far field shares one kernel.

References
----------
Kay, T. L., Kajiya, J. T. (1986). Ray tracing complex scenes. SIGGRAPH (slabs).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

__all__ = ["MeshRegion", "scene_mesh_region", "MARGIN"]

#: Growth of the region, relative to the largest coordinate it holds (and at least a
#: millimetre): float32 vertices round by 6e-8 of their magnitude, Embree's hits lie
#: within a few ulps of the triangles; 1e-5 is a hundred times that.
MARGIN = 1e-5


@dataclass(frozen=True)
class MeshRegion:
    """A box and a skirt holding every mesh of a scene (module docstring).

    Parameters
    ----------
    box : ((3,), (3,)) or None
        Corners of the box holding the unclaimed shapes; None: none.
    skirt : ((4,) or None, float, float) or None
        ``(hole (x0, y0, x1, y1), z0, z1)``; None: none. A hole of None: the skirt is
        the whole slab between the heights.
    """

    box: tuple | None
    skirt: tuple | None

    def grown(self) -> "MeshRegion":
        """The region grown by :data:`MARGIN` (the hole shrunk)."""
        box = skirt = None
        if self.box is not None:
            lo, hi = (np.asarray(v, np.float64) for v in self.box)
            pad = _pad(lo, hi)
            box = (lo - pad, hi + pad)
        if self.skirt is not None:
            hole, z0, z1 = self.skirt
            pad = _pad([z0, z1]) if hole is None else _pad(hole, [z0, z1])
            if hole is not None:
                hole = np.asarray(hole, np.float64) + np.array([pad, pad, -pad, -pad])
                hole = hole if hole[0] < hole[2] and hole[1] < hole[3] else None
            skirt = (hole, z0 - pad, z1 + pad)
        return MeshRegion(box, skirt)

    def may_meet(self, o, d, tmax):
        """Whether the segments ``o + t d``, ``t in [0, tmax]``, may meet a mesh: :meth:`may_meet_box`
        or :meth:`may_meet_skirt`.

        Parameters
        ----------
        o, d : mi.Point3f, mi.Vector3f
            Origins and directions.
        tmax : mi.Float
            The segments' ends (may be infinite).

        Returns
        -------
        mi.Bool
            False only where the segment provably misses the region (call it on the
            :meth:`grown` region).
        """
        return self.may_meet_box(o, d, tmax) | self.may_meet_skirt(o, d, tmax)

    def may_meet_box(self, o, d, tmax):
        """Whether the segments may meet the box (:meth:`may_meet`'s parameters)."""
        if self.box is None:
            return mi.Bool(False)
        inv = mi.Vector3f(1.0 / d.x, 1.0 / d.y, 1.0 / d.z)
        lo, hi = (dr.opaque(mi.Point3f, [float(c) for c in v]) for v in self.box)
        t0, t1 = (lo - o) * inv, (hi - o) * inv
        near, far = dr.minimum(t0, t1), dr.maximum(t0, t1)
        enter = dr.maximum(dr.maximum(dr.maximum(near.x, near.y), near.z), 0.0)
        leave = dr.minimum(dr.minimum(dr.minimum(far.x, far.y), far.z), tmax)
        return ~(enter > leave)

    def may_meet_skirt(self, o, d, tmax):
        """Whether the segments may meet the skirt (:meth:`may_meet`'s parameters)."""
        if self.skirt is None:
            return mi.Bool(False)
        hole, z0, z1 = self.skirt
        inv_z = 1.0 / d.z
        ta, tb = (dr.opaque(mi.Float, z0) - o.z) * inv_z, (dr.opaque(mi.Float, z1) - o.z) * inv_z
        s0 = dr.maximum(dr.minimum(ta, tb), 0.0)
        s1 = dr.minimum(dr.maximum(ta, tb), tmax)
        if hole is None:
            return ~(s0 > s1)
        hole = dr.opaque(mi.Vector4f, [float(c) for c in hole])
        inv_x, inv_y = 1.0 / d.x, 1.0 / d.y
        x0, x1 = (hole.x - o.x) * inv_x, (hole.z - o.x) * inv_x
        y0, y1 = (hole.y - o.y) * inv_y, (hole.w - o.y) * inv_y
        h0 = dr.maximum(dr.minimum(x0, x1), dr.minimum(y0, y1))
        h1 = dr.minimum(dr.maximum(x0, x1), dr.maximum(y0, y1))
        return ~((s0 > s1) | ((h0 < s0) & (s1 < h1)))


def _pad(*values) -> float:
    scale = max(float(np.max(np.abs(np.asarray(v, np.float64)))) for v in values)
    return max(MARGIN * scale, 1e-3)


def scene_mesh_region(scene, items) -> MeshRegion | None:
    """The grown :class:`MeshRegion` of a built Mitsuba scene.

    Parameters
    ----------
    scene : mi.Scene
    items : iterable
        The scene tables' items (:mod:`arches_render.extensions`). An item with
        ``ray_region()`` (``(hole, z0, z1)``) claims its shapes, named
        ``{item.name}_{k}``; every other shape goes into the box.

    Returns
    -------
    MeshRegion or None
        None when the scene has no shape (nothing to skip).
    """
    claimed, skirts = set(), []
    for item in items:
        region = getattr(item, "ray_region", None)
        if region is None:
            continue
        skirts.append(region())
        claimed.add(item.name)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    shapes = list(scene.shapes())
    for shape in shapes:
        if shape.id().rpartition("_")[0] in claimed:
            continue
        b = shape.bbox()
        lo, hi = np.minimum(lo, np.array(b.min, np.float64)), np.maximum(hi, np.array(b.max, np.float64))
    if not shapes:
        return None
    box = (lo, hi) if np.all(lo <= hi) else None
    skirt = None
    if skirts:  # the union of several skirts: the smallest hole, all heights
        holes = np.array([s[0] for s in skirts], np.float64)
        hole = np.concatenate([holes[:, :2].max(0), holes[:, 2:].min(0)])
        hole = hole if hole[0] < hole[2] and hole[1] < hole[3] else None  # holes apart: no hole
        skirt = (hole, min(s[1] for s in skirts), max(s[2] for s in skirts))
    return MeshRegion(box, skirt).grown()
