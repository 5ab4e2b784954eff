"""Compare a low-spp test render with a high-spp reference, with thresholds set by the noise floor.

Three checks, each aimed at one kind of regression:

1. **Global mean shift** (``mean_rel``, 1 %): the relative difference of the
   image mean, computed per RGB channel; the worst channel is reported. Per
   channel rather than on luminance so that a tint (red up, blue down) that
   leaves the luminance unchanged still fails. The measured shift of a render
   that is really 1 % too bright is ``1 % + noise``; compared with 1 % as is,
   it would pass about half the time. So the rule "a shift of 1 % fails" is
   applied as ``|shift| > mean_rel - mean_guard``, where :func:`calibrate` sets
   the guard to 4 sigma of the noise of the image mean at the test spp, capped
   at ``mean_rel / 2`` (the point where passing a good render and failing a
   1 % shift are equally likely to go wrong). Sigma is estimated from each
   calibration render's own error image (:func:`mean_noise`), which is far
   more precise than the spread of a handful of seeds. At the test spp the
   image mean averages ``H * W * spp`` samples, so the guard is small
   (0.2-0.5 % at 48 x 48 pixels, 16-64 spp) for any useful golden;
   :func:`calibrate` warns when the cap is reached (sigma > 0.125 %, i.e. a
   3 sigma noise of ~0.4 %): then the 1 % rule is no longer reliable.
2. **Local window error** (``tile``): for every ``8 x 8`` window, at every
   position (stride 1, so a changed patch at any offset is covered fully by one
   window), ``|mean_test - mean_ref| / (mean_ref + eps)`` on Rec.709
   luminance, with ``eps = eps_rel * mean_ref_luminance`` (1 % of the image
   mean) so that nearly black windows can not produce huge relative errors
   from tiny absolute ones. A window mean averages ``64 * spp`` samples: it
   catches a localized change (a broken material on a small object, a hole in
   the surface) that is invisible in the global mean and lost in per-pixel
   noise.
3. **FLIP** (``flip``): NVIDIA's perceptual difference, mean over the image.
   We evaluate it in **LDR** mode on the sRGB-encoded previews (exposure 0,
   clipped to [0, 1]): that is what a person looks at, it needs no exposure
   range estimation (HDR-FLIP picks its exposures from the image, so its value
   moves with the brightest pixel), and it is one evaluation instead of one per
   exposure (2x to several times faster). Highlights above 1 are invisible to
   it; checks 1 and 2 work on the linear values and cover them.

Window means use a summed-area table in float64, so every one of the
``(H - 7) (W - 7)`` window means costs four look-ups.

References
----------
.. [1] Andersson, P., Nilsson, J., Akenine-Moller, T., Oskarsson, M., Astrom, K.,
   Fairchild, M. D. "FLIP: A Difference Evaluator for Alternating Images",
   Proc. ACM Comput. Graph. Interact. Tech. 3(2), 2020.
.. [2] ITU-R BT.709-6, "Parameter values for the HDTV standards for production
   and international programme exchange", 2015 (luminance weights).
.. [3] Crow, F. C. "Summed-area tables for texture mapping", SIGGRAPH 1984.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import asdict, dataclass, field, fields
from typing import Sequence

import numpy as np

from .preview import encode_srgb

__all__ = [
    "LUMINANCE_WEIGHTS", "Thresholds", "CompareResult", "CalibrationWarning",
    "luminance", "window_error", "mean_shift", "flip_error", "compare", "calibrate",
    "mean_noise", "TILE_MARGIN", "FLIP_MARGIN", "MEAN_GUARD_SIGMAS", "TILE_WARNING",
]

LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)
"""Rec.709 luminance weights of linear R, G, B."""

TILE_MARGIN = 2.0
"""Calibrated ``tile`` = worst window error of the calibration renders x this."""

FLIP_MARGIN = 1.25
"""Calibrated ``flip`` = worst FLIP mean of the calibration renders x this."""

MEAN_GUARD_SIGMAS = 4.0
"""Calibrated ``mean_guard`` = this many standard deviations of the image mean's noise."""

TILE_WARNING = 0.2
"""Calibration warns when the tile threshold exceeds this (a 25 % patch change may pass)."""


class CalibrationWarning(UserWarning):
    """The test spp is too low for the comparison to be reliable."""


@dataclass(kw_only=True)
class Thresholds:
    """Pass limits of :func:`compare`, normally produced by :func:`calibrate`.

    Attributes
    ----------
    tile : float
        Largest allowed relative error of an ``tile_size``-square window mean
        of luminance.
    flip : float
        Largest allowed mean LDR-FLIP error.
    mean_rel : float, optional
        Relative shift of the image mean of an RGB channel that must fail
        (default 0.01, i.e. 1 %).
    mean_guard : float, optional
        Noise guard band: the mean check fails above ``mean_rel - mean_guard``
        so that a true shift of ``mean_rel`` fails despite noise (default 0;
        set by :func:`calibrate`).
    tile_size : int, optional
        Window side in pixels (default 8).
    eps_rel : float, optional
        Window error denominator offset, as a fraction of the reference's mean
        luminance (default 0.01).
    calibration : dict, optional
        Noise measurements the thresholds were derived from (informational).
    """

    tile: float
    flip: float
    mean_rel: float = 0.01
    mean_guard: float = 0.0
    tile_size: int = 8
    eps_rel: float = 0.01
    calibration: dict = field(default_factory=dict)

    @property
    def mean_limit(self) -> float:
        """The applied limit of the global mean shift, ``mean_rel - mean_guard``."""
        return self.mean_rel - self.mean_guard

    def to_dict(self) -> dict:
        """Plain-data copy of the thresholds (JSON compatible)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "Thresholds":
        """Thresholds from :meth:`to_dict` output; unknown keys are ignored (newer files)."""
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in known})

    def to_json(self) -> str:
        """The thresholds as a JSON string."""
        return json.dumps(self.to_dict(), indent=2, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> "Thresholds":
        """Thresholds from a :meth:`to_json` string."""
        return cls.from_dict(json.loads(text))


@dataclass
class CompareResult:
    """Outcome of :func:`compare`.

    Attributes
    ----------
    passed : bool
        ``True`` when no check failed.
    mean_shift : float
        Signed relative shift of the image mean of the worst RGB channel
        (``+0.01`` = test 1 % brighter).
    mean_shift_rgb : tuple of float
        The signed relative shift of each channel.
    tile_max : float
        Worst relative window error.
    tile_where : tuple of int
        ``(y, x)`` of the top-left pixel of the worst window.
    flip_mean : float
        Mean LDR-FLIP error.
    failures : list of str
        One human-readable line per failed check (empty when passed).
    thresholds : Thresholds
        The limits used.
    tile_map : numpy.ndarray
        Window error of every window position, ``(H - s + 1, W - s + 1)``.
    flip_map : numpy.ndarray
        Per-pixel FLIP error, ``(H, W)``.
    nonfinite : int
        Number of test pixels with NaN or infinite values.
    """

    passed: bool
    mean_shift: float
    mean_shift_rgb: tuple[float, float, float]
    tile_max: float
    tile_where: tuple[int, int]
    flip_mean: float
    failures: list[str]
    thresholds: Thresholds
    tile_map: np.ndarray = field(repr=False)
    flip_map: np.ndarray = field(repr=False)
    nonfinite: int = 0

    def summary(self) -> str:
        """One line with every number and its limit."""
        t = self.thresholds
        return (f"{'PASS' if self.passed else 'FAIL'}: mean shift {self.mean_shift:+.3%} (limit {t.mean_limit:.2%}), "
                f"worst {t.tile_size}x{t.tile_size} window {self.tile_max:.4f} at (y, x) = {self.tile_where} "
                f"(limit {t.tile:.4f}), FLIP {self.flip_mean:.5f} (limit {t.flip:.5f})")

    def numbers(self) -> dict:
        """The scalar results (JSON compatible), without the maps."""
        return {"passed": self.passed, "mean_shift": self.mean_shift, "mean_shift_rgb": list(self.mean_shift_rgb),
                "tile_max": self.tile_max, "tile_where": list(self.tile_where), "flip_mean": self.flip_mean,
                "nonfinite": self.nonfinite, "failures": list(self.failures), "thresholds": self.thresholds.to_dict()}


def _image(a, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"{what} must be an H x W x 3 array, got shape {a.shape}")
    return a


def luminance(rgb) -> np.ndarray:
    """Rec.709 relative luminance of linear RGB.

    Parameters
    ----------
    rgb : array_like
        Linear Rec.709 colour, ``(..., 3)``.

    Returns
    -------
    numpy.ndarray
        float64 luminance, shape ``(...)``.

    References
    ----------
    ITU-R BT.709-6, item 3.2.
    """
    return np.asarray(rgb, dtype=np.float64) @ np.asarray(LUMINANCE_WEIGHTS)


def _window_means(y: np.ndarray, s: int) -> np.ndarray:
    sat = np.zeros((y.shape[0] + 1, y.shape[1] + 1))
    np.cumsum(np.cumsum(y, axis=0), axis=1, out=sat[1:, 1:])
    return (sat[s:, s:] - sat[:-s, s:] - sat[s:, :-s] + sat[:-s, :-s]) / (s * s)


def window_error(ref, test, tile_size: int = 8, eps_rel: float = 0.01) -> np.ndarray:
    """Relative error of the luminance mean of every ``tile_size`` square window.

    Parameters
    ----------
    ref, test : array_like
        Linear RGB images, ``(H, W, 3)``, same shape.
    tile_size : int, optional
        Window side; reduced to the image size for smaller images.
    eps_rel : float, optional
        Denominator offset as a fraction of ``ref``'s mean luminance.

    Returns
    -------
    numpy.ndarray
        ``|m_test - m_ref| / (m_ref + eps)`` for every window position (stride
        1), shape ``(H - s + 1, W - s + 1)``; entry ``[y, x]`` is the window whose
        top-left pixel is ``(y, x)``.

    References
    ----------
    Crow 1984 (summed-area tables), see module references.
    """
    yr, yt = luminance(_image(ref, "ref")), luminance(_image(test, "test"))
    if yr.shape != yt.shape:
        raise ValueError(f"image sizes differ: reference {yr.shape}, test {yt.shape}")
    s = max(1, min(int(tile_size), *yr.shape))
    # Negative radiance is impossible, but a reconstruction filter with
    # negative lobes can produce it; clamp so eps keeps the denominator positive.
    eps = max(eps_rel * float(np.mean(yr)), 1e-12)
    mr, mt = np.maximum(_window_means(yr, s), 0.0), _window_means(yt, s)
    return np.abs(mt - mr) / (mr + eps)


def mean_shift(ref, test) -> np.ndarray:
    """Signed relative shift of the image mean of each RGB channel.

    Parameters
    ----------
    ref, test : array_like
        Linear RGB images, ``(H, W, 3)``.

    Returns
    -------
    numpy.ndarray
        ``(mean_test - mean_ref) / (mean_ref + eps)`` per channel, shape ``(3,)``;
        ``eps`` is 1e-3 of the reference's mean luminance so that a channel
        that is black in the reference does not divide by zero.
    """
    r, t = _image(ref, "ref"), _image(test, "test")
    mr, mt = r.mean(axis=(0, 1)), t.mean(axis=(0, 1))
    eps = max(1e-3 * float(luminance(mr)), 1e-12)
    return (mt - mr) / (np.maximum(mr, 0.0) + eps)


def mean_noise(ref, test, block: int = 4) -> np.ndarray:
    """Standard deviation of the relative image-mean noise, estimated from one render.

    Parameters
    ----------
    ref, test : array_like
        Linear RGB images, ``(H, W, 3)``; ``test`` must be a render that differs
        from ``ref`` by noise only.
    block : int, optional
        Side of the pixel blocks whose error sums are treated as independent
        (default 4).

    Returns
    -------
    numpy.ndarray
        Per channel, the estimated standard deviation of :func:`mean_shift`.

    Notes
    -----
    The image mean's error is the sum of the block error sums ``S_b`` divided
    by ``N = H * W``; blocks are nearly independent, so
    ``Var(mean) ~ sum_b S_b**2 / N**2``. Summing over blocks rather than
    single pixels keeps the estimate right when a reconstruction filter wider
    than a pixel correlates neighbours. On the 48 x 48 test scene it matched
    the spread of the mean over 200 seeds within 2 %, with an 8 % scatter
    between renders.
    """
    r, t = _image(ref, "ref"), _image(test, "test")
    e = t - r
    h, w = e.shape[:2]
    sums = np.add.reduceat(np.add.reduceat(e, np.arange(0, h, block), axis=0), np.arange(0, w, block), axis=1)
    mr = r.mean(axis=(0, 1))
    eps = max(1e-3 * float(luminance(mr)), 1e-12)
    return np.sqrt(np.sum(sums ** 2, axis=(0, 1))) / (h * w) / (np.maximum(mr, 0.0) + eps)


def flip_error(ref, test) -> tuple[np.ndarray, float]:
    """LDR-FLIP error between the sRGB previews of two linear images.

    Parameters
    ----------
    ref, test : array_like
        Linear RGB images, ``(H, W, 3)``.

    Returns
    -------
    flip_map : numpy.ndarray
        Per-pixel error in [0, 1], float32 ``(H, W)``.
    flip_mean : float
        Its mean.

    References
    ----------
    Andersson et al. 2020, via NVIDIA's ``flip_evaluator`` (default 67 pixels
    per degree).
    """
    import flip_evaluator  # on use: only FLIP scores need it (conftest loads this module)


    r = np.ascontiguousarray(encode_srgb(ref), dtype=np.float32)
    t = np.ascontiguousarray(encode_srgb(test), dtype=np.float32)
    fmap, fmean, _ = flip_evaluator.evaluate(r, t, "LDR", inputsRGB=True, applyMagma=False,
                                             computeMeanError=True)
    return np.asarray(fmap, dtype=np.float32).reshape(r.shape[:2]), float(fmean)


def compare(ref, test, thresholds: Thresholds) -> CompareResult:
    """Compare a test render with its reference.

    Parameters
    ----------
    ref : array_like
        High-spp reference, linear RGB ``(H, W, 3)``.
    test : array_like
        Test render, same shape.
    thresholds : Thresholds
        Limits, usually from :func:`calibrate`.

    Returns
    -------
    CompareResult
        Numbers, maps, and the list of failed checks. Non-finite test pixels
        are a failure of their own; they are replaced by 0 for the other checks.

    Raises
    ------
    ValueError
        When the images are not ``(H, W, 3)`` arrays of the same shape, or the
        reference has non-finite pixels.

    References
    ----------
    See the module references (FLIP, Rec.709, summed-area tables).
    """
    r, t = _image(ref, "reference"), _image(test, "test")
    if r.shape != t.shape:
        raise ValueError(f"image sizes differ: reference {r.shape[1]}x{r.shape[0]}, "
                         f"test {t.shape[1]}x{t.shape[0]} (width x height)")
    if not np.all(np.isfinite(r)):
        raise ValueError("the reference image has NaN or infinite pixels")
    bad = ~np.all(np.isfinite(t), axis=2)
    nonfinite = int(bad.sum())
    if nonfinite:
        t = np.where(bad[..., None], 0.0, t)

    shifts = mean_shift(r, t)
    worst = int(np.argmax(np.abs(shifts)))
    tmap = window_error(r, t, thresholds.tile_size, thresholds.eps_rel)
    wy, wx = np.unravel_index(int(np.argmax(tmap)), tmap.shape)
    fmap, fmean = flip_error(r, t)

    th, failures = thresholds, []
    if nonfinite:
        ys, xs = np.nonzero(bad)
        failures.append(f"{nonfinite} test pixel(s) are NaN or infinite (first at y={ys[0]}, x={xs[0]})")
    if abs(shifts[worst]) > th.mean_limit:
        guard = f" = {th.mean_rel:.2%} rule - {th.mean_guard:.2%} noise guard" if th.mean_guard else ""
        failures.append(f"global mean of channel {'RGB'[worst]} shifted by {shifts[worst]:+.3%} "
                        f"(limit +-{th.mean_limit:.2%}{guard}); per channel R {shifts[0]:+.3%}, "
                        f"G {shifts[1]:+.3%}, B {shifts[2]:+.3%}")
    s = min(th.tile_size, *r.shape[:2])
    if tmap[wy, wx] > th.tile:
        n_bad = int((tmap > th.tile).sum())
        failures.append(f"{s}x{s} window at (y={wy}, x={wx}) differs by {tmap[wy, wx]:.1%} in mean luminance "
                        f"(limit {th.tile:.1%}); {n_bad} window position(s) over the limit")
    if fmean > th.flip:
        failures.append(f"mean FLIP error {fmean:.5f} exceeds {th.flip:.5f}")
    return CompareResult(passed=not failures, mean_shift=float(shifts[worst]),
                         mean_shift_rgb=tuple(float(v) for v in shifts), tile_max=float(tmap[wy, wx]),
                         tile_where=(int(wy), int(wx)), flip_mean=fmean, failures=failures, thresholds=th,
                         tile_map=tmap, flip_map=fmap, nonfinite=nonfinite)


def calibrate(ref, renders: Sequence, tile_margin: float = TILE_MARGIN, flip_margin: float = FLIP_MARGIN,
              mean_rel: float = 0.01, mean_guard_sigmas: float = MEAN_GUARD_SIGMAS, tile_size: int = 8,
              eps_rel: float = 0.01) -> Thresholds:
    """Set the thresholds of :func:`compare` from the noise of renders that should pass.

    Parameters
    ----------
    ref : array_like
        The reference, linear RGB ``(H, W, 3)`` (as stored: pass the
        half-float rounded golden so calibration sees what checks will see).
    renders : sequence of array_like
        Renders of the same scene at the test spp with distinct seeds (none
        equal to the reference's); 4 or more recommended.
    tile_margin : float, optional
        Multiplier of the worst window error measured (default 2.0).
    flip_margin : float, optional
        Multiplier of the worst FLIP mean measured (default 1.25).
    mean_rel : float, optional
        The global mean shift that must fail (default 1 %); only its noise
        guard ``mean_guard`` is calibrated.
    mean_guard_sigmas : float, optional
        Noise guard of the mean check in standard deviations (default 4).
    tile_size, eps_rel
        See :class:`Thresholds`.

    Returns
    -------
    Thresholds
        With ``calibration`` holding the per-render measurements.

    Warns
    -----
    CalibrationWarning
        When the guard of the mean check reaches its cap ``mean_rel / 2``
        (noise sigma of the image mean > 0.125 %, a 3 sigma noise of about
        0.4 %: the 1 % rule then fails good renders or passes 1 % shifts
        now and then), when the tile threshold exceeds :data:`TILE_WARNING`
        (a 25 % change of an 8 x 8 patch could pass), or with fewer than 3
        renders.

    Notes
    -----
    Why these margins (measured on a 48 x 48 diffuse sphere-and-floor scene,
    200 seeds at 16, 32 and 64 spp against an 8192 spp reference; thresholds
    from each group of 4 seeds, checked on the other 196 seeds):

    * The worst window error has a heavy upper tail (std/mean 0.16-0.19,
      largest/median 1.6-1.9): it is a maximum over a few thousand windows
      whose worst ones sit in the noisiest (shadowed) region. The worst of 4
      seeds x 1.5 failed 0.26-0.59 % of good renders, x 1.75 0.01-0.08 %, and
      x **2.0** one of 29,400 (16 spp; none at 32 and 64 spp). At 2.0 the
      threshold was 0.067-0.135 (16 spp) and 0.032-0.058 (64 spp), well
      below the 0.25 of a 25 % patch change; the tile warning (threshold
      > 0.2) says when that stops being true.
    * The FLIP mean averages all pixels and varies little (std/mean 0.035):
      x **1.25** failed none of 9,800. It guards against broad perceptual
      changes rather than small ones.
    * The image mean's noise sigma was 0.118 / 0.083 / 0.060 % (16 / 32 /
      64 spp), so the guard is 0.47 / 0.33 / 0.24 %. With 4 sigma the
      probability to fail a good render and to pass a 1 % shift are both
      at most ~3e-5 (none of 9,800 either way); a guard of 1.5-3 x the worst
      shift of 4 seeds instead passed 0.1-3 % of the 1 % shifts, because 4
      seeds estimate the spread poorly.
    """
    r = _image(ref, "reference")
    if len(renders) == 0:
        raise ValueError("calibrate needs at least one render")
    shifts, tiles, flips, variances = [], [], [], []
    for img in renders:
        t = _image(img, "render")
        if t.shape != r.shape:
            raise ValueError(f"render shape {t.shape} differs from the reference {r.shape}")
        if not np.all(np.isfinite(t)):
            raise ValueError("a calibration render has NaN or infinite pixels")
        shifts.append(float(np.max(np.abs(mean_shift(r, t)))))
        variances.append(mean_noise(r, t) ** 2)
        tiles.append(float(np.max(window_error(r, t, tile_size, eps_rel))))
        flips.append(flip_error(r, t)[1])
    sigma = float(np.max(np.sqrt(np.mean(variances, axis=0))))
    # The floors matter only for (nearly) noise-free renderers: they keep the
    # half-float rounding of the stored reference (<= 0.05 %) from failing.
    th = Thresholds(tile=max(max(tiles) * tile_margin, 2e-3), flip=max(max(flips) * flip_margin, 1e-4),
                    mean_rel=mean_rel, mean_guard=min(sigma * mean_guard_sigmas, 0.5 * mean_rel),
                    tile_size=tile_size, eps_rel=eps_rel)
    th.calibration = {"renders": len(renders), "tile_margin": tile_margin, "flip_margin": flip_margin,
                      "mean_guard_sigmas": mean_guard_sigmas, "mean_sigma": sigma,
                      "mean_shift_abs": shifts, "tile_max": tiles, "flip_mean": flips,
                      "mean_shift_noise": max(shifts), "tile_noise": max(tiles), "flip_noise": max(flips)}
    notes = []
    if sigma * mean_guard_sigmas > 0.5 * mean_rel:
        notes.append(f"the image mean's noise at this spp is {sigma:.3%} (3 sigma {3 * sigma:.2%}): the "
                     f"{mean_rel:.0%} mean rule is unreliable (good renders may fail, {mean_rel:.0%} shifts "
                     f"may pass); raise the test spp or the resolution")
    if th.tile > TILE_WARNING:
        notes.append(f"the window threshold is {th.tile:.1%} (> {TILE_WARNING:.0%}): a 25% change of an "
                     f"{tile_size}x{tile_size} patch may pass; raise the test spp")
    if len(renders) < 3:
        notes.append(f"only {len(renders)} calibration render(s): the thresholds may be too tight")
    th.calibration["warnings"] = notes
    for note in notes:
        warnings.warn(note, CalibrationWarning, stacklevel=2)
    if not math.isfinite(th.tile) or not math.isfinite(th.flip):
        raise ValueError(f"calibration produced non-finite thresholds: {th}")
    return th
