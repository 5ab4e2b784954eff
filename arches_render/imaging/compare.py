"""Compare two images by what a person sees: image mean, local windows, FLIP.

This is the comparison of two finished images without their per-pixel
variances (:func:`arches_render.api.compare`, "do these two renders look the
same?"), with fixed limits. Golden tests, which have the variances, use the
two-sample statistics of :mod:`arches_render.imaging.welch` instead.

Three checks, each aimed at one kind of regression:

1. **Global mean shift** (``mean_rel``, 1 %): the relative difference of the
   image mean, computed per RGB channel; the worst channel is reported. Per
   channel rather than on luminance so that a tint (red up, blue down) that
   leaves the luminance unchanged still fails. ``mean_guard`` lowers the limit
   to ``mean_rel - mean_guard`` so that a true shift of ``mean_rel`` plus noise
   still fails.
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
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from .preview import encode_srgb

__all__ = ["LUMINANCE_WEIGHTS", "Thresholds", "CompareResult", "luminance", "window_error", "mean_shift",
           "flip_error", "compare"]

LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)
"""Rec.709 luminance weights of linear R, G, B."""

@dataclass(kw_only=True)
class Thresholds:
    """Pass limits of :func:`compare`.

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
        so that a true shift of ``mean_rel`` fails despite noise (default 0).
    tile_size : int, optional
        Window side in pixels (default 8).
    eps_rel : float, optional
        Window error denominator offset, as a fraction of the reference's mean
        luminance (default 0.01).
    """

    tile: float
    flip: float
    mean_rel: float = 0.01
    mean_guard: float = 0.0
    tile_size: int = 8
    eps_rel: float = 0.01

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
        Limits.

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
