"""Two-sample tests of Monte Carlo renders: does a test render converge to its reference?

A render of ``n`` samples per pixel estimates each pixel's expected value ``mu``
by the sample mean ``m``; with the per-pixel sample variance ``s^2`` (from the
second moment ``E[x^2]`` the renderer returns beside the mean, layer
``moment2``), ``Var(m) = s^2 / n``. Two renders of the same scene and code,
with independent samples, differ only by that noise, so for every pixel and
channel Welch's statistic

    z = (m_test - m_ref) / sqrt(s_test^2 / n_test + s_ref^2 / n_ref)

is close to standard normal (``n`` is large enough for the normal limit of
Welch's t; Jung et al. 2020 use it for the same purpose). The reference is a
render of a few times the test's samples, stored with its variance: it need not
be converged, since its noise enters the denominator.

Four tests, each aimed at one kind of regression, at family-wise false-alarm
rate :data:`ALPHA` unless said otherwise:

1. **Pixels** (Mitsuba 3's rule, ``src/render/tests/test_renders.py``): a
   two-sided p-value per pixel and channel, Sidak-corrected level
   ``1 - (1 - 0.01)^(1 / N)`` over the ``N`` pixel-channels; the image passes
   when at least 99.75 % of them pass. Broad changes fail it; a small one is
   lost in the allowed 0.25 %.
2. **Windows**: the same statistic on the luminance summed over every ``8 x 8``
   window and every ``16 x 16`` one, at every position (stride 1, so a changed
   patch at any offset is one window); Sidak over the windows of both sizes
   (conservative: overlapping windows are correlated). Summing 64 pixels cuts the
   noise of a local change by 8, summing 256 by 16: the wide windows are what
   sees a change in dark, noisy regions (shadowed rock under sky light), where an
   8 x 8 window's noise is several times its mean.
3. **Image mean**: the statistic on the sum over all pixels, per channel R, G,
   B and luminance Y (Sidak over the four): a 1 % global shift, a tint.
4. **Geometry** (noise of lighting does not enter): per pixel, the fraction of
   samples that hit a surface (Fisher's exact test on the two hit counts) and,
   where every sample of both renders hit one surface, the depth (the two means'
   difference over the larger of the two per-sample variances, the null's: a
   render that missed a pixel's rare depths underestimates its own); Sidak over the pixels and a *single* failing
   pixel fails. A void of one pixel or a surface that moved fails here
   whatever the light does.

Each statistic's variance gets a floor of ``(FLOOR_REL * |m_ref|)^2`` plus a
tiny absolute term: float32 accumulation in the film and ulp-level differences
between Dr.Jit back-ends change a noise-free pixel (sky) by about 1e-6 relative,
which would otherwise be infinitely significant.

A test is only as good as its power. :func:`power_check` requires, of a 1 % global
change, a 25 % change of the weakest ``8 x 8`` window at least a quarter as bright as
the image and a 25 % change of the weakest ``16 x 16`` window at least 1/32 as bright,
each up and down, that the change alone (its noise-free ``z``) exceed the test's limit
plus the render's own ``|z|``, so that it is detected whatever way the render itself
deviates, and that tests 3 and 2 reject the change injected into the test render; a
golden whose samples cannot prove that is reported as too weak, with the spp it would
need.

References
----------
.. [1] Welch, B. L. "The generalization of 'Student's' problem when several
   different population variances are involved", Biometrika 34, 1947.
.. [2] Jung, A., Hanika, J., Dachsbacher, C. "Detecting Bias in Monte Carlo
   Renderers using Welch's t-test", JCGT 9(2), 2020.
.. [3] Sidak, Z. "Rectangular confidence regions for the means of multivariate
   normal distributions", JASA 62, 1967.
.. [4] Jakob, W. et al. Mitsuba 3, ``src/render/tests/test_renders.py``
   (per-pixel Z-test, Sidak correction, 99.75 % pass rule).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from .pixel_moments import PixelMoments

__all__ = ["PixelMoments", "WelchResult", "ALPHA", "PIXEL_ALPHA", "PIXEL_PASS_FRACTION", "WINDOW",
           "FLOOR_REL", "SHIFT", "PATCH_CHANGE", "DARK_WINDOW", "WIDE_WINDOW", "WIDE_FLOOR", "sidak_z",
           "welch_compare", "power_check", "weakest_window", "window_stats"]

ALPHA = 1e-4
"""Family-wise false-alarm rate of the window, mean and geometry tests (each)."""

PIXEL_ALPHA = 0.01
"""Family-wise level of the per-pixel test before its pass fraction (Mitsuba's value)."""

PIXEL_PASS_FRACTION = 0.9975
"""Fraction of pixel-channels that must pass the per-pixel test (Mitsuba's value)."""

WINDOW = 8
"""Side of the windows of the window test, pixels."""

FLOOR_REL = 1e-4
"""Relative standard deviation added to every statistic's noise (float precision)."""

SHIFT = 0.01
"""Global relative brightening that :func:`power_check` must see rejected."""

PATCH_CHANGE = 0.25
"""Relative brightening of one ``WINDOW`` square that :func:`power_check` must see rejected."""

DARK_WINDOW = 0.25
"""``WINDOW`` squares darker than this fraction of the image's mean luminance are proven
by the wide windows instead (:data:`WIDE_WINDOW`). In shadowed rock lit by sky light
alone the per-sample noise is several times the mean: proving a 25 % change of an
8 x 8 window there down to 1/16 of the mean would take up to 550 spp on the shipped
goldens at 96 x 54, against 30-130 spp for the windows at least a quarter as bright."""

WIDE_WINDOW = 16
"""Side of the wide windows of the window test, pixels: what proves dark regions. Four
times the pixels of a ``WINDOW`` square halve the relative noise of a change, so a
25 % change of any 16 x 16 window of the shipped goldens is proven at 7-47 spp
(measured on all 20 at their check spp, 2026-12-04; 24 x 24 would need 2-8)."""

WIDE_FLOOR = 1.0 / 32.0
"""Wide windows darker than this fraction of the image's mean luminance are left out of
the power check (near-black: a relative change of nothing cannot be proven); none of
the shipped goldens has one."""

ONE_SURFACE = 0.05
"""A pixel whose samples' depths spread (standard deviation) by at most this fraction of
their mean sees one surface; only such pixels enter the depth test."""

_TINY = 1e-12


def sidak_z(alpha: float, tests: int) -> float:
    """Two-sided normal quantile at Sidak's per-test level for ``tests`` tests at family level ``alpha``.

    Parameters
    ----------
    alpha : float
        Family-wise false-alarm rate.
    tests : int
        Number of tests.

    Returns
    -------
    float
        ``z`` with ``P(|Z| > z) = 1 - (1 - alpha)^(1 / tests)``.
    """
    from scipy.special import ndtri  # on use: 0.17 s to import, and renders import this module
    per = -math.expm1(math.log1p(-alpha) / max(int(tests), 1))
    return float(-ndtri(per / 2.0))


@dataclass
class WelchResult:
    """Outcome of :func:`welch_compare`.

    Attributes
    ----------
    passed : bool
        No test failed.
    failures : list of str
        One line per failed test.
    pixel_pass : float
        Fraction of pixel-channels that passed the per-pixel test.
    window_z : float
        Largest ``|z|`` of a ``WINDOW`` square; ``window_where`` its top-left ``(y, x)``.
    wide_window_z : float
        Largest ``|z|`` of a ``WIDE_WINDOW`` square; ``wide_window_where`` its top-left.
    mean_z : tuple of float
        Signed ``z`` of the image mean of R, G, B, Y.
    mean_shift : tuple of float
        Relative shift of those means (test against reference).
    coverage_z, depth_z : float
        Largest per-pixel ``|z|`` of coverage and (fully covered) depth.
    limits : dict of str to float
        The thresholds applied.
    z_map : numpy.ndarray
        Per-pixel ``|z|`` of luminance ``(H, W)``.
    window_map : numpy.ndarray
        ``|z|`` of every window, ``(H - s + 1, W - s + 1)``.
    geometry_map : numpy.ndarray
        Per-pixel ``max(|z_coverage|, |z_depth|)``.
    """

    passed: bool
    failures: list[str]
    pixel_pass: float
    window_z: float
    window_where: tuple[int, int]
    mean_z: tuple[float, ...]
    mean_shift: tuple[float, ...]
    coverage_z: float
    depth_z: float
    limits: dict
    z_map: np.ndarray = field(repr=False)
    window_map: np.ndarray = field(repr=False)
    geometry_map: np.ndarray = field(repr=False)
    wide_window_z: float = 0.0
    wide_window_where: tuple[int, int] = (0, 0)

    def summary(self) -> str:
        """One line with every number and its limit."""
        lim = self.limits
        return (f"{'PASS' if self.passed else 'FAIL'}: pixels {self.pixel_pass:.4%} pass (need "
                f"{lim['pixel_pass']:.2%}), worst {WINDOW}x{WINDOW} window |z| {self.window_z:.2f} at (y, x) = "
                f"{self.window_where}, {WIDE_WINDOW}x{WIDE_WINDOW} {self.wide_window_z:.2f} at "
                f"{self.wide_window_where} (limit {lim['window_z']:.2f}), image mean z "
                f"{', '.join(f'{c} {z:+.2f}' for c, z in zip('RGBY', self.mean_z))} (limit {lim['mean_z']:.2f}), "
                f"coverage |z| {self.coverage_z:.2f}, depth |z| {self.depth_z:.2f} (limit {lim['geometry_z']:.2f})")

    def numbers(self) -> dict:
        """The scalar results (JSON compatible), without the maps."""
        return {"passed": self.passed, "failures": list(self.failures), "pixel_pass": self.pixel_pass,
                "window_z": self.window_z, "window_where": list(self.window_where),
                "wide_window_z": self.wide_window_z, "wide_window_where": list(self.wide_window_where),
                "mean_z": list(self.mean_z),
                "mean_shift": list(self.mean_shift), "coverage_z": self.coverage_z, "depth_z": self.depth_z,
                "limits": dict(self.limits)}


def _check_pair(ref: PixelMoments, test: PixelMoments) -> None:
    if ref.shape != test.shape:
        raise ValueError(f"image sizes differ: reference {ref.shape[1]}x{ref.shape[0]}, "
                         f"test {test.shape[1]}x{test.shape[0]} (width x height)")
    if not np.all(np.isfinite(ref.mean)) or not np.all(np.isfinite(ref.m2)):
        raise ValueError("the reference has NaN or infinite pixels")


def _noise(ref: PixelMoments, test: PixelMoments) -> np.ndarray:
    """``(H, W, 4)``: variance of ``m_test - m_ref`` per pixel, without the floor."""
    return ref.mean_variance() + test.mean_variance()


def _window_sums(a: np.ndarray, s: int) -> np.ndarray:
    # Summed-area table (Crow 1984) in float64: four look-ups per window.
    sat = np.zeros((a.shape[0] + 1, a.shape[1] + 1))
    np.cumsum(np.cumsum(a, axis=0), axis=1, out=sat[1:, 1:])
    return sat[s:, s:] - sat[:-s, s:] - sat[s:, :-s] + sat[:-s, :-s]


def _window_sides(shape) -> tuple[int, ...]:
    """The sides of the window test's squares on an image of ``shape``: ``WINDOW`` and
    ``WIDE_WINDOW``, each clipped to the image (one side where the two coincide)."""
    h, w = shape
    return tuple(dict.fromkeys(max(1, min(side, h, w)) for side in (WINDOW, WIDE_WINDOW)))


def _window_count(shape) -> int:
    """Windows the window test makes on an image of ``shape`` (every position of every side)."""
    h, w = shape
    return sum((h - s + 1) * (w - s + 1) for s in _window_sides(shape))


def _z(diff, var, level):
    return diff / np.sqrt(var + (FLOOR_REL * level) ** 2 + _TINY)


def window_stats(ref: PixelMoments, test: PixelMoments, s: int = WINDOW):
    """Luminance sums over every ``s x s`` window (stride 1) of two renders.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray, numpy.ndarray)
        ``sum(test - ref)``, the noise (standard deviation) of that sum, and
        ``sum(ref)``, each ``(H - s + 1, W - s + 1)``; entry ``[y, x]`` is the
        window whose top-left pixel is ``(y, x)``.
    """
    d = _window_sums(test.mean4[..., 3] - ref.mean4[..., 3], s)
    sd = np.sqrt(_window_sums(_noise(ref, test)[..., 3], s))
    return d, sd, _window_sums(ref.mean4[..., 3], s)


def _window_z(ref: PixelMoments, test: PixelMoments, s: int) -> np.ndarray:
    d = test.mean4[..., 3] - ref.mean4[..., 3]
    v = _noise(ref, test)[..., 3]
    return _z(_window_sums(d, s), _window_sums(v, s), _window_sums(np.abs(ref.mean4[..., 3]), s))


def _mean_z(ref: PixelMoments, test: PixelMoments) -> np.ndarray:
    d = (test.mean4 - ref.mean4).sum(axis=(0, 1))
    v = _noise(ref, test).sum(axis=(0, 1))
    return _z(d, v, np.abs(ref.mean4).sum(axis=(0, 1)))


def _coverage_z(ref: PixelMoments, test: PixelMoments) -> np.ndarray:
    """``|z|`` equivalent of the exact two-sided p-value that both renders' camera rays hit
    with the same probability, per pixel.

    Given the hits of both together, the test's hits follow a hypergeometric law
    (Fisher's exact test): exact where a pixel's hits are few, unlike the normal
    approximation (which failed a correct render 1 time in 60: 40 of 256 reference
    samples hit, 0 of 64 test samples, |z| = 6.2 against an exact p of 3e-5).
    """
    n_r, n_t = ref.n, test.n
    k_t = test.hits
    total = ref.hits + k_t
    # On use: scipy.stats takes 0.6 s to import, and every render (and every worker
    # process) imports this module for PixelMoments; only golden checks need the test.
    from scipy.special import ndtri
    from scipy.stats import hypergeom
    lower = hypergeom.cdf(k_t, n_r + n_t, total, n_t)
    upper = hypergeom.sf(k_t - 1, n_r + n_t, total, n_t)
    p = np.clip(2.0 * np.minimum(lower, upper), 0.0, 1.0)
    return -ndtri(p / 2.0)


def welch_compare(ref: PixelMoments, test: PixelMoments, alpha: float = ALPHA,
                  geometry: bool = True) -> WelchResult:
    """Test whether ``test`` and ``ref`` are renders of the same image (see the module doc).

    Parameters
    ----------
    ref : PixelMoments
        The reference (usually a few times the test's samples).
    test : PixelMoments
        The render under test, with samples independent of the reference's.
    alpha : float, optional
        Family-wise false-alarm rate of the window, mean and geometry tests.
    geometry : bool, optional
        Run the coverage and depth test (false where a side has no such layers,
        see :meth:`PixelMoments.from_batches`).

    Returns
    -------
    WelchResult
        Non-finite test pixels are a failure of their own and count 0 in the tests.

    Raises
    ------
    ValueError
        Different image sizes, or a non-finite reference.
    """
    _check_pair(ref, test)
    bad = ~(np.all(np.isfinite(test.mean), axis=2) & np.all(np.isfinite(test.m2), axis=2))
    if bad.any():
        test = replace(test, mean=np.where(bad[..., None], 0.0, test.mean),
                       m2=np.where(bad[..., None], 0.0, test.m2))
    h, w = ref.shape
    failures = []
    if bad.any():
        ys, xs = np.nonzero(bad)
        failures.append(f"{int(bad.sum())} test pixel(s) are NaN or infinite (first at y={ys[0]}, x={xs[0]})")

    # 1. Pixels (Mitsuba's rule), on R, G, B.
    z_pix = np.abs(_z(test.mean4 - ref.mean4, _noise(ref, test), np.abs(ref.mean4)))
    z_pixel_limit = sidak_z(PIXEL_ALPHA, h * w * 3)
    pixel_pass = float(np.mean(z_pix[..., :3] <= z_pixel_limit))
    if pixel_pass < PIXEL_PASS_FRACTION:
        failures.append(f"{1 - pixel_pass:.3%} of pixel-channels differ significantly (|z| > {z_pixel_limit:.2f}); "
                        f"at most {1 - PIXEL_PASS_FRACTION:.2%} may")

    # 2. Windows of both sides, on luminance.
    z_window_limit = sidak_z(alpha, _window_count(ref.shape))
    by_side = {}
    for s in _window_sides(ref.shape):
        wz = np.abs(_window_z(ref, test, s))
        wy, wx = np.unravel_index(int(np.argmax(wz)), wz.shape)
        by_side[s] = (wz, (int(wy), int(wx)))
        if wz[wy, wx] > z_window_limit:
            rel = _window_sums(test.mean4[..., 3] - ref.mean4[..., 3], s)[wy, wx] / max(
                _window_sums(ref.mean4[..., 3], s)[wy, wx], _TINY)
            failures.append(f"{s}x{s} window at (y={wy}, x={wx}) differs in luminance by {rel:+.1%} (|z| = "
                            f"{wz[wy, wx]:.1f} > {z_window_limit:.2f}); {int((wz > z_window_limit).sum())} "
                            f"window position(s) of that size over the limit")
    (wz, (wy, wx)), (wide_z, wide_where) = by_side[min(by_side)], by_side[max(by_side)]

    # 3. Image mean, per channel and luminance.
    mz = _mean_z(ref, test)
    z_mean_limit = sidak_z(alpha, 4)
    ref_sum = ref.mean4.sum(axis=(0, 1))
    shift = (test.mean4.sum(axis=(0, 1)) - ref_sum) / np.maximum(np.abs(ref_sum), _TINY)
    worst = int(np.argmax(np.abs(mz)))
    if abs(mz[worst]) > z_mean_limit:
        failures.append(f"image mean of {'RGBY'[worst]} shifted by {shift[worst]:+.3%} (z = {mz[worst]:+.1f}, "
                        f"limit {z_mean_limit:.2f}); R {shift[0]:+.3%}, G {shift[1]:+.3%}, B {shift[2]:+.3%}")

    # 4. Geometry: coverage everywhere, depth where every sample of both hit.
    z_geometry_limit = sidak_z(alpha, h * w)
    cov_z = _coverage_z(ref, test)
    # Depth where the pixel sees one surface in both renders: every sample hit, and the
    # samples' depths spread by at most ONE_SURFACE of the mean. A pixel that mixes a
    # near and a far surface has a two-valued depth whose mean is a hit fraction, for
    # which the normal limit fails at these counts (a correct render failed twice in
    # 200 checks, once by 83 m); coverage and the beauty tests see such pixels.
    full = (ref.coverage >= 1.0 - 1e-6) & (test.coverage >= 1.0 - 1e-6)
    for m in (ref, test):
        full &= np.sqrt(m.depth_sample_variance()) <= ONE_SURFACE * np.abs(m.depth)
    # Under the null both renders draw a pixel's depths from one distribution, so each
    # mean's variance is that distribution's over its n; the larger of the two sample
    # variances estimates it. Each side's own variance (Welch) failed correct renders
    # 2 times in 180 checks: a pixel whose depths are mostly one surface with rare
    # samples on a near one (a ledge, a boulder's rim) has a reference that caught
    # the rare ones and a test that did not, whose own variance is then 2-3x too
    # small (terrain_sea seed 1011: |z| 6.1 with Welch, 3.5 with this).
    per_sample = np.maximum(ref.depth_sample_variance(), test.depth_sample_variance())
    dep_z = np.where(full, np.abs(_z(test.depth - ref.depth, per_sample * (1.0 / ref.n + 1.0 / test.n),
                                     np.abs(ref.depth))), 0.0)
    if not geometry:
        cov_z, dep_z = np.zeros((h, w)), np.zeros((h, w))
    for what, zmap, sign in (("coverage", cov_z, test.coverage - ref.coverage), ("depth", dep_z,
                                                                                  test.depth - ref.depth)):
        over = zmap > z_geometry_limit
        if over.any():
            y, x = np.unravel_index(int(np.argmax(zmap)), zmap.shape)
            failures.append(f"{what} differs at {int(over.sum())} pixel(s) (worst y={y}, x={x}: {sign[y, x]:+.3g}, "
                            f"|z| = {zmap[y, x]:.1f} > {z_geometry_limit:.2f})")

    limits = {"pixel_z": z_pixel_limit, "pixel_pass": PIXEL_PASS_FRACTION, "window_z": z_window_limit,
              "mean_z": z_mean_limit, "geometry_z": z_geometry_limit, "alpha": alpha}
    return WelchResult(passed=not failures, failures=failures, pixel_pass=pixel_pass, window_z=float(wz[wy, wx]),
                       window_where=(wy, wx), wide_window_z=float(wide_z[wide_where]),
                       wide_window_where=wide_where, mean_z=tuple(float(v) for v in mz),
                       mean_shift=tuple(float(v) for v in shift), coverage_z=float(cov_z.max()),
                       depth_z=float(dep_z.max()), limits=limits, z_map=z_pix[..., 3], window_map=wz,
                       geometry_map=np.maximum(cov_z, dep_z))


def weakest_window(ref: PixelMoments, test: PixelMoments, change: float = PATCH_CHANGE, side: int = WINDOW,
                   floor: float = DARK_WINDOW) -> tuple[tuple[int, int], float]:
    """The window where scaling the test by ``1 + change`` is least significant.

    Parameters
    ----------
    ref, test : PixelMoments
        As for :func:`welch_compare`.
    change : float, optional
        Relative change of the window's beauty (negative: darkening).
    side : int, optional
        Side of the square windows (clipped to the image).
    floor : float, optional
        Only windows at least this fraction of the image's mean luminance count.

    Returns
    -------
    ((y, x), z)
        Top-left pixel of the window and the ``|z|`` that the change alone would
        give there (noise of the changed test and the reference, not the render's
        own deviation), among windows at least ``floor`` as bright as the image mean.
    """
    h, w = ref.shape
    s = max(1, min(side, h, w))
    y_ref = ref.mean4[..., 3]
    sums = _window_sums(y_ref, s)
    k = 1.0 + change
    var = _window_sums(ref.mean_variance()[..., 3] + k * k * test.mean_variance()[..., 3], s)
    z = abs(change) * _window_sums(test.mean4[..., 3], s) / np.sqrt(var + (FLOOR_REL * sums) ** 2 + _TINY)
    eligible = sums >= floor * s * s * max(float(y_ref.mean()), _TINY)
    z = np.where(eligible, z, np.inf)
    y, x = np.unravel_index(int(np.argmin(z)), z.shape)
    return (int(y), int(x)), float(z[y, x])


def power_check(ref: PixelMoments, test: PixelMoments, alpha: float = ALPHA) -> list[str]:
    """Prove on ``test`` that the tests reject a 1 % global and a 25 % local change, up and down.

    For each change (:data:`SHIFT` everywhere; :data:`PATCH_CHANGE` in the weakest
    ``WINDOW`` square at least :data:`DARK_WINDOW` as bright as the image and in the
    weakest ``WIDE_WINDOW`` square at least :data:`WIDE_FLOOR` as bright, from
    :func:`weakest_window`), brightening and darkening: the change's
    noise-free ``z`` must exceed the test's limit plus the render's own ``|z|`` there
    (so it is detected whatever way the render itself deviates, not by the luck of
    a render already deviating its way), and the change injected into ``test``
    (means and second moments scaled as a changed render's would be) must fail
    the image-mean or the window test.

    What this proves for windows: the weakest window of each size (smallest
    noise-free ``z`` of the change) is proven on this render, so a 25 % change of any
    8 x 8 region a quarter as bright as the image, and of any 16 x 16 region down to
    1/32 of it (shadows), is seen. Every other eligible window has a
    larger noise-free ``z``; a change there is missed only where the render's own
    deviation opposes it by more than that surplus, which the check does not rule
    out window by window (an estimate, not measured: with the largest own ``|z|`` of
    ~4000 windows near 3.5, that would take ~2.6x the samples).

    Parameters
    ----------
    ref, test : PixelMoments
        As for :func:`welch_compare` (``test`` should itself pass).
    alpha : float, optional
        As for :func:`welch_compare`.

    Returns
    -------
    list of str
        One line per change that is not proven, naming the samples per pixel that
        would prove it (empty: all six proven).
    """
    out = []
    z_mean_limit = sidak_z(alpha, 4)
    own = np.abs(_mean_z(ref, test))
    level = np.abs(ref.mean4).sum(axis=(0, 1))
    for change, word in ((SHIFT, "brightening"), (-SHIFT, "darkening")):
        changed = test.brightened(1.0 + change)
        alone = np.abs(_z(change * test.mean4.sum(axis=(0, 1)), _noise(ref, changed).sum(axis=(0, 1)), level))
        injected = np.abs(_mean_z(ref, changed))
        c = int(np.argmax(alone - own))
        if not (alone[c] - own[c] > z_mean_limit and injected[c] > z_mean_limit):
            out.append(f"a {abs(change):.0%} global {word} is not proven (z of the change {alone[c]:.2f}, the "
                       f"render's own |z| {own[c]:.2f}, limit {z_mean_limit:.2f}): "
                       f"{_spp_hint(test.n, alone[c], z_mean_limit + own[c])}")
    z_window_limit = sidak_z(alpha, _window_count(ref.shape))
    for (s, floor), (change, word) in itertools.product(
            zip(_window_sides(ref.shape), (DARK_WINDOW, WIDE_FLOOR)),
            ((PATCH_CHANGE, "brightening"), (-PATCH_CHANGE, "darkening"))):
        (wy, wx), alone = weakest_window(ref, test, change, s, floor)
        own_w = abs(float(_window_z(ref, test, s)[wy, wx]))
        patched = test.brightened(1.0 + change, (slice(wy, wy + s), slice(wx, wx + s)))
        zp = abs(float(_window_z(ref, patched, s)[wy, wx]))
        if not (alone - own_w > z_window_limit and zp > z_window_limit):
            out.append(f"a {abs(change):.0%} {word} of the {s}x{s} window at (y={wy}, x={wx}) is not proven "
                       f"(z of the change {alone:.2f}, the render's own |z| there {own_w:.2f}, limit "
                       f"{z_window_limit:.2f}): {_spp_hint(test.n, alone, z_window_limit + own_w)}")
    return out


def _spp_hint(n: int, z_expected: float, limit: float) -> str:
    # z of a fixed change grows like sqrt(n) (both renders scaled together); aim
    # for 3 sigma above the limit so that the check itself rarely misfires.
    if not np.isfinite(z_expected) or z_expected <= 0:
        return "raise the test spp"
    need = n * ((limit + 3.0) / z_expected) ** 2
    return f"the test needs about {int(math.ceil(need))} spp (has {n})"
