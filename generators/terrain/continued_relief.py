"""The DEM's relief continued past its tile without copies of its landforms (the far field's heights).

Mirroring a DEM across its borders (:class:`.MirroredRelief`) continues it without a
seam, but a mirror is periodic: every landform of the tile comes back every two
tiles, out to the horizon. Behind every shot of a 0.86 km volcanic tile its crater
stood again every tile for 26 km; a caldera got a twin cone beside it.
:class:`ContinuedRelief` keeps
the mirror near the tile, where it carries valleys and ridges across the border, and
farther out replaces it by a continuation that has the tile's relief and character
but none of its landforms:

Low part
    The mirror blurred by ``sigma_c =`` :data:`LOW_BLUR` ``T`` (``T`` the tile's
    shorter side): the tile-scale trends continue as mirrored (a plateau's edge runs
    on; a coast's sea and land alternate in bands a tile wide, as in the mirror), but
    a Gaussian of a quarter tile takes out any landform under about half a tile (a
    400 m crater keeps 0.4 % of its depth on an 0.86 km tile).
Detail
    Asymptotic discrete spot noise (Galerne et al. 2011): white noise convolved with
    the tile's own detail (its mirrored period, less the low part), over the square
    root of the spot's size. A stationary Gaussian field with the detail's power
    spectrum, i.e. the sizes and orientations of its landforms, and random phases: no
    landform of the tile recurs in it.
Character
    Low part plus detail, remapped to the tile's own (unblurred) height distribution
    (histogram matching, Heeger & Bergen 1995): plateaus keep flat tops at the tile's
    heights, plains stay flat.

Coasts
    With a sea level, the tile's border decides what lies past it: where the border
    (the tile's share of sea within :data:`COAST_BLUR` ``T`` of its nearest border
    point) is sea, the continuation is folded below the sea; where it is land, above
    it (``z -/+ sqrt((h - z)^2 + m^2)``, ``z`` the sea level, ``m`` :data:`COAST_MARGIN`
    of the DEM's height deviation: heights far from the sea stay, and what the mirror put on
    the wrong side of it comes back as low hills or as sea floor). Where the coast
    crosses the border the two fade into each other over that share's 0.35-0.65, and
    the ground there flattens towards the sea level: the coastline runs on from where
    it leaves the tile, along a low strip. (The mirror put a coast's land again a
    tile out to sea, a far shore across an ocean, and a sea a tile inland.)

The continuation is a grid of spacing about ``T /`` :data:`GRID_PER_TILE` reaching
:data:`GRID_TILES` tiles past the tile on every side (mirrored beyond, where the far
field is blurred by at least ``keep`` and fading), seeded by the DEM's own bytes: the
same DEM gives the same far field in every process. The mirror holds out to
``BAND[0] T`` from the border (Chebyshev distance); the continuation takes over
smoothly by ``BAND[1] T``. A landform at the tile's middle, ``T / 2`` from its
border, would mirror to ``T / 2`` outside, where only the continuation remains.

References
----------
Galerne, B., Gousseau, Y., Morel, J.-M. (2011). Random phase textures: theory and
synthesis. IEEE Transactions on Image Processing 20(1), 257-267.
Heeger, D. J., Bergen, J. R. (1995). Pyramid-based texture analysis/synthesis.
SIGGRAPH '95, 229-238.
"""

from __future__ import annotations

import math
import zlib

import numpy as np

from .mirrored_relief import MirroredRelief

__all__ = ["ContinuedRelief", "BAND", "LOW_BLUR", "GRID_PER_TILE", "COAST_BLUR", "COAST_MARGIN"]

#: Where the continuation takes over from the mirror, in tiles (the shorter side) from
#: the border: the mirror alone within ``BAND[0]``, the continuation alone past ``BAND[1]``.
BAND = (0.1, 0.35)

#: Blur of the continuation's low part, in tiles (module docstring).
LOW_BLUR = 0.25

#: Blur of a coast's sea share, in tiles (module docstring, "Coasts"): the border's sea
#: and land are read over about this much of it.
COAST_BLUR = 0.125

#: How far below (above) the sea a continuation held under (over) it stays, as a share
#: of the DEM's height deviation: a shallow sea floor, a low coastal plain.
COAST_MARGIN = 0.05

#: Continuation grid samples a tile (shorter side), at most. The far field is blurred
#: by at least ``BAND[0] T / 8`` where the continuation starts, so 32 samples a tile
#: hold all the detail it shows there.
GRID_PER_TILE = 32

#: How many tiles (shorter side) the continuation's grid reaches past the tile.
GRID_TILES = 6

#: Most samples a side of the continuation's grid.
GRID_MAX = 1024


class ContinuedRelief:
    """Heights of a DEM continued past its tile (module docstring), blurred by a Gaussian
    of any width: ``heights(x, y, sigma)`` as :class:`.MirroredRelief`'s, which it is
    inside the tile and within ``BAND[0]`` tiles of its border.

    Parameters
    ----------
    H : numpy.ndarray
        ``(ny, nx)`` heights.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` of the samples' corners (the tile).
    sea_level : float, optional
        The sea's level: past the tile, sea stays sea and land stays land (module
        docstring, "Coasts"). None: no sea.
    """

    def __init__(self, H, extent, sea_level=None):
        H = np.asarray(H, np.float64)
        self.mirror = MirroredRelief(H, extent)
        #: The DEM's mean height and standard deviation (metres).
        self.mean, self.relief = self.mirror.mean, self.mirror.relief
        x0, y0, x1, y1 = (float(v) for v in extent)
        self.box = (x0, y0, x1, y1)
        tile = min(x1 - x0, y1 - y0)
        self.band = (BAND[0] * tile, BAND[1] * tile)
        #: The continuation (a MirroredRelief over its grid); None for a flat DEM.
        self.continued = None
        if self.relief > 0.0 and tile > 0.0 and min(H.shape) >= 2:
            seed = zlib.crc32(np.ascontiguousarray(H).tobytes())
            self.continued = _continuation(self.mirror, self.box, tile, np.random.default_rng(seed), sea_level)

    def blur_keeping(self, share: float) -> float:
        """:meth:`.MirroredRelief.blur_keeping` of the DEM."""
        return self.mirror.blur_keeping(share)

    def weight(self, x, y):
        """The continuation's share of the heights at world points ``(x, y)``: 0 inside
        the tile and within ``BAND[0]`` tiles of it, 1 past ``BAND[1]`` tiles, a
        smoothstep of the Chebyshev distance from the tile between.

        Returns
        -------
        numpy.ndarray
        """
        x0, y0, x1, y1 = self.box
        x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
        d = np.maximum(np.maximum(x0 - x, x - x1), np.maximum(y0 - y, y - y1))
        u = np.clip((d - self.band[0]) / (self.band[1] - self.band[0]), 0.0, 1.0)
        return u * u * (3.0 - 2.0 * u)

    def heights(self, x, y, sigma):
        """Heights at world points ``(x, y)`` (arrays) blurred by ``sigma`` metres (a float).

        Returns
        -------
        numpy.ndarray
        """
        x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
        h = np.array(self.mirror.heights(x, y, sigma), np.float64)
        if self.continued is None:
            return h
        w = np.broadcast_to(self.weight(x, y), h.shape)
        out = w > 0.0
        if np.any(out):
            far = self.continued.heights(np.broadcast_to(x, h.shape)[out], np.broadcast_to(y, h.shape)[out], sigma)
            h[out] += w[out] * (far - h[out])
        return h


def _continuation(mirror, box, tile, rng, sea_level=None):
    """The continuation's grid (module docstring) as a :class:`.MirroredRelief` centred
    on the tile (held to the border's sea and land with ``sea_level``)."""
    x0, y0, x1, y1 = box
    step = tile / GRID_PER_TILE
    counts = [min(GRID_MAX, int(math.ceil((side + 2.0 * GRID_TILES * tile) / step)) + 1)
              for side in (x1 - x0, y1 - y0)]
    centre = (0.5 * (x0 + x1), 0.5 * (y0 + y1))
    axes = [c + (np.arange(n) - 0.5 * (n - 1)) * step for c, n in zip(centre, counts)]
    X, Y = np.meshgrid(*axes)
    sigma_c = LOW_BLUR * tile
    low = mirror.heights(X.ravel(), Y.ravel(), sigma_c).reshape(X.shape)

    # The spot: one period of the mirror (two tiles a side) at the grid's spacing, less its low
    # part; along a long tile's long side a window of it, no longer than the grid.
    px, py = (np.arange(min(int(round(2.0 * (b - a) / step)), GRID_MAX)) * step + a for a, b in ((x0, x1), (y0, y1)))
    PX, PY = np.meshgrid(px, py)
    spot = (mirror.heights(PX.ravel(), PY.ravel(), step) - mirror.heights(PX.ravel(), PY.ravel(), sigma_c))
    spot = spot.reshape(PX.shape)
    spot -= spot.mean()
    shape = tuple(max(a, b) for a, b in zip(X.shape, spot.shape))
    noise = rng.standard_normal(shape)
    detail = np.fft.irfft2(np.fft.rfft2(noise) * np.fft.rfft2(spot, shape), shape)[:X.shape[0], :X.shape[1]]
    detail /= math.sqrt(spot.size)

    # The tile's own heights, unblurred, give the distribution to match: the grid stands in
    # for the DEM, and the far field blurs it as it blurs the mirror. (Matched to the tile
    # blurred by a grid step through the pyramid, a tile of ridges a third of it apart
    # lost a third of its deviation before the rings blurred it again.)
    target = np.sort(np.asarray(mirror.levels[0], np.float64).ravel())
    grid = (low + detail).ravel()
    ranks = np.empty(grid.size, np.float64)
    ranks[np.argsort(grid)] = (np.arange(grid.size) + 0.5) / grid.size
    matched = np.interp(ranks, (np.arange(target.size) + 0.5) / target.size, target).reshape(X.shape)
    if sea_level is not None:
        matched = _held_to_the_coast(matched, X, Y, mirror, box, tile, float(sea_level))
    extent = (axes[0][0], axes[1][0], axes[0][-1], axes[1][-1])
    return MirroredRelief(matched, extent)


def _held_to_the_coast(h, X, Y, mirror, box, tile, sea_level):
    """Heights ``h`` at grid points ``(X, Y)`` held below the sea past a sea border and
    above it past a land border (module docstring, "Coasts")."""
    from scipy.ndimage import gaussian_filter, map_coordinates
    H = np.asarray(mirror.levels[0], np.float64)
    x0, y0, x1, y1 = box
    ny, nx = H.shape
    dx, dy = (x1 - x0) / max(nx - 1, 1), (y1 - y0) / max(ny - 1, 1)
    sea = gaussian_filter((H < sea_level).astype(np.float64), (COAST_BLUR * tile / dy, COAST_BLUR * tile / dx),
                          mode="nearest")
    # The share at each point's nearest border point (the tile's own, clamped).
    j = np.clip((Y - y0) / dy, 0.0, ny - 1.0)
    i = np.clip((X - x0) / dx, 0.0, nx - 1.0)
    share = map_coordinates(sea, [j.ravel(), i.ravel()], order=1, mode="nearest").reshape(h.shape)
    u = np.clip((share - 0.35) / 0.3, 0.0, 1.0)
    wet = u * u * (3.0 - 2.0 * u)
    # Folded about the sea level, rounded over the margin (a hyperbola): land that the
    # mirror put under the sea becomes low hills, not a plain at one height, and hills
    # it put in the sea become its floor; far from the sea level nothing moves.
    margin = COAST_MARGIN * mirror.relief
    fold = np.sqrt((h - sea_level) ** 2 + margin ** 2)
    return sea_level + (1.0 - 2.0 * wet) * fold
