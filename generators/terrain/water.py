"""Water where the DEM has it: the sea below the sea level, lakes at the level their catchment fills (issues 14, 34).

Sea
    The cells at or below ``sea_level`` connected (8-neighbours) to the tile's
    border (:func:`.preset_choice.sea_mask`): a closed basin below sea level
    (Death Valley) is dry land, as in nature.
Lakes
    Depression filling (Priority-Flood, :func:`.hydrology.fill_depressions`) finds every
    closed depression and the level where it spills; a connected set of filled cells,
    not sea, whose depth reaches ``max(1 m, 2 % of the relief)`` and that covers at
    least 9 cells may hold a lake. Shallower pits are noise of the DEM: resampling and
    interpolation dam valley floors by a few metres (the USGS canyon of ``scenes/data``
    has nine such pits, 1.3-4.4 m deep on a 264 m relief, one of them 0.1 km^2 of its
    flat floor; at 0.5 % of the relief they flooded the canyon). The karst preset keeps
    its dolines dry: they drain underground.

    How high a closed lake stands is a water balance: it rises until what its surface
    evaporates (``E A_lake``) equals what its catchment brings (``P A_lake + r P
    (A_basin - A_lake)``), so its area is a share of its catchment's,
    ``A_lake / A_basin = r P / (E - P + r P)`` (Mason et al. 1994; Street-Perrott and
    Harrison 1985 use the same ratio to read past climates from old shorelines); a
    lake that reaches its spill level first overflows there. A valley dammed by a
    landslide or a moraine drains a catchment far larger than the lake and fills to
    its spill level; a crater or a caldera drains little more than its own bowl and
    holds its lake well below its rim (Crater Lake, Oregon, has no outlet: its level is
    set by precipitation against evaporation and seepage). Filling every depression to
    its spill level drowned such bowls to the brim: a synthetic caldera 500 m deep
    rendered as a flat disc inside a thin rim. Here
    a lake covers at most :data:`LAKE_CATCHMENT_SHARE` of the cells that drain
    straight into it (steepest descent on the DEM ends in it; a lake upstream that
    spills into it is not counted, so this errs low), and its level is the highest
    that keeps it so, up to the spill level. Cells below the level that are cut off
    from each other are separate pools at the same level, each kept if it passes the
    depth and size rules above.

Measured relief
    A crop refined from a coarser DEM (:mod:`.refined_crop`) adds relief the DEM did not
    measure: benches, which follow warped strata and so dip and rise, and detail, which
    dents them. Their closed pits, tens of metres deep at 10 m cells, held lakes on a
    caldera's terraces (five on some seeds, besides the one on its floor), and a crop that
    cuts a basin leaves it open. There the lakes are the DEM's own, found on its cells as
    above (:func:`.refined_crop.crop_lake_levels`), and flood the crop's cells below their
    level within a DEM cell of them.

Surfaces
    Each water body is a flat mesh at its level over its cells, *grown* by
    ``reach`` metres (the sea: far enough to flood the sea caves cut under the
    land; lakes: one cell) so that the water meets the shore under the ground
    instead of leaving a gap along it: where the ground stands above the water,
    the water is hidden under it. It grows only under that shore: a sample below
    the level that holds no water lies outside the basin (past a lake's spill point,
    where the ground falls away again, or in a pit left dry), and no cell with such a
    corner is water. Grown over it, a crater lake filled to its brim stood as a sheet
    in the air past the low point of its rim. Runs of wet cells along each row are merged into
    one quad (the surface is flat, so T-junctions leave no crack), which keeps a
    large sea of a large DEM to a few thousand triangles per row band.

References
----------
Barnes, R., Lehman, C., Mulla, D. (2014). Priority-flood. Computers & Geosciences 62,
117-127.
Mason, I. M., Guzkowska, M. A. J., Rapley, C. G., Street-Perrott, F. A. (1994). The
response of lake levels and areas to climatic change. Climatic Change 27(2), 161-197.
Street-Perrott, F. A., Harrison, S. P. (1985). Lake levels and climate reconstruction.
In Hecht, A. D. (ed.), Paleoclimate Analysis and Modeling, Wiley, 291-340.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy import ndimage

from .hydrology import NEIGHBOUR_DI, NEIGHBOUR_DJ, fill_depressions, label_extrema
from .preset_choice import sea_mask

__all__ = ["WaterBodies", "find_water", "water_mesh", "LAKE_DEPTH_M", "LAKE_DEPTH_RELIEF", "LAKE_CATCHMENT_SHARE",
           "descent_sinks"]

#: A depression is a lake when at least this deep (metres) and this fraction of the relief.
LAKE_DEPTH_M, LAKE_DEPTH_RELIEF = 1.0, 0.02

#: The largest share of its catchment a closed lake covers (module docstring, "Lakes").
#: ``r P / (E - P + r P)`` is ~0.1 where the climate is semi-arid (P = 0.4 m, E = 1.2 m,
#: runoff r = 0.2) and reaches 1 (the lake spills) where precipitation exceeds
#: evaporation; one half is a temperate choice that keeps a crater's lake in the lower
#: part of its bowl and fills every dammed valley to its spill level.
LAKE_CATCHMENT_SHARE = 0.5


class WaterBodies:
    """Water of a DEM.

    Attributes
    ----------
    level : numpy.ndarray
        ``(ny, nx)`` water level per cell sample (NaN: dry).
    sea : numpy.ndarray
        ``(ny, nx)`` bool, the sea's samples.
    sea_level : float or None
        The sea's level when the tile has sea.
    lakes : list of (float, int)
        ``(level, cells)`` of each lake.
    touches_border : bool
        Whether the sea reaches the tile's border (it then continues to the horizon).
    heights : numpy.ndarray or None
        ``(ny, nx)`` the DEM the water was found on: where the surfaces may grow
        (module docstring, "Surfaces"); ``None``: anywhere.
    """

    def __init__(self, level, sea, sea_level, lakes, heights=None):
        self.level, self.sea, self.lakes, self.heights = level, sea, lakes, heights
        self.sea_level = sea_level if sea.any() else None
        self.touches_border = bool(sea[0].any() or sea[-1].any() or sea[:, 0].any() or sea[:, -1].any())

    @property
    def wet(self) -> bool:
        """Whether there is any water."""
        return bool(np.isfinite(self.level).any())


def find_water(heights, sea_level=0.0, lakes=True, lake_levels=None):
    """Sea and lakes of a DEM (see the module docstring).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations (m).
    sea_level : float or None
        Sea level (m); ``None``: no sea.
    lakes : bool
        Look for lakes.
    lake_levels : array_like, optional
        ``(ny, nx)`` levels of the lakes the DEM holds where ``heights`` add relief it did
        not measure (a refined crop, :func:`.refined_crop.crop_lake_levels`; NaN: no
        lake): the cells below them are the lakes, and no other depression is looked for
        (module docstring, "Measured relief").

    Returns
    -------
    WaterBodies
    """
    H = np.asarray(heights, np.float64)
    level = np.full(H.shape, np.nan)
    sea = sea_mask(H, sea_level) if sea_level is not None else np.zeros(H.shape, bool)
    level[sea] = sea_level
    found = []
    if lakes and lake_levels is not None:
        L = np.asarray(lake_levels, np.float64)
        wet = np.isfinite(L) & (H < np.where(np.isfinite(L), L, -np.inf)) & ~sea
        lab, n = ndimage.label(wet, structure=np.ones((3, 3), bool))
        level[wet] = L[wet]
        found = [(float(L[lab == k].max()), int((lab == k).sum())) for k in range(1, n + 1)]
    elif lakes:
        relief = float(np.percentile(H, 99) - np.percentile(H, 1))
        deep_enough = max(LAKE_DEPTH_M, LAKE_DEPTH_RELIEF * relief)
        filled = fill_depressions(H)
        depth = filled - H
        wet = (depth > 1e-6) & ~sea
        lab, n = ndimage.label(wet, structure=np.ones((3, 3), bool))
        if n:
            deepest = label_extrema(depth, lab, n)[1]
            cells = np.bincount(lab.ravel(), minlength=n + 1)[1:]
            spill = label_extrema(filled, lab, n)[1]
            # Cells draining straight into each depression: steepest descent ends in it.
            catchment = np.bincount(lab.ravel()[descent_sinks(H).ravel()], minlength=n + 1)[1:]
            boxes = ndimage.find_objects(lab)
            for k in np.nonzero((deepest >= deep_enough) & (cells >= 9))[0]:
                box = boxes[k]
                m = lab[box] == k + 1
                h = _balanced_level(H[box][m], spill[k], LAKE_CATCHMENT_SHARE * catchment[k])
                pools, count = ndimage.label(m & (H[box] < h), structure=np.ones((3, 3), bool))
                for q in range(1, count + 1):
                    pool = pools == q
                    if pool.sum() >= 9 and h - H[box][pool].min() >= deep_enough:
                        level[box][pool] = h
                        found.append((float(h), int(pool.sum())))
    return WaterBodies(level, sea, sea_level, found, heights=H)


def _balanced_level(heights, spill, allowed):
    """The level of a lake over a depression whose cells have ``heights``: ``spill`` when
    the full lake covers at most ``allowed`` cells, else the highest level with at most
    ``allowed`` cells strictly below it (module docstring, "Lakes")."""
    if heights.size <= allowed:
        return float(spill)
    return float(np.partition(heights, int(allowed))[int(allowed)])


def descent_sinks(heights):
    """Flat index of the cell where each cell's steepest descent (D8, square cells) ends.

    Each cell points to its neighbour of steepest drop, itself where none is lower (a
    pit, a flat, or the border's lowest points); following the pointers ends at a pit.
    Pointer doubling (``sink = sink[sink]``) reaches every end in ``log2`` of the longest
    path's length passes over the array.

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` elevations.

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` int64 flat indices into ``heights``.
    """
    H = np.asarray(heights, np.float64)
    ny, nx = H.shape
    pad = np.pad(H, 1, constant_values=np.inf)
    own = np.arange(H.size, dtype=np.int64).reshape(H.shape)
    to, best = own.copy(), np.zeros(H.shape)
    for di, dj in zip(NEIGHBOUR_DI, NEIGHBOUR_DJ):
        rate = (H - pad[1 + di:1 + di + ny, 1 + dj:1 + dj + nx]) / np.hypot(di, dj)
        steeper = rate > best
        best = np.where(steeper, rate, best)
        to = np.where(steeper, own + di * nx + dj, to)
    to = to.ravel()
    while True:
        further = to[to]
        if np.array_equal(further, to):
            return to.reshape(H.shape)
        to = further


def _grow(level, mask, steps, heights=None):
    """Spread the levels of ``mask`` over ``steps`` cells around it (the highest neighbour
    wins), only into samples of ``heights`` at or above the level they would take (the
    shore; everywhere without ``heights``)."""
    lev = np.where(mask, level, -np.inf)
    grown = mask.copy()
    for _ in range(int(steps)):
        nxt = ndimage.grey_dilation(lev, size=(3, 3))
        new = ~grown & np.isfinite(nxt)
        if heights is not None:
            new &= heights >= nxt
        lev[new] = nxt[new]
        grown |= new
    return lev, grown


def water_mesh(water: WaterBodies, extent, sea_reach_cells=2):
    """Flat water surfaces of ``water`` over the tile (module docstring), or ``None`` if dry.

    Parameters
    ----------
    water : WaterBodies
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` of the grid.
    sea_reach_cells : int
        Cells the sea grows by under the land (caves below sea level are flooded).

    Returns
    -------
    trimesh.Trimesh or None
    """
    if not water.wet:
        return None
    ny, nx = water.level.shape
    x0, y0, x1, y1 = extent
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    wet = np.isfinite(water.level)
    lev, grown = _grow(water.level, wet & ~water.sea, 1, water.heights)
    slev, sgrown = _grow(water.level, water.sea, max(1, int(sea_reach_cells)), water.heights)
    lev = np.where(sgrown & (~grown | (slev > lev)), slev, lev)
    grown |= sgrown
    # A cell (between samples j..j+1, i..i+1) is water when any corner is: at the highest level,
    # unless a corner is dry ground below that level (outside the basin: module docstring).
    corners = np.stack([lev[:-1, :-1], lev[:-1, 1:], lev[1:, :-1], lev[1:, 1:]])
    cell_lev = corners.max(axis=0)
    cell_wet = np.isfinite(cell_lev)
    if water.heights is not None:
        low = np.where(grown, np.inf, water.heights)
        lowest = np.stack([low[:-1, :-1], low[:-1, 1:], low[1:, :-1], low[1:, 1:]]).min(axis=0)
        cell_wet &= ~(lowest < cell_lev)
    # One quad per run of wet cells at one level along a row, rows in order: a run
    # starts at a wet cell whose left neighbour is dry or at another level, and ends
    # before the next start or dry cell (each row padded with one dry cell).
    rows, cols = cell_wet.shape
    wet = np.concatenate([cell_wet, np.zeros((rows, 1), bool)], axis=1).ravel()
    lv = np.concatenate([cell_lev, np.zeros((rows, 1))], axis=1).ravel()  # (read only where wet)
    prev_wet = np.concatenate([[False], wet[:-1]])
    start = wet & ~(prev_wet & (lv == np.concatenate([[0.0], lv[:-1]])))
    if not start.any():
        return None
    first = np.flatnonzero(start)
    stop = np.flatnonzero(start | ~wet)
    last = stop[np.searchsorted(stop, first, side="right")]  # (a row's padding cell stops every run)
    j, k = np.divmod(first, cols + 1)
    e = last - j * (cols + 1)
    xa, xb, ya, yb, z = x0 + k * dx, x0 + e * dx, y0 + j * dy, y0 + (j + 1) * dy, lv[first]
    V = np.stack([np.stack([xa, ya, z], 1), np.stack([xb, ya, z], 1), np.stack([xb, yb, z], 1),
                  np.stack([xa, yb, z], 1)], 1).reshape(-1, 3)
    n = 4 * np.arange(len(first))[:, None]
    F = np.stack([n + [0, 1, 2], n + [0, 2, 3]], 1).reshape(-1, 3)
    return trimesh.Trimesh(V, F.astype(np.int64), process=False)
