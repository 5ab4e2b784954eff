"""Per-pixel sample statistics of a render: what the two-sample tests of
:mod:`arches_render.imaging.welch` compare.

A render of ``n`` samples per pixel returns, besides each pixel's mean, the mean of
the squared samples (layer ``moment2``), hence the per-sample variance ``s^2`` and
the variance of the mean ``s^2 / n``; coverage and depth carry their own moments.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .compare import LUMINANCE_WEIGHTS

__all__ = ["PixelMoments"]


@dataclass
class PixelMoments:
    """Per-pixel sample statistics of a render of ``n`` samples per pixel.

    Attributes
    ----------
    n : int
        Samples per pixel.
    mean : numpy.ndarray
        Beauty, linear RGB ``(H, W, 3)``: the sample mean.
    m2 : numpy.ndarray
        ``(H, W, 4)``: mean of the squared samples of R, G, B and luminance Y.
    coverage : numpy.ndarray
        ``(H, W)``: fraction of the samples whose camera ray hit a surface.
    depth : numpy.ndarray
        ``(H, W)``: mean depth (misses count 0).
    depth_m2 : numpy.ndarray
        ``(H, W)``: mean squared depth.
    """

    n: int
    mean: np.ndarray = field(repr=False)
    m2: np.ndarray = field(repr=False)
    coverage: np.ndarray = field(repr=False)
    depth: np.ndarray = field(repr=False)
    depth_m2: np.ndarray = field(repr=False)

    def __post_init__(self):
        self.mean = np.asarray(self.mean, np.float64)
        h, w = self.mean.shape[:2]
        want = {"mean": (h, w, 3), "m2": (h, w, 4), "coverage": (h, w), "depth": (h, w), "depth_m2": (h, w)}
        for name, shape in want.items():
            value = np.asarray(getattr(self, name), np.float64)
            if value.shape != shape:
                raise ValueError(f"PixelMoments.{name} has shape {value.shape}, expected {shape}")
            setattr(self, name, value)
        if int(self.n) < 2:
            raise ValueError(f"PixelMoments needs at least 2 samples per pixel for a variance, got {self.n}")
        self.n = int(self.n)

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self.mean.shape[:2]

    @property
    def mean4(self) -> np.ndarray:
        """``(H, W, 4)``: the mean of R, G, B and luminance Y."""
        y = self.mean @ np.asarray(LUMINANCE_WEIGHTS)
        return np.concatenate([self.mean, y[..., None]], axis=-1)

    @classmethod
    def from_sample_variance(cls, n: int, mean, variance, coverage, depth, depth_variance) -> "PixelMoments":
        """Moments from means and unbiased sample variances (as a golden stores them).

        Parameters
        ----------
        n : int
            Samples per pixel.
        mean : array_like
            ``(H, W, 3)`` beauty.
        variance : array_like
            ``(H, W, 4)`` sample variance ``s^2`` of R, G, B, Y.
        coverage, depth, depth_variance : array_like
            ``(H, W)`` each.
        """
        mean = np.asarray(mean, np.float64)
        y = mean @ np.asarray(LUMINANCE_WEIGHTS)
        mean4 = np.concatenate([mean, y[..., None]], axis=-1)
        k = (n - 1) / n
        depth = np.asarray(depth, np.float64)
        return cls(n=n, mean=mean, m2=np.asarray(variance, np.float64) * k + mean4 ** 2, coverage=coverage,
                   depth=depth, depth_m2=np.asarray(depth_variance, np.float64) * k + depth ** 2)

    @classmethod
    def from_batches(cls, images, spp_each: int) -> "PixelMoments":
        """Moments from independent renders of equal spp (a renderer that returns no
        second moments, e.g. Mitsuba's stock ``path``): the spread of the batch means
        times ``spp_each`` estimates the per-sample variance (``len(images) - 1``
        degrees of freedom). Coverage and depth are unknown: compare with
        ``geometry=False``.

        Parameters
        ----------
        images : sequence of array_like
            ``(H, W, 3)`` renders with distinct seeds, ``spp_each`` samples each.
        spp_each : int
        """
        rgb = np.stack([np.asarray(i, np.float64) for i in images])
        if len(rgb) < 2:
            raise ValueError("from_batches needs at least two renders")
        y = rgb @ np.asarray(LUMINANCE_WEIGHTS)
        x4 = np.concatenate([rgb, y[..., None]], axis=-1)
        n = len(rgb) * int(spp_each)
        var = x4.var(axis=0, ddof=1) * spp_each
        h, w = rgb.shape[1:3]
        zeros = np.zeros((h, w))
        return cls.from_sample_variance(n, rgb.mean(axis=0), var, np.ones((h, w)), zeros, zeros)

    def sample_variance(self) -> np.ndarray:
        """``(H, W, 4)``: unbiased per-sample variance ``s^2`` of R, G, B, Y."""
        m = self.mean4
        return np.maximum(self.m2 - m * m, 0.0) * (self.n / (self.n - 1))

    def depth_sample_variance(self) -> np.ndarray:
        """``(H, W)``: unbiased per-sample variance of the depth."""
        return np.maximum(self.depth_m2 - self.depth ** 2, 0.0) * (self.n / (self.n - 1))

    def mean_variance(self) -> np.ndarray:
        """``(H, W, 4)``: variance of the pixel means of R, G, B, Y, ``s^2 / n``."""
        return self.sample_variance() / self.n

    def depth_mean_variance(self) -> np.ndarray:
        """``(H, W)``: variance of the mean depth."""
        return self.depth_sample_variance() / self.n

    @property
    def hits(self) -> np.ndarray:
        """``(H, W)``: the number of samples whose camera ray hit a surface."""
        return np.rint(self.coverage * self.n)

    def brightened(self, factor: float, where: tuple[slice, slice] | None = None) -> "PixelMoments":
        """A copy with the beauty scaled by ``factor`` (everywhere, or in the window ``where``):
        what a render that is that much brighter there would have returned."""
        mean, m2 = self.mean.copy(), self.m2.copy()
        sl = (slice(None), slice(None)) if where is None else where
        mean[sl] *= factor
        m2[sl] *= factor * factor
        return replace(self, mean=mean, m2=m2)
