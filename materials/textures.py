"""Layer textures of the ``triplanar`` BSDF: loading, and tiling that does not repeat.

A triplanar layer repeats its texture every ``scale`` metres. Across a landscape
a plain repeat (``tiling = "repeat"``) shows as a grid of identical patches, from
a few metres to the horizon. The default ``tiling = "histogram"`` hides it with
the histogram-preserving blending of randomly offset tiles of Heitz and Neyret
(2018):

1. **Gaussianisation** (pre-computed, numpy): each channel ``c`` of the texture
   ``T`` is mapped through its own rank transform to a standard normal texture
   ``G = Phi^-1(F_T(T))`` (average ranks for tied 8-bit values, so equal texels
   stay equal). ``F_T^-1`` is kept as a look-up table.
2. **Triangle grid** (per shading point): the texture coordinates ``uv`` (in
   texture periods) are split into equilateral triangles of edge
   :data:`TRIANGLE_EDGE` periods. With the lattice basis ``e1 = (1, 0)`` and
   ``e2 = (1/2, sqrt(3)/2)`` (times the edge), the skewed coordinates are
   ``t = uv_y / (a sqrt(3)/2)``, ``s = uv_x / a - t / 2``; the integer part picks
   the cell, and ``f_s + f_t < 1`` the lower triangle with vertices
   ``(0,0), (1,0), (0,1)`` and barycentric weights ``(1 - f_s - f_t, f_s, f_t)``,
   else the upper one ``(1,1), (1,0), (0,1)`` with ``(f_s + f_t - 1, 1 - f_t, 1 - f_s)``.
   Each vertex ``v`` hashes to a random offset ``o_v`` in ``[0, 1)^2``.
3. **Variance-preserving blend**: ``g = sum_v w_v G(uv + o_v) / sqrt(sum_v w_v^2)``,
   again standard normal wherever the three tiles are uncorrelated, so the blend
   keeps the texture's contrast instead of washing it out as a linear blend does.
4. **Back to the texture's histogram**: ``T = F_T^-1(Phi(g))``.

Filtering. Heitz and Neyret pre-filter the Gaussian texture with MIP maps and the
look-up table per level; so do we. The pixel footprint (``footprint``, metres, see
:mod:`arches_render.materials.detail`: the camera's pixel at the first vertex, the
integrator's ray cone after a bounce) selects a level ``l`` of the Gaussian
texture's pyramid ``G_l`` (:mod:`arches_render.materials.mipmap`: box filter, one
level per shading point chosen stochastically between the two around
``log2(footprint / texel)``), whose standard deviation is ``s_l`` (relative to
level 0). The blend of step 3 then has standard deviation ``s_l``, so step 4 reads
``T = F_l(Phi(g / s_l))`` from the table of that level,
``F_l(u) = E_z[F_T^-1(Phi(s_l Phi^-1(u) + sqrt(1 - s_l^2) z))]`` with ``z ~ N(0, 1)``
(Gauss-Hermite quadrature): the expected texel given the filtered Gaussian value,
the part of ``G`` finer than the footprint (variance ``1 - s_l^2``) integrated out.
At level 0 this is ``F_T^-1``; as the footprint covers the whole texture (``s_l ->
0``) it tends to the texture's mean, which is what an area-filtered lookup returns,
and the last level is that mean without a lookup. A pixel thus averages to the right
value at every distance and the lookups do not alias: the texture blurs with the
footprint instead of sparkling.

``tiling = "bands"`` offsets the tiles along the texture's ``u`` only, for banded
textures (``strata.png``) whose rows must stay aligned so that bands stay
continuous across tiles. Colour textures are Gaussianised per channel (Heitz and
Neyret decorrelate the channels first; our bundled textures are grey, where the
two agree).

References
----------
Heitz, E., Neyret, F. (2018). High-performance by-example noise using a
histogram-preserving blending operator. Proceedings of the ACM on Computer
Graphics and Interactive Techniques 1(2), article 31 (HPG 2018).
Burley, B. (2019). On histogram-preserving blending for randomized texture
tiling. Journal of Computer Graphics Techniques 8(4) (variance-preserving blend
and its look-up tables, the same operator explained step by step).
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from statistics import NormalDist

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render import cache
from arches_render.npzfile import write_npz

from .mipmap import MipTexture, mip_levels

__all__ = ["TEXTURE_DIR", "TILINGS", "TRIANGLE_EDGE", "texture_path", "load_texture", "RepeatTexture",
           "HistogramTexture", "average_ranks", "gaussianize", "filter_tables", "histogram_tables", "triangle_grid"]

TEXTURE_DIR = Path(__file__).resolve().parent / "textures"
#: Tiling modes of a layer (``layer{i}_tiling``).
TILINGS = ("histogram", "bands", "repeat")
#: Edge of the triangles of the tiling grid, in texture periods (Heitz and Neyret's
#: grid, ``uv * 2 sqrt(3)`` skewed, has edges of about 0.33 periods; larger patches
#: keep more of the texture's structure, smaller ones blend more often).
TRIANGLE_EDGE = 0.4
#: Entries of the inverse-CDF tables along ``u``, and Gauss-Hermite nodes of the
#: filtered tables.
LUT_SIZE, HERMITE_NODES = 256, 24

_SQRT3_2 = math.sqrt(3.0) / 2.0
_CACHE: dict = {}


def texture_path(name: str) -> Path:
    """Resolve a layer texture name.

    Parameters
    ----------
    name : str
        File name inside :data:`TEXTURE_DIR` or an absolute path.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    ValueError
        When the file does not exist (the message lists the bundled textures).
    """
    path = Path(name)
    if not path.is_absolute():
        path = TEXTURE_DIR / name
    if not path.is_file():
        bundled = sorted(p.name for p in TEXTURE_DIR.glob("*.png"))
        raise ValueError(f"triplanar: texture '{name}' not found; bundled textures: "
                         f"{', '.join(bundled)} (or give an absolute path)")
    return path


def _read(path: Path, srgb: bool, normalize: bool) -> np.ndarray:
    """``(H, W, C)`` float32 texels, linear, rows flipped so that +v is up on cliffs."""
    bmp = mi.Bitmap(str(path))
    grey = bmp.pixel_format() in (mi.Bitmap.PixelFormat.Y, mi.Bitmap.PixelFormat.YA)
    if not srgb:
        # Data textures: take the stored numbers as they are.
        bmp.set_srgb_gamma(False)
    bmp = bmp.convert(mi.Bitmap.PixelFormat.Y if grey else mi.Bitmap.PixelFormat.RGB,
                      mi.Struct.Type.Float32, srgb_gamma=False)
    arr = np.array(bmp, dtype=np.float32).reshape(bmp.height(), bmp.width(), -1)
    # Image rows run downwards; flip so that +v (world +Z on the side
    # projections) shows the image upright on cliffs.
    arr = np.ascontiguousarray(arr[::-1])
    if normalize:
        lum = arr[..., 0] if grey else arr @ np.array([0.2126, 0.7152, 0.0722], np.float32)
        arr = arr / max(float(lum.mean()), 1e-6)
    return arr


def _texture2f(arr: np.ndarray, wrap) -> "mi.Texture2f":
    if arr.shape[2] == 3 and mi.variant().startswith("cuda"):
        # Hardware textures take 1, 2 or 4 channels.
        arr = np.concatenate([arr, np.ones_like(arr[..., :1])], axis=2)
    return mi.Texture2f(mi.TensorXf(np.ascontiguousarray(arr, np.float32)), use_accel=True,
                        filter_mode=dr.FilterMode.Linear, wrap_mode=wrap)


def _colour(v) -> "mi.Color3f":
    return mi.Color3f(v[0], v[1], v[2]) if len(v) >= 3 else mi.Color3f(v[0])


def average_ranks(v: np.ndarray) -> np.ndarray:
    """1-based ranks of ``v``, ties sharing the mean of their ranks (float64).

    What ``scipy.stats.rankdata(v, method="average")`` returns, in numpy: importing
    scipy.stats costs 0.9 s in every process that loads a scene.
    """
    ranks, inverse = distinct_ranks(v)
    return ranks[inverse]


def distinct_ranks(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The average ranks of the distinct values of ``v`` (float64, ascending) and, for
    each element of ``v`` (flattened), the index of its value among them."""
    _, inverse, counts = np.unique(v, return_inverse=True, return_counts=True)
    return (np.cumsum(counts) - 0.5 * (counts - 1)).astype(np.float64), inverse.reshape(-1)


def gaussianize(arr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rank transform of each channel to a standard normal, and its inverse table.

    Parameters
    ----------
    arr : numpy.ndarray
        ``(H, W, C)`` texels.

    Returns
    -------
    gauss : numpy.ndarray
        ``(H, W, C)`` float32, ``Phi^-1((rank - 1/2) / N)`` per channel (average
        ranks: tied texels map to one value).
    lut : numpy.ndarray
        ``(LUT_SIZE, C)`` float32: the texture's quantile function ``F_T^-1`` at
        ``u_j = (j + 1/2) / LUT_SIZE``.
    """
    h, w, c = arr.shape
    gauss = np.empty_like(arr, dtype=np.float32)
    u = (np.arange(LUT_SIZE) + 0.5) / LUT_SIZE
    lut = np.empty((LUT_SIZE, c), np.float32)
    for k in range(c):
        v = arr[..., k].ravel().astype(np.float64)
        # Per distinct texel value (a texture has few: its grey levels), then spread.
        ranks, inverse = distinct_ranks(v)
        gauss[..., k] = normal_quantile((ranks - 0.5) / v.size)[inverse].reshape(h, w)
        lut[:, k] = np.quantile(v, u)
    return gauss, lut


def normal_quantile(u: np.ndarray) -> np.ndarray:
    """``Phi^-1(u)``, the standard normal quantile, elementwise (float64).

    By the standard library (``statistics.NormalDist.inv_cdf``: Wichura's algorithm
    AS 241, accurate to about 1e-16) over the distinct values of ``u``, not by
    ``scipy.special.ndtri``, whose import (0.17 s) every process that loads a scene
    paid: a texture's ranks take at most as many values as it has grey levels.
    """
    values, inverse = np.unique(np.asarray(u, np.float64), return_inverse=True)
    quantiles = np.array([_NORMAL.inv_cdf(float(v)) for v in values])
    return quantiles[inverse].reshape(np.shape(u))


def normal_cdf(x: np.ndarray) -> np.ndarray:
    """``Phi(x) = erfc(-x / sqrt 2) / 2``, elementwise (float64), by the standard
    library's ``math.erfc`` (see :func:`normal_quantile` for why not scipy)."""
    return 0.5 * _ERFC(-np.asarray(x, np.float64) / math.sqrt(2.0)).astype(np.float64)


_NORMAL = NormalDist()
_ERFC = np.frompyfunc(math.erfc, 1, 1)


def filter_tables(gauss: np.ndarray, lut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse-CDF tables pre-filtered per MIP level (see the module docstring).

    Parameters
    ----------
    gauss : numpy.ndarray
        ``(H, W, C)`` Gaussianised texture (:func:`gaussianize`).
    lut : numpy.ndarray
        ``(LUT_SIZE, C)`` level-0 table.

    Returns
    -------
    tables : numpy.ndarray
        ``(levels, LUT_SIZE, C)`` float32, ``F_l`` per level ``l = 0 .. log2(min(H, W))``.
    sigma : numpy.ndarray
        ``(levels,)`` the relative standard deviation ``s_l`` of each level of the
        pyramid (:func:`~arches_render.materials.mipmap.mip_levels`).
    """
    c = gauss.shape[2]
    pyramid = mip_levels(gauss)
    sd0 = pyramid[0].std()
    sig = [min(float(g.std() / sd0), 1.0) for g in pyramid]
    sig[-1] = 0.0  # the whole texture in one footprint: its mean
    levels = len(sig)
    z, wz = np.polynomial.hermite_e.hermegauss(HERMITE_NODES)
    wz = wz / wz.sum()
    x = normal_quantile((np.arange(LUT_SIZE) + 0.5) / LUT_SIZE)
    u_lut = (np.arange(LUT_SIZE) + 0.5) / LUT_SIZE
    tables = np.empty((levels, LUT_SIZE, c), np.float32)
    for i, s in enumerate(sig):
        q = normal_cdf(s * x[:, None] + math.sqrt(max(1.0 - s * s, 0.0)) * z[None, :])
        for k in range(c):
            tables[i, :, k] = np.interp(q, u_lut, lut[:, k]) @ wz
    return tables, np.asarray(sig)


def histogram_tables(arr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`gaussianize` and :func:`filter_tables` of ``arr``, through the project's cache.

    They are functions of the texels alone and took 40 ms a 512x512 texture in every
    process that loads a scene (a terrain material has four or five); the entry is
    keyed by the texels' bytes and the code of this module and of :mod:`.mipmap`
    (:mod:`arches_render.cache`, folder ``textures/``).

    Returns
    -------
    (gauss, tables, sigma)
        As :func:`gaussianize` and :func:`filter_tables` return them.
    """
    arr = np.ascontiguousarray(arr)
    code = cache.source_digest(Path(__file__).resolve().parent, ("textures", "mipmap"), str(LUT_SIZE))
    texels = hashlib.sha256(arr.tobytes()).hexdigest()
    key = cache.cache_key(dict(shape=list(arr.shape), dtype=arr.dtype.str, texels=texels), code)

    def build():
        gauss, lut = gaussianize(arr)
        return (gauss, *filter_tables(gauss, lut))

    def load(f):
        with np.load(f, allow_pickle=False) as z:
            out = (z["gauss"], z["tables"], z["sigma"])
        if out[0].shape != arr.shape:
            raise ValueError(f"texture tables of shape {out[0].shape}, expected {arr.shape}")
        return out

    def save(value, path):
        write_npz(path, dict(zip(("gauss", "tables", "sigma"), value)))

    value, _ = cache.load_or_build(cache.cache_dir("textures") / f"histogram-{key}.npz", load, build, save)
    return value


def _hash2(ix, iy, seed):
    """Two uniform numbers in ``[0, 1)`` from an integer lattice vertex (Wellons' lowbias32 mix)."""
    h = mi.UInt32(ix) * 0x8DA6B343 ^ mi.UInt32(iy) * 0xD8163841 ^ seed
    h ^= h >> 16
    h *= 0x7FEB352D
    h ^= h >> 15
    h *= 0x846CA68B
    h ^= h >> 16
    return mi.Float(h & 0xFFFF) * (1.0 / 65536.0), mi.Float(h >> 16) * (1.0 / 65536.0)


def triangle_grid(uv, edge=TRIANGLE_EDGE):
    """Barycentric weights and lattice vertices of the triangle holding ``uv``.

    Parameters
    ----------
    uv : mi.Point2f
        Coordinates in texture periods.
    edge : float
        Triangle edge, in the same units.

    Returns
    -------
    (list of mi.Float, list of (mi.Int32, mi.Int32))
        Three weights (summing to 1) and the three vertices' integer lattice
        coordinates (see the module docstring).
    """
    t = uv.y * (1.0 / (edge * _SQRT3_2))
    s = uv.x * (1.0 / edge) - 0.5 * t
    bs, bt = dr.floor(s), dr.floor(t)
    fs, ft = s - bs, t - bt
    i, j = mi.Int32(bs), mi.Int32(bt)
    lower = fs + ft < 1.0
    w0 = dr.select(lower, 1.0 - fs - ft, fs + ft - 1.0)
    w1 = dr.select(lower, fs, 1.0 - ft)
    w2 = dr.select(lower, ft, 1.0 - fs)
    v0 = (dr.select(lower, i, i + 1), dr.select(lower, j, j + 1))
    return [w0, w1, w2], [v0, (i + 1, j), (i, j + 1)]


class RepeatTexture:
    """A texture repeated every period (``tiling = "repeat"``): one bilinear lookup on the
    MIP level of the footprint (:class:`~arches_render.materials.mipmap.MipTexture`)."""

    def __init__(self, arr: np.ndarray):
        self.channels = arr.shape[2]
        self.pyramid = MipTexture(arr)
        self.texels = self.pyramid.texels

    def eval(self, uv, footprint=None, active=True, xi=None):
        """Texel at ``uv`` (texture periods) under a ``footprint`` in texels (``None``: full
        detail), the level chosen by ``xi`` (:meth:`MipTexture.level`). Returns ``mi.Color3f``."""
        return _colour(self.pyramid.eval(uv, self.pyramid.level(footprint, xi), active))


class HistogramTexture:
    """Heitz and Neyret's histogram-preserving tiling of one texture (see the module docstring).

    Parameters
    ----------
    arr : numpy.ndarray
        ``(H, W, C)`` linear texels.
    bands : bool
        Offset tiles along ``u`` only.
    seed : int
        Salt of the tile offsets (layers sharing a texture take different tiles).
    """

    def __init__(self, arr: np.ndarray, bands: bool = False, seed: int = 0):
        gauss, tables, sigma = histogram_tables(arr)
        self.channels = arr.shape[2]
        self.gauss = MipTexture(gauss)
        self.texels = self.gauss.texels
        self.levels = tables.shape[0]
        self.sigma = sigma
        # 1 / s_l per level, gathered by the chosen level (the last, s = 0, is never read).
        self.inv_sigma = mi.Float(1.0 / np.maximum(sigma, 1e-6))
        # Opaque: a literal would tie the kernels to the texture's content.
        self.mean = [dr.opaque(mi.Float, float(tables[-1, :, k].mean())) for k in range(self.channels)]
        self.bands = bool(bands)
        # Level along y, u along x; clamped at both ends.
        self.lut = _texture2f(tables, dr.WrapMode.Clamp)
        self.seed = dr.opaque(mi.UInt32, int(seed) & 0xFFFFFFFF)

    def level(self, footprint, xi=None):
        """The pyramid level of a footprint given in texels (0: full detail), see
        :meth:`~arches_render.materials.mipmap.MipTexture.level`."""
        return self.gauss.level(footprint, xi)

    def eval(self, uv, footprint=None, active=True, xi=None):
        """Tiled texel at ``uv`` (texture periods).

        Parameters
        ----------
        uv : mi.Point2f
        footprint : mi.Float, optional
            Pixel footprint in texels (``None``: full detail).
        active : mi.Bool
        xi : mi.Float, optional
            Uniform number that chooses the MIP level (``None``: the nearest).

        Returns
        -------
        mi.Color3f
        """
        level = self.level(footprint, xi)
        active = mi.Bool(active)

        def taps(uv, level, *mean):
            weights, verts = triangle_grid(uv)
            g = [mi.Float(0.0) for _ in range(self.channels)]
            for w, (i, j) in zip(weights, verts):
                ox, oy = _hash2(i, j, self.seed)
                if self.bands:
                    oy = mi.Float(0.0)
                v = self.gauss.eval(mi.Point2f(uv.x + ox, uv.y + oy), level)
                for k in range(self.channels):
                    g[k] += w * v[k]
            norm = dr.rsqrt(dr.maximum(dr.square(weights[0]) + dr.square(weights[1]) + dr.square(weights[2]),
                                       1e-8)) * dr.gather(mi.Float, self.inv_sigma, level)
            y = (mi.Float(level) + 0.5) * (1.0 / self.levels)
            out = []
            for k in range(self.channels):
                u = 0.5 * (1.0 + dr.erf(g[k] * norm * (1.0 / math.sqrt(2.0))))
                # Table texel centres sit at (j + 1/2) / LUT_SIZE, as the quantiles do.
                out.append(self.lut.eval(mi.Point2f(u, y))[k])
            return tuple(out)

        # The last level is the texture's mean: packets entirely there take no lookup. (The
        # mean travels as state: a false branch returning values that are not among its
        # inputs met a Dr.Jit 1.5 code-generation bug once nested in another branch.)
        out = dr.if_stmt((uv, level, *self.mean), active & (level < self.levels - 1), taps,
                         lambda uv, level, *mean: mean, label="histogram_taps")
        return _colour(list(out))


def load_texture(name: str, srgb: bool = True, normalize: bool = True, tiling: str = "histogram",
                 seed: int = 0):
    """The sampler of a layer texture, built once per (variant, file, decoding, tiling, seed).

    Parameters
    ----------
    name : str
        As for :func:`texture_path`.
    srgb, normalize : bool
        Decode from sRGB; divide by the mean luminance.
    tiling : str
        One of :data:`TILINGS`.
    seed : int
        Tile-offset salt (histogram tilings).

    Returns
    -------
    RepeatTexture or HistogramTexture

    Raises
    ------
    ValueError
        Unknown tiling or missing file.
    """
    if tiling not in TILINGS:
        raise ValueError(f"triplanar: tiling '{tiling}' is not one of {', '.join(TILINGS)}")
    path = texture_path(name)
    key = (mi.variant(), str(path), bool(srgb), bool(normalize), tiling,
           0 if tiling == "repeat" else int(seed))
    if key not in _CACHE:
        arr = _read(path, bool(srgb), bool(normalize))
        _CACHE[key] = RepeatTexture(arr) if tiling == "repeat" else \
            HistogramTexture(arr, bands=tiling == "bands", seed=seed)
    return _CACHE[key]
