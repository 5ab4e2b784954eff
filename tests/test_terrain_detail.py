"""Sub-cell detail of terrain amplification (generators/terrain/detail.py, issue 24).

The detail continues the roughness *between* a DEM's landforms: a DEM's sharp
cliffs are already in the DEM and must not be spread over the whole tile as fBm
(on the gallery's chalk island they were: 3.4 m needles on every surface, shards
along the cliff tops and crumbs that sea erosion cut loose under the water).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from arches_render.generators.terrain import detail
from arches_render.generators.terrain.detail import detail_amplification


def _rough(shape, seed, rms, sigma=1.5):
    r = gaussian_filter(np.random.default_rng(seed).normal(size=shape), sigma, mode="wrap")
    return rms * r / r.std()


def _island(n=161, cliff=20.0):
    """A plateau ``cliff`` metres above a sea floor, its edge a one-cell step (1 m cells)."""
    x = np.arange(n) - (n - 1) / 2
    X, Y = np.meshgrid(x, x)
    inside = np.hypot(X / 50.0, Y / 38.0) + 0.05 * _rough(X.shape, 9, 1.0, 6.0) < 1.0
    return np.where(inside, cliff, 0.0)


@pytest.mark.parametrize("rms", [0.05, 0.3])
def test_cliffs_are_not_roughness(rms):
    """The same fine roughness with and without a 20 m cliff round an island gets the same
    detail within 2x (the coarsest bands still see the coast, which steepens the fitted
    spectrum); the fit on the Welch RMS gave the cliffy tile 13-77x more."""
    base = _rough((161, 161), 4, rms)
    _, flat = detail_amplification(base, 1.0, 0.1, seed=1)
    _, cliffy = detail_amplification(base + _island(), 1.0, 0.1, seed=1)
    ratio = cliffy["sigma0_m"] / flat["sigma0_m"]
    assert 0.5 < ratio < 2.0, (flat, cliffy)


def test_detail_continues_a_fractal():
    """On fBm-like relief (octave RMS ~ lambda^H) the fit finds H and the level of the
    2-cell octave the spectrum extrapolates to (within 30 %)."""
    rng = np.random.default_rng(2)
    n, Htrue = 256, 0.7
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n), indexing="ij"))
    amp = np.where(f > 0, np.maximum(f, 1e-9) ** -(1.0 + Htrue), 0.0)  # 2-D fBm: P(f) ~ f^-(2H+2)
    z = np.real(np.fft.ifft2(amp * np.exp(2j * np.pi * rng.random((n, n)))))
    lam, sig = detail.band_roughness(z, 1.0)
    _, fit = detail_amplification(z, 1.0, 0.1)
    assert fit["hurst"] == pytest.approx(Htrue, abs=0.15)
    # The line through the measured bands, extrapolated one octave below the finest.
    use = (lam >= 4) & (lam <= 64)
    slope, c = np.polyfit(np.log2(lam[use] / 2.0), np.log2(sig[use]), 1)
    assert fit["sigma0_m"] == pytest.approx(2.0 ** c, rel=0.3)
