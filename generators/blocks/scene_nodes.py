"""The ``blocks`` node of scene files: fractured blocks replicated over a host.

Lengths are metres, angles degrees; ``[ ]`` marks an optional key and its default.

=====================  ==================================================================
type                   keys
=====================  ==================================================================
blocks                 host (node name or inline table), [structure = "equidimensional"]
                       (equidimensional, rhombohedral, polyhedral, tabular, columnar,
                       prismatic), [seed = 0];
                       tile: [tile_size = 20] in [1, 1000], [point_radius = tile_size /
                       28.5], [spacing] (fracture spacing, default per structure),
                       [disc_radius = 0.35 tile_size], [axis = [0, 0, 1]] (column axis,
                       bedding normal), [obliquity = 25] (rhombohedral), [column_sets =
                       3] in [2, 8] (columnar), [joint_width = 0.1], [tile] (a .npz
                       written by ``arches-render blocks``: replaces the tile keys);
                       shape: [smoothness = 0.25] (smooth-intersection radius R > 0),
                       [warp = 0.04] >= 0 (detail amplitude), [warp_wavelength = 0.5],
                       [warp_octaves = 2] in [1, 4], [margin = 0.25] in (0, 1000] (the clamp m:
                       deeper than the hit tolerance, 2e-4 x the scene's diagonal, where
                       the region is seen from afar);
                       presence: [region = host box] [x0, y0, z0, x1, y1, z1],
                       [distance_range = [-1, 1]] (host field at the anchors),
                       [min_slope = 60] in [0, 90] (walls steeper than it), [max_slope
                       = 90] in [min_slope, 90] (ground facing up, gentler than it: where
                       fallen blocks rest; 90: no test), [density] (an .npz whose array
                       ``density`` (ny, nx) in [0, 1] spans the region's x, y, row 0
                       south: each copy is kept with the probability at its centroid,
                       drawn with ``seed``), [resistance] (number or node),
                       [resistance_range = [-inf, inf]], [contact] >= 0 (blocks rest
                       on the host: 3 anchors within it of the host or inside; none: no
                       test), [protrusion] >= 0 (clip the blocks to the host grown by it;
                       none: max(host, t))
=====================  ==================================================================

The node is ``max(host, t)`` with ``t`` the replicated blocks (see
:mod:`arches_render.generators.blocks.block_field` and
:mod:`~arches_render.generators.blocks.replication`). Tiles are built once per
parameter set and cached (:mod:`~arches_render.generators.blocks.tile_cache`).

References
----------
Paris, A., Peytavie, A., Guerin, E., Dischler, J.-M., Galin, E. (2020). Modeling
rocky scenery using implicit blocks. The Visual Computer 36(10), 2251-2261.
"""

from __future__ import annotations

import math

import numpy as np

from arches_render.field.node import finite_box
from arches_render.scene.array_files import ArrayFileError, Spec, read_arrays
from arches_render.scene.paths import scene_file

# The tile builder (numba, scipy.spatial: 0.26 s to import) is imported where a scene
# has a ``blocks`` node, not by every process that reads the node types.

__all__ = ["NODE_TYPES", "tile_params", "tile_from_table"]

#: The ``density`` file of a ``blocks`` node.
DENSITY_SPECS = {"density": Spec((None, None), "number", lo=0.0, hi=1.0)}

TILE_KEYS = ("structure", "tile_size", "point_radius", "spacing", "disc_radius", "axis",
             "obliquity", "column_sets", "joint_width", "seed")


def tile_params(t):
    """:class:`~.tile_cache.TileParams` from the tile keys of a ``blocks`` table."""
    from .fracture_discs import STRUCTURES
    from .tile_cache import TileParams
    size = t.number("tile_size", 20.0, lo=1.0, hi=1000.0)
    r = t.number("point_radius", None, lo=size / 60.0, hi=size / 4.0)
    spacing = t.number("spacing", None, lo=0.0, hi=size, lo_open=True)
    disc_radius = t.number("disc_radius", None, lo=0.0, lo_open=True)
    p = TileParams(structure=t.string("structure", "equidimensional", choices=set(STRUCTURES)),
                   size=size, point_radius=r, spacing=spacing, disc_radius=disc_radius,
                   axis=tuple(t.vector("axis", default=[0.0, 0.0, 1.0], nonzero=True)),
                   obliquity=t.number("obliquity", 25.0, lo=0.0, hi=40.0),
                   column_sets=t.integer("column_sets", 3, lo=2, hi=8),
                   joint_width=t.number("joint_width", 0.1, lo=0.0, hi=size / 10),
                   seed=t.integer("seed", 0, lo=0, hi=2 ** 31 - 1))
    try:
        p.validate()
    except ValueError as exc:
        raise t.error("structure", str(exc)) from None
    return p


def tile_from_table(t, base_dir, progress=None):
    """The tile of a ``blocks`` table: its ``tile`` file, or built from its keys (cached)."""
    from .tile_cache import cached_tile, load_tile
    if t.has("tile"):
        path = scene_file(t, "tile", (".npz",), base_dir, what="block tile")
        for key in TILE_KEYS:
            if key != "seed" and t.has(key):
                raise t.error(key, "cannot be combined with 'tile' (the file fixes the tile)")
        try:
            return load_tile(path)
        except ValueError as exc:
            raise t.error("tile", str(exc)) from None
    return cached_tile(tile_params(t), progress=progress)


def _range(t, key, default):
    v = t.raw(key, default)
    ok = (isinstance(v, list) and len(v) == 2
          and all(isinstance(x, (int, float)) and not isinstance(x, bool) and not math.isnan(x) for x in v)
          and v[0] <= v[1])
    if not ok:
        raise t.error(key, f"must be [lo, hi] with lo <= hi (got {v!r})")
    return float(v[0]), float(v[1])


def _blocks(t, ctx):
    from .replication import replicate
    host = ctx.build(t.raw("host"), t, "host")
    tile = tile_from_table(t, ctx.base_dir, ctx.progress)
    if t.has("tile"):
        t.integer("seed", 0, lo=0, hi=2 ** 31 - 1)
    if t.has("region"):
        reg = t.vector("region", 6)
        lo, hi = np.array(reg[:3]), np.array(reg[3:])
        if not np.all(hi > lo):
            raise t.error("region", "must be [x0, y0, z0, x1, y1, z1] with x1 > x0, y1 > y0, "
                                    f"z1 > z0 (got {reg})")
    else:
        box = finite_box(host)
        if box is None or not np.all(box[1] > box[0]):
            raise t.error("region", "is required: the host is unbounded")
        lo, hi = box
    resistance = None
    if t.has("resistance"):
        v = t.raw("resistance")
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            resistance = t.number("resistance")
        else:
            resistance = ctx.build(v, t, "resistance")
    res_range = _range(t, "resistance_range", [-math.inf, math.inf])
    min_slope = t.number("min_slope", 60.0, lo=0.0, hi=90.0)
    max_slope = t.number("max_slope", 90.0, lo=min_slope, hi=90.0)
    density = None
    if t.has("density"):
        path = scene_file(t, "density", (".npz",), ctx.base_dir, what="density grid")
        try:
            density = read_arrays(path, DENSITY_SPECS, "density grid")["density"]
        except ArrayFileError as exc:
            raise t.error("density", str(exc)) from None
        if density.size == 0:
            raise t.error("density", "holds an empty grid")
    try:
        return replicate(host, tile, lo, hi,
                         distance_range=_range(t, "distance_range", [-1.0, 1.0]),
                         min_slope=min_slope, max_slope=max_slope, density=density,
                         resistance=resistance, resistance_range=res_range,
                         contact=t.number("contact", None, lo=0.0),
                         protrusion=t.number("protrusion", None, lo=0.0),
                         smoothness=t.number("smoothness", 0.25, lo=0.0, lo_open=True, hi=5.0),
                         warp=t.number("warp", 0.04, lo=0.0, hi=2.0),
                         warp_wavelength=t.number("warp_wavelength", 0.5, lo=0.0, lo_open=True),
                         warp_octaves=t.integer("warp_octaves", 2, lo=1, hi=4),
                         seed=t.integer("seed", 0, lo=0, hi=2 ** 31 - 1),
                         margin=t.number("margin", 0.25, lo=0.0, lo_open=True, hi=1000.0))
    except ValueError as exc:
        raise t.error("region", str(exc)) from None


NODE_TYPES = {"blocks": _blocks}
