"""DEMs that store the sea as a flat sheet at the sea level, and the sea floor laid under it.

Why. Land DEMs have no bathymetry: SRTM and the products built on it (and many
GeoTIFFs whose no-data was filled with 0) store the open sea as exactly 0 m. Such a
sea is a table top at the water's own level. Amplified and rendered, its detail
noise (a few decimetres) pokes through the water as sand and puddles, and every
measure of the coast reads the flat sheet as land (the land by the sea "rises
0.2 m" on the analysis grid, so ``auto`` dropped the ``sea`` preset on the Devil's
Slide coast, whose cliffs rise 130 m).

What. :func:`flat_sea` finds the sheet: the cells exactly at the sea level that are
connected to the tile's border (8-neighbours), at least ``MIN_FRACTION`` of the
tile. :func:`lay_sea_floor` lowers them to a floor that deepens away from the shore,

    z(d) = sea_level - min(DEPTH_AT_SHORE + SLOPE d, max_depth),

``d`` the distance to the nearest cell that is not sheet: a nearshore slope of 1 in
20 (steep for a beach, usual below cliffs), capped at a fifth of the land's relief
(at least ``DEPTH_AT_SHORE``). The floor is an assumption, said so in the scene's
header; it only keeps the water over the sea and lets the coast be measured.
Samples of the land, and sea cells below the level (real bathymetry, lagoons), do
not move.

References
----------
Farr, T. G. et al. (2007). The Shuttle Radar Topography Mission. Reviews of
Geophysics 45(2) (ocean pixels set to 0 m in the finished products).
Bird, E. (2008). Coastal Geomorphology: An Introduction, 2nd ed., Wiley, ch. 4
(nearshore profiles: 1-5 % slopes, steeper off rocky and cliffed coasts).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import distance_transform_edt

from .preset_choice import sea_mask

__all__ = ["flat_sea", "lay_sea_floor", "MIN_FRACTION", "SLOPE", "DEPTH_AT_SHORE"]

#: Smallest share of the tile that a flat sheet must cover to be taken for the sea.
MIN_FRACTION = 0.01
#: Depth gained per metre from the shore.
SLOPE = 0.05
#: Depth at the shore (m): deeper than the detail noise, so no sea cell dries.
DEPTH_AT_SHORE = 2.0


def flat_sea(H, sea_level):
    """The cells of a DEM's flat sea sheet, or ``None`` where it has none.

    Parameters
    ----------
    H : numpy.ndarray
        ``(ny, nx)`` elevations (m), as read (before any smoothing).
    sea_level : float or None
        The sea level (m); ``None``: no sea.

    Returns
    -------
    numpy.ndarray or None
        ``(ny, nx)`` bool: cells exactly at ``sea_level`` (to float32 rounding)
        connected to the border through such cells, when they are at least
        ``MIN_FRACTION`` of the tile.
    """
    if sea_level is None:
        return None
    H = np.asarray(H, dtype=np.float64)
    level = float(sea_level)
    at = np.abs(H - level) <= 4 * np.finfo(np.float32).eps * max(1.0, abs(level))
    if at.mean() < MIN_FRACTION:
        return None
    sheet = sea_mask(np.where(at, level, np.inf), level)  # the sheet's own cells, from the border
    return sheet if sheet.mean() >= MIN_FRACTION else None


def lay_sea_floor(H, sheet, cell, sea_level):
    """``H`` with the sheet's cells lowered to the floor of the module docstring.

    Parameters
    ----------
    H : numpy.ndarray
        ``(ny, nx)`` elevations (m).
    sheet : numpy.ndarray
        ``(ny, nx)`` bool, from :func:`flat_sea`.
    cell : float
        Cell size (m).
    sea_level : float

    Returns
    -------
    (numpy.ndarray, float)
        The heights (float64) and the floor's greatest depth (m).
    """
    H = np.array(H, dtype=np.float64)
    d = distance_transform_edt(sheet, sampling=float(cell))
    land = H[~sheet]
    relief = float(land.max() - sea_level) if land.size else 0.0
    max_depth = max(0.2 * relief, DEPTH_AT_SHORE)
    depth = np.minimum(DEPTH_AT_SHORE + SLOPE * d[sheet], max_depth)
    H[sheet] = float(sea_level) - depth
    return H, float(depth.max())
