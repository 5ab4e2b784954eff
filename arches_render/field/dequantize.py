"""Quantized DEMs: heights stored on a lattice (whole metres, say) and the terraces they make.

Why. Many DEMs store integer metres (SRTM, USGS 1-degree and ASCII grids, R's
``volcano``, int16 GeoTIFFs). Where the ground rises less than a step per cell, such
a DEM is a staircase: flat treads a few cells wide joined by one-step risers. A
renderer shows what it is given: lit from a low sun, the treads read as contour
terraces, and a triplanar material that puts rock on steep ground draws the risers
as square patches of rock on a grass slope (``real_maunga_whau_10m``: 27 % of the
neighbouring samples equal, in a crater whose walls rise 1-2 m a cell).

What. The true surface passed within half a step of every sample, so any surface
inside those intervals is as faithful to the data; the smoothest one has no
terraces. :func:`dequantize` finds a smooth one by *projected smoothing*: it blurs
the heights and clamps every sample back into ``[h - q/2, h + q/2]``, many times,
at spacings from coarse to fine (16, 8, ..., 1 samples: a wide tread needs the
coarse passes, a small one only the fine). Its fixed point is discrete-harmonic
wherever no bound holds it, i.e. a ramp across each tread. A slope steeper than a
step per cell, a cliff or a peak is held by its own intervals: nothing moves by more
than ``q / 2``. With a sea level, a sample at or below it stays at or below it and
one above stays above (the coast, and which cells are sea, do not move).

When. :func:`quantization_step` answers only for lattice data whose terraces show:
every height on ``h0 + k q`` (to 1 % of ``q``), at least ``MIN_LEVELS`` levels over
the relief (a DEM of a few plateaus is shapes, not rounding), and ``q`` at least
``MIN_STEP_FRACTION`` of the median non-zero difference between neighbours (a 1 m
lattice under 44 m differences, ``real_salish_sea_2435m``, shows no terrace).

Why by hand: a dozen lines of numpy; the libraries that read DEMs (GDAL, rasterio,
richdem) offer smoothing filters that move samples freely, none bounded by the
quantization interval.

References
----------
Guth, P. L. (1999). Contour line "ghosts" in USGS level 2 DEMs. Photogrammetric
Engineering & Remote Sensing 65(3) (terraces of integer DEMs).
Rodriguez, E. et al. (2005). An assessment of the SRTM topographic products. JPL D-31639
(SRTM heights are stored as whole metres).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MIN_LEVELS", "MIN_STEP_FRACTION", "dequantize", "quantization_step"]

#: Fewest lattice levels over the relief for heights to count as quantized.
MIN_LEVELS = 50
#: Smallest lattice step, as a fraction of the median non-zero neighbour difference,
#: whose terraces count.
MIN_STEP_FRACTION = 0.1
#: Largest distance of a height from the lattice, as a fraction of the step.
LATTICE_TOLERANCE = 0.01
#: Blur spacings (samples), coarse to fine, and passes at each.
SPACINGS = (16, 8, 4, 2, 1)
PASSES = 24


def quantization_step(heights):
    """The lattice step ``q`` of a DEM whose heights are quantized visibly, else ``None``
    (module docstring, "When").

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` finite heights.

    Returns
    -------
    float or None
    """
    H = np.asarray(heights, dtype=np.float64)
    d = np.concatenate([np.abs(np.diff(H, axis=0)).ravel(), np.abs(np.diff(H, axis=1)).ravel()])
    moving = d[d > 0]
    if moving.size == 0:
        return None
    # The smallest step, refined by least squares over every level (a float32 file's
    # rounding makes the smallest difference a few ulps off, which adds up over levels).
    rise = H - H.min()
    k = np.round(rise / float(moving.min()))
    q = float(np.sum(rise * k) / np.sum(k * k))
    slack = max(LATTICE_TOLERANCE * q, 8.0 * float(np.finfo(np.float32).eps) * float(np.max(np.abs(H))))
    if float(np.max(np.abs(rise - k * q))) > slack:
        return None
    if (H.max() - H.min()) / q < MIN_LEVELS or q < MIN_STEP_FRACTION * float(np.median(moving)):
        return None
    return q


def _blur(Z, s, out):
    """``out`` = the binomial filter ``(1, 2, 1) / 4`` of ``Z`` with taps ``s`` samples apart,
    along both axes (edges repeat their last sample); ``Z`` is overwritten."""
    for axis in (0, 1):
        src = Z if axis == 0 else Z.T
        dst = out if axis == 0 else out.T
        np.multiply(src, 0.5, out=dst)
        dst[s:] += 0.25 * src[:-s]
        dst[:s] += 0.25 * src[:1]
        dst[:-s] += 0.25 * src[s:]
        dst[-s:] += 0.25 * src[-1:]
        Z, out = out, Z
    return Z, out


def _inward(bound, towards):
    """``bound`` as float32, rounded towards ``towards`` where float32 cannot hold it."""
    b32 = bound.astype(np.float32)
    off = np.where(towards > bound, b32 < bound, b32 > bound)
    return np.where(off, np.nextafter(b32, np.where(towards > bound, np.inf, -np.inf).astype(np.float32)), b32)


def dequantize(heights, step, sea_level=None):
    """The smoothest heights found within half a lattice step of ``heights`` (module
    docstring, "What").

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` heights on a lattice of step ``step``.
    step : float
        The lattice step ``q`` (:func:`quantization_step`).
    sea_level : float, optional
        Samples at or below it stay at or below it; samples above stay above.

    Returns
    -------
    numpy.ndarray
        float64 heights, each within ``step / 2`` of its input.
    """
    H = np.asarray(heights, dtype=np.float64)
    lo, hi = H - 0.5 * step, H + 0.5 * step
    if sea_level is not None:
        wet = H <= sea_level
        hi = np.where(wet, np.minimum(hi, sea_level), hi)
        # Strictly above, by a part in 1e6 of the step (float32 storage keeps it above).
        lo = np.where(wet, lo, np.maximum(lo, sea_level + 1e-6 * step + 1e-7 * abs(sea_level)))
    # float32 throughout (a file's heights are float32 anyway): half the memory traffic.
    lo, hi = _inward(lo, H), _inward(hi, H)
    Z, spare = H.astype(np.float32), np.empty(H.shape, np.float32)
    for s in SPACINGS:
        if s >= min(H.shape):
            continue
        for _ in range(PASSES):
            Z, spare = _blur(Z, s, spare)
            np.clip(Z, lo, hi, out=Z)
    return Z.astype(np.float64)
