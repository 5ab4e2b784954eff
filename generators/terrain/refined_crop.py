"""A refined crop of a coarse DEM: landforms carved in metres, not at the cell's size (issue 34).

On a DEM of 100 m cells or coarser every landform process works at the cell's scale:
the falloff radius, the primitives' spacing and the cliffs' heights all follow the
cell (a 2.4 km coastal DEM was carved into sea-erosion bowls kilometres wide). The
paper amplifies terrains whose landforms are metres to tens of metres (Paris et al.
2019, Sec. 8); it does not say what to do with a DEM that cannot resolve them. We
bring the surface down to the landforms' scale first, on a window of the DEM:

Window
    A square of ``side`` cells, at least :data:`CROP_WIDTH_M` metres and
    :data:`CROP_CELLS` cells wide (the whole DEM's shorter side at most), whose middle
    (the central ``side / 2`` cells) has the largest relief (highest less lowest
    sample): mountains and escarpments rather than plains, and in the middle of the
    crop, not cut by its border (measured over the whole window, a peak sat in the
    crop's corner, :func:`crop_window`). With a sea, windows holding both sea and land
    (a share of sea between :data:`COAST_SHARE`) come first, so that a coast has its
    shore in the crop.
Surface
    The window resampled at ``side * cell / cells`` metres by a cubic B-spline
    (C2, through the samples), plus fBm octaves that continue the DEM's own spectrum
    from its Nyquist wavelength (two cells) down to four fine cells
    (:func:`.detail.detail_amplification`'s fit of the whole DEM, the same noise the
    renderer adds below a cell), so that the processes find relief between the
    samples and not a smooth spline. Where the spline is steep it is stepped into
    benches and risers (:func:`_benches`: a coarse cell averages a cliff band and its
    bench into one slope, and a ramp has no wall to undercut). The fBm fades out below
    the sea level (it would
    put islands and pools along the shore) and over the border's :data:`TAPER` of the
    crop, where the surface also turns from the spline to the context's bilinear
    surface: at its edge the crop is exactly what the far field reads there, so that it
    sits in its DEM without a step.
Context
    The whole DEM resampled by the same spline at up to :data:`CONTEXT_UPSAMPLE` times
    its density (at most :data:`CONTEXT_SAMPLES` samples), placed in the crop's frame
    (the crop centred on the origin, as :func:`.amplify.amplify` centres its tiles):
    the far field continues the crop with the real terrain around it, not with a copy
    of the crop's own relief, and in facets a fraction of the DEM's cell (the DEM's own
    samples, bilinear, made kilometre-wide flat planes and creases around a 2.4 km
    DEM's crop, and so did the crop's border band).

A DEM whose sea is SRTM's flat sheet gets its floor laid first
(:func:`.sea_floor.lay_sea_floor`), as amplify does, so the spline does not ring
along the coast of a flat sheet.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), Sec. 8.
Unser, M. (1999). Splines: a perfect fit for signal and image processing. IEEE Signal
Processing Magazine 16(6), 22-38 (cubic B-spline interpolation, as
``scipy.ndimage.map_coordinates(order=3)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .detail import NOISE_RMS, detail_amplification
from .sea_floor import flat_sea, lay_sea_floor

__all__ = ["REFINE_ABOVE", "RefinedCrop", "attach_context", "crop_window", "refine_crop"]

#: DEMs of cells this coarse (metres) or coarser are worth refining.
REFINE_ABOVE = 100.0
#: Fine cells along the crop's side (the 5 km benchmark's tile is 500 cells a side).
REFINE_CELLS = 512
#: Least width of the crop (metres) ...
CROP_WIDTH_M = 5000.0
#: ... and least number of DEM cells across it.
CROP_CELLS = 4
#: Share of the crop's side over which the detail fades out towards its border.
TAPER = 0.15
#: Share of sea a window holding a coast has (with a sea in the DEM).
COAST_SHARE = (0.15, 0.85)
#: The context (the far field's DEM) is the DEM resampled this many times denser ...
CONTEXT_UPSAMPLE = 4
#: ... within this many samples.
CONTEXT_SAMPLES = 4_000_000


@dataclass
class RefinedCrop:
    """A window of a DEM at a finer cell (module docstring).

    Attributes
    ----------
    heights : numpy.ndarray
        ``(cells + 1, cells + 1)`` fine heights (m).
    cell : float
        Fine cell (m).
    window : tuple of int
        ``(i0, j0, side)``: the window's first sample (column, row) and its cells a side.
    context : numpy.ndarray
        The whole DEM (m; its sea floor laid where it was a flat sheet), resampled by the
        spline (module docstring, "Context").
    context_extent : tuple of float
        ``(x0, y0, x1, y1)`` of the DEM's samples in the crop's frame.
    notes : list of str
        What was done, for the scene's header.
    lake_levels : numpy.ndarray
        ``heights``' shape: the level of the DEM's lake over each sample within a DEM
        cell of it, NaN elsewhere (:func:`crop_lake_levels`).
    """

    heights: np.ndarray
    cell: float
    window: tuple
    context: np.ndarray
    context_extent: tuple
    notes: list = field(default_factory=list)
    lake_levels: np.ndarray = None


def _window_reduce(A, side, reduce):
    """``reduce`` (``'max'``, ``'min'`` or ``'mean'``) of ``A`` over every window of
    ``side + 1`` samples a side: ``out[j0, i0]`` covers rows ``j0 .. j0 + side``."""
    from scipy.ndimage import maximum_filter, minimum_filter, uniform_filter
    s = side + 1
    filt = {"max": maximum_filter, "min": minimum_filter, "mean": uniform_filter}[reduce]
    out = filt(np.asarray(A, np.float64), size=s, mode="nearest")
    ny, nx = A.shape
    return out[s // 2: ny - s + s // 2 + 1, s // 2: nx - s + s // 2 + 1]


def crop_window(H, side, sea_level=None):
    """``(i0, j0)``: the first sample of the window of ``side`` cells whose middle has the
    greatest relief (module docstring).

    Parameters
    ----------
    H : numpy.ndarray
        ``(ny, nx)`` elevations (m), ``side <= min(nx, ny) - 1``.
    side : int
        Cells along the window's side.
    sea_level : float, optional
        With a sea below it, windows holding a coast come first.

    Returns
    -------
    (int, int)
        Column and row of the window's first sample (the first of equal windows in
        row-major order: the same DEM gives the same window).
    """
    inner = max(side // 2, 1)
    off = (side - inner) // 2
    middle = _window_reduce(H, inner, "max") - _window_reduce(H, inner, "min")
    ny, nx = H.shape
    relief = middle[off: off + ny - side, off: off + nx - side]  # by the outer window's first sample
    score = relief
    if sea_level is not None:
        wet = _window_reduce((H < sea_level).astype(np.float64), side, "mean")
        coast = (wet >= COAST_SHARE[0]) & (wet <= COAST_SHARE[1])
        if coast.any():
            score = np.where(coast, relief, -1.0)
    j0, i0 = np.unravel_index(int(np.argmax(score)), score.shape)
    return int(i0), int(j0)


def _fbm_heights(x, y, table):
    """The detail table's fBm, ``a fbm((x, y, 0) / lambda)``, at points (arrays, metres)."""
    import drjit as dr
    import mitsuba as mi

    from arches_render.backend import variant
    from arches_render.field.noise import fbm
    variant()
    inv = 1.0 / table["wavelength"]
    p = mi.Point3f(mi.Float(np.ravel(x) * inv), mi.Float(np.ravel(y) * inv), mi.Float(0.0))
    value = table["amplitude"] * fbm(p, int(table["octaves"]), table["lacunarity"], table["gain"],
                                     mi.UInt32(table["seed"]))
    dr.eval(value)
    return np.asarray(value.numpy(), np.float64).reshape(np.shape(x))


#: Slopes (degrees) over which the surface turns into benches and risers.
BENCH_SLOPES = (12.0, 22.0)
#: Range of the share of a band's height its riser takes (the rest is its bench), drawn per band.
RISER = (0.2, 0.45)
#: Band thicknesses: the band height times ``exp(N(0, BAND_SIGMA))``, clipped to
#: :data:`BAND_SPREAD` of it.
BAND_SIGMA = 0.45
BAND_SPREAD = (0.35, 2.5)


def _benches(Z, cell, sea_level, seed):
    """``Z`` stepped into benches and risers where it is steep, and the band height (m).

    A DEM of 100 m cells averages a cliff band and the bench above it into one slope
    (an escarpment of 30 degrees at 200 m cells hides walls a hundred metres tall); a
    spline through it is a smooth ramp, where no process finds a wall to undercut.
    Where the slope passes :data:`BENCH_SLOPES`, heights are mapped through a staircase
    of bands about ``b`` tall, each a flat bench and a riser of a share of it drawn in
    :data:`RISER` (on a slope ``g`` the riser climbs at ``g / share``: 27 degrees become
    50-70), the band boundaries warped by fBm a band high (strata are not contour
    lines): ``b`` is a tenth of the crop's relief, 40-200 m (the strata thickness of
    :func:`.preset_choice.landform_scales` on real escarpments), each band's thickness
    ``b`` times a lognormal factor (:data:`BAND_SIGMA`, :data:`BAND_SPREAD`), seeded. Not in the paper,
    which amplifies DEMs that resolve their cliffs; this restores what the cell averaged.
    """
    gy, gx = np.gradient(Z, cell, cell)
    slope = np.degrees(np.arctan(np.hypot(gx, gy)))
    lo, hi = BENCH_SLOPES
    weight = _smoothstep((slope - lo) / (hi - lo))
    if sea_level is not None:
        weight *= _smoothstep((Z - sea_level) / 10.0)
    band = float(np.clip(0.1 * (Z.max() - Z.min()), 40.0, 200.0))
    if not weight.any():
        return Z, band
    n = Z.shape[0] - 1
    x = (np.arange(n + 1) - 0.5 * n) * cell
    X, Y = np.meshgrid(x, x)
    warp = _fbm_heights(X, Y, dict(amplitude=band / 0.5, wavelength=20.0 * band, octaves=3, lacunarity=2.0,
                                   gain=0.5, seed=int(seed) + 7919))
    h = Z + warp
    # Bands of varied thickness and riser share, as beds are (equal bands read as a
    # contour map from above: the Salish crop's overview was regular stripes).
    rng = np.random.default_rng(int(seed) + 15838)
    lo_h, hi_h = float(h.min()) - 2.0 * band, float(h.max()) + 2.0 * band
    count = int(np.ceil((hi_h - lo_h) / (BAND_SPREAD[0] * band))) + 1
    thick = band * np.clip(np.exp(rng.normal(0.0, BAND_SIGMA, count)), *BAND_SPREAD)
    tops = lo_h + np.concatenate([[0.0], np.cumsum(thick)])
    riser = rng.uniform(*RISER, count)
    k = np.clip(np.searchsorted(tops, h, side="right") - 1, 0, count - 1)
    t = (h - tops[k]) / thick[k]
    stair = tops[k] + _smoothstep((t - (1.0 - riser[k])) / riser[k]) * thick[k] - warp
    return Z + weight * (stair - Z), band


def _smoothstep(u):
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def refine_crop(heights, cell, sea_level=0.0, seed=0, cells=REFINE_CELLS, width=CROP_WIDTH_M):
    """A window of a coarse DEM at a fine cell, with detail continuing its spectrum.

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` finite elevations (m), at least 3 x 3.
    cell : float
        The DEM's cell (m).
    sea_level : float or None
        Sea level (m; ``None``: no sea).
    seed : int
        Seed of the detail (same seed, same crop).
    cells : int
        Fine cells along the crop's side (>= 8).
    width : float
        Least crop width (m).

    Returns
    -------
    RefinedCrop
    """
    H = np.asarray(heights, np.float64)
    cell = float(cell)
    ny, nx = H.shape
    cells = int(cells)
    if cells < 8 or min(nx, ny) < 3:
        raise ValueError(f"refine_crop needs at least 8 fine cells and a 3x3 DEM (got {cells}, {nx}x{ny})")
    notes = []
    sheet = flat_sea(H, sea_level)
    if sheet is not None:
        H, deepest = lay_sea_floor(H, sheet, cell, sea_level)
        notes.append(f"the DEM's sea is a flat sheet: a floor was laid under it (at most {deepest:.3g} m deep) "
                     f"before refining")
    side = int(min(max(CROP_CELLS, math.ceil(float(width) / cell - 1e-9)), nx - 1, ny - 1))
    wet_level = None if sea_level is None else float(sea_level)
    i0, j0 = crop_window(H, side, wet_level)
    fine = side * cell / cells
    # One spline of the DEM serves the crop and the context.
    from scipy.ndimage import map_coordinates, spline_filter
    coefficients = spline_filter(H, order=3, mode="nearest")

    def spline(v, u):
        return map_coordinates(coefficients, [v, u], order=3, mode="nearest", prefilter=False)
    k = np.arange(cells + 1) * (side / cells)
    cubic = spline(*np.meshgrid(j0 + k, i0 + k, indexing="ij"))
    up = int(max(1, min(CONTEXT_UPSAMPLE, math.isqrt(CONTEXT_SAMPLES // (nx * ny)))))
    cv, cu = np.meshgrid(np.arange((ny - 1) * up + 1) / up, np.arange((nx - 1) * up + 1) / up, indexing="ij")
    context = spline(cv, cu) if up > 1 else H
    V, U = np.meshgrid((j0 + k) * up, (i0 + k) * up, indexing="ij")
    linear = map_coordinates(context, [V, U], order=1, mode="nearest")
    # Detail from the DEM's Nyquist wavelength down to four fine cells (precision 2 fine cells).
    table, fit = detail_amplification(H, cell, 2.0 * fine, seed=int(seed))
    x = (np.arange(cells + 1) - 0.5 * cells) * fine
    X, Y = np.meshgrid(x, x)
    detail = _fbm_heights(X, Y, table) if table is not None else np.zeros_like(linear)
    # Fades: towards the border (the crop meets its DEM's bilinear surface) and below the sea.
    edge = np.minimum(np.arange(cells + 1), np.arange(cells + 1)[::-1]) / (TAPER * cells)
    w = np.outer(_smoothstep(edge), _smoothstep(edge))
    if wet_level is not None and table is not None:
        sigma0 = table["amplitude"] * NOISE_RMS
        detail *= _smoothstep((linear - wet_level) / max(2.0 * sigma0, 1e-9))
    benched, bands = _benches(cubic, fine, wet_level, seed)
    fine_H = linear + w * (benched - linear + detail)
    centre = ((i0 + 0.5 * side) * cell, (j0 + 0.5 * side) * cell)
    context_extent = (-centre[0], -centre[1], (nx - 1) * cell - centre[0], (ny - 1) * cell - centre[1])
    octaves = int(table["octaves"]) if table is not None else 0
    wet = float(np.mean(H[j0:j0 + side + 1, i0:i0 + side + 1] < wet_level)) if wet_level is not None else 0.0
    coast = COAST_SHARE[0] <= wet <= COAST_SHARE[1]
    notes.append(
        f"refined: a {side * cell / 1000:.3g} km crop of the DEM's {nx - 1}x{ny - 1} cells of {cell:g} m "
        f"(columns {i0}-{i0 + side}, rows {j0}-{j0 + side}: its greatest relief"
        f"{', with a coast' if wet_level is not None and coast else ''}) at "
        f"{fine:.3g} m cells, a cubic spline "
        + (f"with {octaves} fBm octaves of the DEM's spectrum (Hurst {fit['hurst']:.2f})" if octaves
           else "(the DEM's spectrum gave no detail to continue)")
        + f", stepped into benches and risers {bands:.3g} m tall on slopes over {BENCH_SLOPES[0]:g} deg"
        + f"; the rest of the DEM, by the same spline at {cell / up:.4g} m, is the far field")
    return RefinedCrop(fine_H, fine, (i0, j0, side), context, context_extent, notes,
                       crop_lake_levels(H, wet_level, (i0, j0, side), cells))


def crop_lake_levels(H, sea_level, window, cells):
    """The lakes of a DEM over a crop of it: per crop sample, the level of the lake whose
    cells lie within one DEM cell of it (the highest, where two do), NaN elsewhere.

    The lakes are the DEM's own (:func:`.water.find_water` on its cells): the crop's
    benches and detail are relief the DEM did not measure, and its window may cut a
    basin open (:mod:`.water`, "Measured relief").

    Parameters
    ----------
    H : numpy.ndarray
        The DEM (m).
    sea_level : float or None
        Its sea level.
    window : (int, int, int)
        ``(i0, j0, side)``: the crop's first DEM sample (column, row) and its DEM cells a side.
    cells : int
        The crop's cells a side.

    Returns
    -------
    numpy.ndarray
        ``(cells + 1, cells + 1)`` levels (m).
    """
    from scipy.ndimage import maximum_filter

    from .water import find_water
    water = find_water(H, sea_level, lakes=True)
    lakes = np.where(water.sea | ~np.isfinite(water.level), -np.inf, water.level)
    near = maximum_filter(lakes, size=3, mode="nearest")
    i0, j0, side = window
    k = np.rint(np.arange(cells + 1) * (side / cells)).astype(int)
    out = near[np.ix_(j0 + k, i0 + k)]
    return np.where(np.isfinite(out), out, np.nan)


def attach_context(doc, crop, folder, prefix) -> str:
    """Write the crop's DEM beside the scene's data and name it in the scene's far field.

    Parameters
    ----------
    doc : dict
        The scene document (:func:`.scene_writer.scene_document`), with one ``far_field``.
    crop : RefinedCrop
    folder : Path
        The work folder the data files are written to.
    prefix : str
        Relative path prefix of the data files (as :func:`.amplify.amplify`'s).

    Returns
    -------
    str
        The file's path relative to the scene file.
    """
    from pathlib import Path
    rel = f"{prefix}.context.npy"
    path = Path(folder) / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, crop.context.astype(np.float32))
    for far in doc.get("far_field", []):
        far["context"] = {"file": rel, "extent": [float(v) for v in crop.context_extent]}
    return rel
