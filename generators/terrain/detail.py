"""Detail below the DEM's cell: fBm octaves that continue the DEM's own spectrum (issue 14).

A DEM resolves wavelengths down to two cells; below, a mesh of it is flat. The
paper amplifies terrains "at a precision of about 10 cm" (Paris et al. 2019,
Sec. 8.3) and builds its terrains from fBm ``t(p) = sum_k 2^-k n(2^k p)`` (Sec. 3.3);
it does not say how the fBm is matched to a DEM. We continue the DEM's own
spectrum, the usual assumption of fractal terrain synthesis (Mandelbrot 1982;
Musgrave 2003): natural relief has octave amplitudes ``sigma(lambda) ~ lambda^H``
over a wide range (Hurst exponent ``H``, typically 0.5-0.9), so

1. the RMS ``sigma_b`` of the DEM in octave bands of wavelength 4-8, 8-16, ...,
   up to 64 cells is measured *robustly* (:func:`band_roughness`): the band-pass
   ``B_b = G_(s(lo)) * H - G_(s(hi)) * H`` (Gaussian low-passes whose gain is 1/2 at
   the band's edges, ``s(lambda) = lambda sqrt(ln 2 / 2) / pi``) and
   ``sigma_b = 1.4826 median |B_b - median B_b|`` (the normal-consistent median
   absolute deviation); the 2-4 cell band is left out, resampling and
   interpolation deplete it;
2. a line ``log2 sigma = log2 sigma_0 + H log2(lambda / 2 cell)`` is fitted
   (least squares), ``H`` clipped to ``[0.4, 1]`` (rougher than white noise, no
   smoother than a ramp); when ``H`` was clipped the line no longer passes
   through all bands, and it is anchored at the finest band (the one the
   extrapolation continues from): ``sigma_0 = sigma_1 (lambda_0 / lambda_1)^H``;
3. the fBm starts at ``lambda_0 = 2 cells`` (the grid's Nyquist wavelength) with
   ``amplitude = sigma_0 / NOISE_RMS``, lacunarity 2, gain ``2^-H``, and has as many
   octaves as halvings from ``lambda_0`` to ``2 precision`` (the smallest feature,
   half a wavelength, is then the precision), at most 12.

Why the median and the anchor (issue 24). The band RMS of a power spectrum is a
mean over the tile (Parseval), and a few sharp cliffs (steps: amplitude ``~ 1/f``)
dominate it: on a 1 m chalk island (the gallery's Fig. 23 coast) the 4-8 cell
band has 1.2 m RMS and a median deviation under 1 cm. Spread uniformly as fBm, that
energy covered every surface with metre-high needles: shards along the cliff top
and, under the sea, bumps that the sea-erosion spheres cut loose into floating
crumbs. The cliffs are already in the DEM; the detail is the roughness *between*
them, which the median measures (a DEM rough everywhere, e.g. an eroded canyon,
keeps nearly its RMS). Likewise a least-squares level refitted after clipping a
steep spectrum (``H > 1``: smooth landforms, sharp edges) is pulled up by the
large-scale bands: 14x above the finest band's level on that island.

The amplitude is uniform over the tile: a flat sea floor or valley fill gets the
same roughness as a cliff (a slope-dependent amplitude would be closer to nature
and is left for later).

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), Sec. 3.3, 8.3.
Mandelbrot, B. B. (1982). The fractal geometry of nature. Freeman.
Musgrave, F. K. (2003). Procedural fractal terrains. In Texturing and Modeling, 3rd ed.
Welch, P. (1967). The use of fast Fourier transform for the estimation of power
spectra. IEEE Trans. Audio Electroacoustics 15(2), 70-73.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["NOISE_RMS", "default_precision", "band_roughness", "detail_amplification"]

#: RMS of the gradient noise off the lattice planes (measured on 2e6 random points: 0.253
#: on z = 0, 0.270 in 3-D; the fBm's octaves are offset off the plane).
NOISE_RMS = 0.26


def default_precision(cell_size: float) -> float:
    """``--precision`` default: 10 cm for DEMs of 2 m cells or finer, ``cell / 16`` otherwise."""
    return 0.1 if cell_size <= 2.0 else float(cell_size) / 16.0


def band_roughness(heights, cell_size, max_cells=64):
    """Robust RMS height of the DEM per octave band of wavelength (module docstring, step 1).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations (m).
    cell_size : float
        Metres per cell.
    max_cells : int
        Longest band edge in cells (bands ``[2^k, 2^(k+1))`` cells up to it, and
        at most a quarter of the shorter side).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        Band centre wavelengths (m, geometric means of the band edges) and robust
        RMS (m): ``1.4826 MAD`` of the band-pass, away from the border (where the
        reflected boundary bends planes); empty when the DEM is smaller than 8 x 8.
    """
    from scipy.ndimage import gaussian_filter
    H = np.asarray(heights, np.float64)
    ny, nx = H.shape
    top = min(int(max_cells), min(ny, nx) // 4)
    if top < 4:
        return np.zeros(0), np.zeros(0)
    s = math.sqrt(math.log(2.0) / 2.0) / math.pi  # Gaussian sigma whose gain at lambda is 1/2, per lambda
    centres, rms = [], []
    k = 1
    low = gaussian_filter(H, s * 2.0, mode="reflect")
    while 2 ** (k + 1) <= top:
        nxt = gaussian_filter(H, s * 2.0 ** (k + 1), mode="reflect")
        m = min(int(math.ceil(2.0 * s * 2.0 ** (k + 1))), min(ny, nx) // 4)
        b = (low - nxt)[m:ny - m, m:nx - m]
        rms.append(1.4826 * float(np.median(np.abs(b - np.median(b)))))
        centres.append(2 ** (k + 0.5) * float(cell_size))
        low, k = nxt, k + 1
    return np.array(centres), np.array(rms)


def detail_amplification(heights, cell_size, precision, seed=0, max_octaves=12):
    """The ``amplification`` table of an ``implicit_heightfield`` continuing the DEM's spectrum.

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations (m).
    cell_size : float
        DEM cell (m).
    precision : float
        Smallest feature (half the finest wavelength), metres.
    seed : int
        Noise seed.
    max_octaves : int

    Returns
    -------
    (dict or None, dict)
        The table (``amplitude``, ``wavelength``, ``octaves``, ``lacunarity``, ``gain``,
        ``seed``), or ``None`` when the precision is not below the DEM's cell or the
        DEM is flat; and the fit (``hurst``, ``sigma0_m``, ``bands``).
    """
    cell = float(cell_size)
    lam0 = 2.0 * cell
    octaves = int(math.floor(math.log2(lam0 / (2.0 * float(precision))) + 1e-9)) + 1 if precision < cell else 0
    octaves = min(octaves, max_octaves)
    lam, rms = band_roughness(heights, cell)
    fit = dict(bands=[(float(a), float(b)) for a, b in zip(lam, rms)], hurst=None, sigma0_m=0.0)
    use = (lam >= 4.0 * cell) & (lam <= 64.0 * cell) & (rms > 0)
    if octaves < 1 or use.sum() < 2:
        return None, fit
    x, y = np.log2(lam[use] / lam0), np.log2(rms[use])
    H_fit, c = np.polyfit(x, y, 1)
    Hh = float(np.clip(H_fit, 0.4, 1.0))
    # Clipped: the line through the finest band (the extrapolation continues from it);
    # otherwise the least-squares level.
    sigma0 = float(2.0 ** (y[0] - Hh * x[0]) if Hh != H_fit else 2.0 ** c)
    fit.update(hurst=Hh, sigma0_m=sigma0)
    if not sigma0 > 1e-6:
        return None, fit
    table = dict(amplitude=sigma0 / NOISE_RMS, wavelength=lam0, octaves=int(octaves), lacunarity=2.0,
                 gain=float(2.0 ** -Hh), seed=int(seed))
    return table, fit
