"""The DEM's own relief past its tile, blurred as distance asks (the far field's heights).

:class:`MirroredRelief` extends a DEM by reflection about its border samples and
blurs it by a Gaussian of any width from a pyramid; :func:`gaussian_blur` and
:func:`bilinear` are the two scipy.ndimage filters it needs, written in numpy so that
a render process does not import scipy.ndimage (0.17 s) for its far field.
Used by :mod:`.continued_relief`, whose heights are the mirror's near the tile.
"""

from __future__ import annotations

import math

import numpy as np


class MirroredRelief:
    """Heights of a DEM mirrored across its borders and blurred by a Gaussian of any width.

    The DEM is extended by reflection about its border samples (period ``2 (n - 1)``
    samples per axis: the extension is continuous and repeats the tile's character,
    not a flat plane). A pyramid of the extension, each level blurred by a Gaussian of
    one of its samples and halved (:func:`gaussian_blur`, mirrored: the same
    reflection), holds blurs of about ``2^j`` samples; a query between two levels
    interpolates linearly in ``sigma`` (:func:`bilinear`), and beyond the coarsest
    level the heights fade to the DEM's mean over one octave.

    Parameters
    ----------
    H : numpy.ndarray
        ``(ny, nx)`` heights.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` of the samples' corners (the tile).
    """

    def __init__(self, H, extent):
        H = np.asarray(H, np.float64)
        self.shape = H.shape
        x0, y0, x1, y1 = (float(v) for v in extent)
        ny, nx = H.shape
        self.origin = (x0, y0)
        self.spacing = ((x1 - x0) / max(nx - 1, 1), (y1 - y0) / max(ny - 1, 1))
        # Blur of each level in level-0 samples (a blur of one sample of level j is 2^j of
        # level 0); the levels themselves are built when first asked for (an unblurred
        # query, as the overview camera's, needs none).
        self.levels, self.sigmas = [H], [0.0]
        size = min(H.shape)
        while size > 2:
            size = (size + 1) // 2
            self.sigmas.append(math.sqrt(self.sigmas[-1] ** 2 + 4.0 ** (len(self.sigmas) - 1)))
        self.mean = float(H.mean())
        #: The DEM's standard deviation of height (metres).
        self.relief = float(H.std())

    def blur_keeping(self, share: float) -> float:
        """The widest blur of the pyramid (metres) whose heights keep at least ``share`` of
        the DEM's standard deviation: the scale of its main landforms (ridges, valleys,
        plateaus), which a wider blur flattens. 0 for a flat DEM.

        Parameters
        ----------
        share : float
            In ``(0, 1]``.

        Returns
        -------
        float
        """
        keep = 0.0
        for j in range(1, len(self.sigmas)):
            if not float(np.std(self._level(j))) >= share * self.relief > 0.0:
                break
            keep = self.sigmas[j]
        return keep * min(self.spacing)

    def _level(self, j):
        """Level ``j`` of the pyramid (built up to it on first use)."""
        while len(self.levels) <= j:
            self.levels.append(gaussian_blur(self.levels[-1])[::2, ::2])
        return self.levels[j]

    def _mirror(self, x, y):
        """Level-0 sample coordinates ``(u, v)`` of world points, reflected into the tile."""
        out = []
        for c, o, d, n in ((x, self.origin[0], self.spacing[0], self.shape[1]),
                           (y, self.origin[1], self.spacing[1], self.shape[0])):
            period = 2.0 * max(n - 1, 1)
            u = np.mod((np.asarray(c, np.float64) - o) / d, period)
            out.append(np.where(u > n - 1, period - u, u))
        return out

    def heights(self, x, y, sigma):
        """Heights at world points ``(x, y)`` (arrays) blurred by ``sigma`` metres (a float).

        Returns
        -------
        numpy.ndarray
        """
        u, v = self._mirror(x, y)
        s = max(float(sigma), 0.0) / min(self.spacing)  # in level-0 samples

        def level(j):
            scale = 0.5 ** j
            return bilinear(self._level(j), v * scale, u * scale)

        top = len(self.sigmas) - 1
        if s >= self.sigmas[top]:
            # Past the coarsest level: to the mean over one octave of sigma. A DEM two samples
            # wide has no level past its own: to the mean over one sample (it returned the
            # mean even unblurred).
            w = min(math.log2(s / self.sigmas[top]) if self.sigmas[top] > 0 else s, 1.0)
            return (1.0 - w) * level(top) + w * self.mean
        j = int(np.searchsorted(self.sigmas, s, side="right")) - 1
        w = (s - self.sigmas[j]) / (self.sigmas[j + 1] - self.sigmas[j])
        return level(j) if w <= 0.0 else (1.0 - w) * level(j) + w * level(j + 1)


def gaussian_blur(H: np.ndarray, radius: int = 4) -> np.ndarray:
    """``H`` blurred by a Gaussian of one sample, truncated at ``radius`` samples, each axis
    mirrored about its end samples (``d c b | a b c d | c b a``).

    What ``scipy.ndimage.gaussian_filter(H, 1.0, mode="mirror")`` returns, bit for bit
    (the same normalized taps, summed in the same order: the centre, then the pairs
    from the outermost in), in numpy: importing ``scipy.ndimage`` took 0.17 s of every
    render process with a far field.
    """
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    taps = np.exp(-0.5 * x ** 2)
    taps = (taps / taps.sum())[radius:]  # taps[k]: weight at distance k
    out = np.asarray(H, np.float64)
    for axis in range(out.ndim):
        pad = [(0, 0)] * out.ndim
        pad[axis] = (radius, radius)
        padded = np.pad(out, pad, mode="reflect")  # numpy's "reflect" is scipy's "mirror"
        n = out.shape[axis]

        def shifted(k):
            index = [slice(None)] * out.ndim
            index[axis] = slice(radius + k, radius + k + n)
            return padded[tuple(index)]

        acc = shifted(0) * taps[0]
        for k in range(radius, 0, -1):
            acc = acc + (shifted(-k) + shifted(k)) * taps[k]
        out = acc
    return out


def bilinear(A: np.ndarray, v, u) -> np.ndarray:
    """``A`` interpolated bilinearly at fractional rows ``v`` and columns ``u``, samples
    beyond the edges repeating the edge's: ``scipy.ndimage.map_coordinates(A, [v, u],
    order=1, mode="nearest")`` bit for bit (the weights of the unclamped coordinates, the
    four corners summed in its order), in numpy (see :func:`gaussian_blur` for why)."""
    v, u = np.asarray(v, np.float64), np.asarray(u, np.float64)
    ny, nx = A.shape
    j0, i0 = np.floor(v).astype(np.int64), np.floor(u).astype(np.int64)
    fy, fx = v - j0, u - i0
    rows = (np.clip(j0, 0, ny - 1), np.clip(j0 + 1, 0, ny - 1))
    cols = (np.clip(i0, 0, nx - 1), np.clip(i0 + 1, 0, nx - 1))
    wy, wx = (1.0 - fy, fy), (1.0 - fx, fx)
    out = 0.0
    for a in range(2):
        for b in range(2):
            out = out + A[rows[a], cols[b]] * wy[a] * wx[b]
    return np.asarray(out, np.float64)
