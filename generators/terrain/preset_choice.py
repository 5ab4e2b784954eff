"""Choosing an amplification preset from a DEM, and landform sizes from its relief.

``--preset auto`` (issue 14) must pick what a geomorphologist would: sea caves only
where there is a sea, canyon overhangs where rivers have cut valleys, layered cliffs
on escarpments, karst on plateaus with closed depressions, hoodoos on small
badland escarpments. Every threshold below is in metres, square metres or degrees,
never in DEM cells, and every measure is taken on an *analysis grid* whose cell
depends on the tile's extent, not on the DEM's resolution:

    a = max(cell, min(L / (N - 1), S / 2)),   N = 256,

with ``L`` and ``S`` the longer and shorter sides of the tile (m); the ``S / 2`` keeps
three samples across narrow strips.

A 1 m DEM and a 10 m DEM of the same 5 km tile are both analysed at 20 m, so the same
place gets the same preset. (Slopes depend on the baseline they are measured over;
a fixed baseline per tile is what makes them comparable.) DEMs coarser than
``L / 255`` are analysed as they are.

Rules, in order (the first that holds wins)
-------------------------------------------
``sea``      Cells below ``sea_level`` (or exactly at it: DEMs that store the sea as
             the sea level) connected (8-neighbours) to the tile's border cover at
             least 1 % of the tile and at least 1 % of the border. A closed
             depression below the sea level (Death Valley, the Dead Sea shore) is
             not sea, nor is a tile that only grazes the sea in a corner.
``karst``    Closed depressions (depression-filled minus DEM) deeper than
             ``max(1 m, 1 % of the relief)`` that cover at least 1 % of the land,
             at least 3 of them, lying in the upper half of the relief: dolines on
             a plateau. One big basin floor at the bottom of the relief is a
             basin, not karst.
``river``    An incised drainage: the largest catchment (Freeman's multiple flow
             direction on the filled DEM) drains at least 25 % of the tile, and the
             channels (upstream area >= 2 % of the tile) lie at least
             ``max(10 m, 15 % of the relief)`` below the *lower* of their two valley
             sides (the highest ground within an eighth of the tile on either side,
             along rows and columns; median over channel cells). Valleys cut into the
             land, as in Zion (Fig. 15); a plain at the foot of mesas has one low side
             and does not count. (The real New Mexico canyon measures 22-26 %, a
             mesa landscape under 1 %: 15 % sits between with a margin.)
``strata``   Flat tops and escarpments: at least 15 % of the land is flat (< 6 deg)
             in the upper half of the relief and at least 3 % is steep
             (>= 30 deg): mesas, cuestas, tablelands. The layered-cliff preset when
             the escarpments are tall (cliff height >= 40 m) or the tile is large
             (>= 2 km): strata are resolved by the DEM.
``hoodoos``  The same flat tops and escarpments at badland scale (cliffs under 40 m
             on a tile under 2 km), or steep (>= 30 deg on 20 % of the land),
             finely dissected slopes of less than 150 m of relief: the paper's
             hoodoos are a few metres to more than 40 m tall (section 6.3) and its
             hoodoo scene is 350 m across (Table 1).
``strata``   Walls without flat tops (:func:`has_walls`): at least 1 % of the land is
             steep and the escarpments are at least 40 m tall: a caldera's or a
             crater's ring of cliffs, a fault scarp, a mountain's rock faces. Such
             walls are a small share of a tile (the 500 m inner walls of a caldera
             2.8 km across are ~3 % of a 10 km tile at 100 m cells) but they are its
             landform, and they expose layered rock (stacked lava flows and tuffs,
             bedded limestone) that the erosion node undercuts; the river default
             found no valley to work on there (issue 34).
``river``    Otherwise (hills, plains): water is the agent that shapes most land,
             and the river preset only acts where stream power is high.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), sections 6.1-6.3, Table 1.
Tarboton, D. G., Bras, R. L., Rodriguez-Iturbe, I. (1991). On the extraction of
channel networks from digital elevation data. Hydrological Processes 5(1), 81-100
(channels as cells above a drainage-area threshold).
"""

from __future__ import annotations

import math

import numpy as np

from .hydrology import fill_depressions, flow_accumulation, label_extrema

__all__ = ["ANALYSIS_CELLS", "analysis_grid", "sea_mask", "terrain_stats", "choose_preset", "has_walls",
           "landform_scales"]

#: Samples along the longer side of the analysis grid.
ANALYSIS_CELLS = 256

_FLAT_DEG = 6.0  # below: a flat top, bench or valley floor
_STEEP_DEG = 30.0  # above: an escarpment or cliff at the analysis baseline (talus is ~30-35 deg)
_WALL_SHARE, _WALL_HEIGHT_M = 0.01, 40.0  # walls: steep land share and escarpment height (rules, "strata")


def has_walls(stats) -> bool:
    """Whether :func:`terrain_stats` measured walls that layered cliffs can be carved in:
    at least 1 % of the land steep, in escarpments at least 40 m tall (module docstring)."""
    return stats["steep_fraction"] >= _WALL_SHARE and stats["cliff_height_m"] >= _WALL_HEIGHT_M


def analysis_grid(heights, cell_size, cells=ANALYSIS_CELLS):
    """Resample a DEM to the analysis grid of its extent.

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` finite elevations (m).
    cell_size : float
        DEM cell (m).
    cells : int
        Samples along the longer side when the DEM is finer.

    Returns
    -------
    (numpy.ndarray, float)
        Heights on the analysis grid (anti-aliased by a Gaussian of half the
        reduction before bilinear sampling) and its cell (m). A DEM already as
        coarse is returned as it is (float64).
    """
    from scipy import ndimage
    H = np.asarray(heights, dtype=np.float64)
    cell = float(cell_size)
    ny, nx = H.shape
    L = (max(nx, ny) - 1) * cell
    # Square cells, and at least 3 samples across the short side (a 3 x 5000 strip stays as it is).
    a = min(L / (cells - 1), 0.5 * (min(nx, ny) - 1) * cell)
    if a <= cell * 1.000001:
        return H, cell
    f = a / cell
    G = ndimage.gaussian_filter(H, 0.5 * f, mode="nearest")
    my, mx = int(math.floor((ny - 1) / f)) + 1, int(math.floor((nx - 1) / f)) + 1
    J, I = np.meshgrid(np.arange(my) * f, np.arange(mx) * f, indexing="ij")
    return ndimage.map_coordinates(G, [J, I], order=1, mode="nearest"), a


def sea_mask(H, sea_level):
    """Cells at or below ``sea_level`` connected to the tile's border (8-neighbours).

    Parameters
    ----------
    H : numpy.ndarray
        ``(ny, nx)`` elevations (m).
    sea_level : float

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` bool.
    """
    from scipy import ndimage
    wet = H <= sea_level
    lab, n = ndimage.label(wet, structure=np.ones((3, 3), bool))
    if n == 0:
        return wet
    edge = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    return np.isin(lab, edge[edge > 0])


def terrain_stats(heights, cell_size, sea_level=0.0):
    """Measures of a DEM that the preset rules use (see the module docstring).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations (m).
    cell_size : float
        DEM cell (m).
    sea_level : float
        Sea level (m).

    Returns
    -------
    dict
        ``analysis_cell_m``, ``extent_m`` (longer side), ``relief_m`` (1st to 99th
        percentile of the land), ``sea_fraction``, ``sea_border_fraction``,
        ``flat_top_fraction``, ``steep_fraction``, ``main_catchment_fraction``,
        ``channel_incision_m``, ``depression_fraction``, ``depressions``,
        ``depressions_upland`` and ``cliff_height_m`` (see :func:`landform_scales`).
    """
    return _analyse(heights, cell_size, sea_level)[0]


def _analyse(heights, cell_size, sea_level):
    """:func:`terrain_stats` and the analysis-grid arrays it was computed from."""
    from scipy import ndimage
    H, a = analysis_grid(heights, cell_size)
    ny, nx = H.shape
    L = (max(nx, ny) - 1) * a
    sea = sea_mask(H, sea_level)
    border = np.concatenate([sea[0], sea[-1], sea[1:-1, 0], sea[1:-1, -1]])
    land = ~sea if (~sea).any() else np.ones_like(sea)  # an all-sea tile: measure its floor
    st = dict(analysis_cell_m=a, extent_m=L, sea_fraction=float(sea.mean()),
              sea_border_fraction=float(border.mean()))
    zlo, zhi = (float(v) for v in np.percentile(H[land], [1.0, 99.0]))
    R = max(zhi - zlo, 1e-6)
    gy, gx = np.gradient(H, a)
    slope = np.degrees(np.arctan(np.hypot(gx, gy)))
    upper = H > zlo + 0.5 * R
    nland = max(int(land.sum()), 1)
    st.update(relief_m=zhi - zlo, land_low_m=zlo,
              flat_top_fraction=float((land & upper & (slope < _FLAT_DEG)).sum() / nland),
              steep_fraction=float((land & (slope >= _STEEP_DEG)).sum() / nland))
    # Drainage on the filled surface (the sea is a sink like any border cell).
    A = flow_accumulation(H, a)
    tile = H.size * a * a
    st["main_catchment_fraction"] = float(A.max() / tile)
    chan = land & (A >= 0.02 * tile)
    st["channel_incision_m"] = _incision(H, chan, max(3, int(round(0.125 * L / a))))
    # Closed depressions: what filling adds, where it adds more than a metre (or 1 % of R).
    dep = (fill_depressions(H) - H) > max(1.0, 0.01 * R)
    dep &= land
    lab, n = ndimage.label(dep, structure=np.ones((3, 3), bool))
    up = 0
    if n:
        floor = label_extrema(H, lab, n)[0]
        up = int((floor > zlo + 0.5 * R).sum())
    st.update(depression_fraction=float(dep.sum() / nland), depressions=int(n), depressions_upland=up)
    st["cliff_height_m"] = _cliff_height(H, slope >= _STEEP_DEG, land, a)
    return st, dict(H=H, a=a, sea=sea, land=land, slope=slope, chan=chan)


def _incision(H, chan, w):
    """Median depth of channel cells below the *lower* of their two valley sides.

    For each channel cell and each grid axis, the highest ground within ``w`` cells
    on either side; the valley side is the lower of the two, and the depth is the
    larger over the two axes. A channel on a plain at the foot of an escarpment has
    one low side (no incision), a canyon has two high ones.
    """
    from scipy import ndimage
    if not chan.any():
        return 0.0
    depth = np.zeros(H.shape)
    for axis in (0, 1):
        after = ndimage.maximum_filter1d(H, w, axis=axis, origin=-(w // 2), mode="nearest")
        before = ndimage.maximum_filter1d(H, w, axis=axis, origin=(w - 1) // 2, mode="nearest")
        depth = np.maximum(depth, np.minimum(after, before) - H)
    return float(np.median(depth[chan]))


def _cliff_height(H, steep, land, a):
    """Median height of the escarpments crossed by rows and columns of the grid.

    Runs of consecutive steep cells along a row or a column, with one cell more at
    each end (the rim and the foot), are crossings of a steep face; a run whose mean
    gradient is at least ``tan(30 deg)`` crosses it downhill (not along it), and its
    height range is the height of that face. Local, so unaffected by how far the
    steep ground connects (a canyon system is one connected region).
    """
    from scipy import ndimage
    steep = steep & land
    heights = []
    for st in (np.array([[0, 0, 0], [1, 1, 1], [0, 0, 0]], bool), np.array([[0, 1, 0], [0, 1, 0], [0, 1, 0]], bool)):
        lab, n = ndimage.label(steep, structure=st)
        if n == 0:
            continue
        grown = ndimage.grey_dilation(lab, footprint=st)
        lo, hi = label_extrema(H, grown, n)
        rng = hi - lo
        length = (np.bincount(lab.ravel(), minlength=n + 1)[1:] + 1) * a
        heights.append(rng[rng >= math.tan(math.radians(_STEEP_DEG)) * length])
    h = np.concatenate(heights) if heights else np.zeros(0)
    return float(np.median(h)) if h.size else 0.0


def choose_preset(heights, cell_size, sea_level=0.0):
    """Pick the amplification preset a DEM calls for (rules in the module docstring).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` finite elevations (m), at least 2 x 2.
    cell_size : float
        DEM cell (m).
    sea_level : float
        Sea level (m); ``--sea-level`` in ``amplify``.

    Returns
    -------
    (str, str, dict)
        The preset name, one sentence saying why (with the measures in metres,
        percent and degrees), and the measures (:func:`terrain_stats`).
    """
    H = np.asarray(heights, dtype=np.float64)
    if H.ndim != 2 or min(H.shape) < 2:
        raise ValueError("choose_preset needs a 2-D DEM of at least 2 x 2 samples")
    if not np.all(np.isfinite(H)):
        raise ValueError("choose_preset needs finite heights")
    st = terrain_stats(H, cell_size, sea_level)
    pct = lambda v: f"{100 * v:.0f} %"  # noqa: E731
    if st["sea_fraction"] >= 0.01 and st["sea_border_fraction"] >= 0.01:
        return "sea", (f"sea: {pct(st['sea_fraction'])} of the tile lies below {sea_level:g} m and reaches "
                       f"{pct(st['sea_border_fraction'])} of its edge"), st
    R = st["relief_m"]
    if st["depressions_upland"] >= 3 and st["depression_fraction"] >= 0.01:
        return "karst", (f"karst: {st['depressions_upland']} closed depressions in the upper half of "
                         f"{R:.0f} m of relief cover {pct(st['depression_fraction'])} of the land"), st
    incised = st["channel_incision_m"] >= max(10.0, 0.15 * R)
    if st["main_catchment_fraction"] >= 0.25 and incised:
        return "river", (f"river: valleys {st['channel_incision_m']:.0f} m deep (relief {R:.0f} m) drain "
                         f"{pct(st['main_catchment_fraction'])} of the tile into one outlet"), st
    tabular = st["flat_top_fraction"] >= 0.15 and st["steep_fraction"] >= 0.03
    cliff = st["cliff_height_m"]
    why = (f"flat tops on {pct(st['flat_top_fraction'])} and slopes over {_STEEP_DEG:g} deg on "
           f"{pct(st['steep_fraction'])} of the land, escarpments {cliff:.0f} m high")
    if tabular and (cliff >= 40.0 or st["extent_m"] >= 2000.0):
        return "strata", f"strata: {why} on a {st['extent_m'] / 1000:.1f} km tile", st
    if tabular or (st["steep_fraction"] >= 0.2 and R < 150.0 and st["extent_m"] < 2000.0):
        return "hoodoos", f"hoodoos: badland scale, {why}, relief {R:.0f} m", st
    if has_walls(st):
        return "strata", (f"strata: walls without flat tops, slopes over {_STEEP_DEG:g} deg on "
                          f"{pct(st['steep_fraction'])} of the land in escarpments {cliff:.0f} m high"), st
    return "river", (f"river (default): no sea, plateau or karst; relief {R:.0f} m, valleys "
                     f"{st['channel_incision_m']:.0f} m deep"), st


def landform_scales(heights, cell_size, preset, sea_level=0.0):
    """Landform sizes in metres from the relief, for amplification (issue 14).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations (m).
    cell_size : float
        DEM cell (m).
    preset : str
        ``sea``, ``river``, ``karst``, ``hoodoos`` or ``strata``.
    sea_level : float
        Sea level (m).

    Returns
    -------
    dict
        All in metres, measured on the analysis grid (so independent of the DEM's
        resolution):

        ``relief_m``            1st to 99th percentile of the land.
        ``cliff_height_m``      median height of the steep faces (>= 30 deg) crossed
                                by the grid's rows and columns, rim and foot
                                included; ``0.25 relief`` when there is none.
        ``strata_thickness_m``  period of the beds: the first autocorrelation peak
                                of the mean slope against elevation on the walls
                                (hard beds stand steep, soft ones recede to benches);
                                a third of the cliff height when no period shows.
        ``valley_depth_m``      median depth of channels below the lower of their
                                valley sides (see the ``river`` rule).
        ``valley_width_m``      twice the median distance from a channel to ground
                                half the valley depth above it.
        ``feature_m``           the size of the preset's landform: sea caves and
                                notches 0.2 x the coastal cliff (the paper: 8 m of sea
                                range on cliffs of ~40 m, Fig. 11); river undercuts
                                0.25 x the valley depth; karst tunnel radius a quarter
                                of a stratum, 1-10 m; hoodoo height 0.6 x the cliff,
                                2-45 m (section 6.3); strata: the stratum thickness.

        With ``sea``, also ``coast_cliff_m`` (90th percentile of the land within
        two analysis cells of the sea, above the sea level).
    """
    from scipy import ndimage
    if preset not in ("sea", "river", "karst", "hoodoos", "strata"):
        raise ValueError(f"unknown preset {preset!r}")
    st, g = _analyse(heights, cell_size, sea_level)
    H, a, sea, land, chan = g["H"], g["a"], g["sea"], g["land"], g["chan"]
    R = max(st["relief_m"], 1e-6)
    cliff = st["cliff_height_m"] or 0.25 * R
    thick = _layer_period(H, g["slope"], land, R)
    if thick is None:
        thick = cliff / 3.0
    depth = st["channel_incision_m"]
    width = 0.0
    if chan.any() and depth > 0:
        # Height of the nearest channel cell under every cell; "low" is the valley below half depth.
        _, (jj, ii) = ndimage.distance_transform_edt(~chan, return_indices=True)
        low = H < H[jj, ii] + 0.5 * depth
        width = 2.0 * float(np.median(ndimage.distance_transform_edt(low)[chan])) * a
    out = dict(relief_m=R, cliff_height_m=cliff, strata_thickness_m=thick, valley_depth_m=depth,
               valley_width_m=width)
    if preset == "sea":
        near = land & ndimage.binary_dilation(sea, np.ones((3, 3), bool), iterations=2)
        coast = float(np.percentile(H[near] - sea_level, 90)) if near.any() else cliff
        out["coast_cliff_m"] = max(coast, 0.0)
        out["feature_m"] = float(np.clip(0.2 * out["coast_cliff_m"], 1.0, 30.0))
    elif preset == "river":
        out["feature_m"] = float(np.clip(0.25 * (depth or cliff), 1.0, 40.0))
    elif preset == "karst":
        out["feature_m"] = float(np.clip(0.25 * thick, 1.0, 10.0))
    elif preset == "hoodoos":
        out["feature_m"] = float(np.clip(0.6 * cliff, 2.0, 45.0))
    else:  # strata
        out["feature_m"] = float(thick)
    return out


def _layer_period(H, slope, land, relief):
    """Dominant period (m) of the slope-elevation profile of the slopes, or None.

    Hard beds stand as cliffs and soft ones weather back to benches, so along the walls
    the mean slope at each elevation rises and falls with the beds. The profile (mean
    slope of the land steeper than 6 deg in bins of ``relief / 400``, trend wider than
    15 % of the relief removed) is autocorrelated; its first peak at a lag of at least
    4 m with a correlation of at least 0.1 is the layer period. None otherwise.
    """
    from scipy import ndimage
    wall = land & (slope > _FLAT_DEG)
    if wall.sum() < 50 or relief < 8.0:
        return None
    z, v = H[wall], slope[wall]
    bin_m = max(0.25, relief / 400.0)
    nb = int(math.ceil((float(z.max()) - float(z.min())) / bin_m)) + 1
    k = ((z - z.min()) / bin_m).astype(int)
    cnt = np.bincount(k, minlength=nb)
    good = cnt >= 5
    if good.sum() < 8:
        return None
    mean = np.bincount(k, v, minlength=nb) / np.maximum(cnt, 1)
    i = np.arange(nb)
    sig = np.interp(i, i[good], mean[good])  # bins with too few cells: interpolated
    sig = ndimage.gaussian_filter1d(sig, 1.0) - ndimage.gaussian_filter1d(sig, 0.15 * relief / bin_m)
    f = np.fft.rfft(sig, 2 * nb)
    ac = np.fft.irfft(f * np.conj(f))[:nb]
    if ac[0] <= 0:
        return None
    ac /= ac[0]
    for q in range(max(2, int(math.ceil(4.0 / bin_m))), nb - 1):
        if ac[q] >= ac[q - 1] and ac[q] >= ac[q + 1] and ac[q] >= 0.1:
            return float(q * bin_m)
    return None
