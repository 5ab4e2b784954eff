"""MIP pyramids of the layer textures, looked up at the level of the pixel footprint.

A texture seen from afar puts many texels under one pixel; looked up at full
resolution it aliases (the pixel's samples hit unrelated texels, and the image
sparkles). The pyramid holds the texture box-filtered at every scale:

    level 0 = the texture,  level l = the 2x2 means of level l - 1
    (an odd last row or column dropped),  l = 0 .. L - 1,  L = floor(log2(min(H, W))) + 1,

so the last level of a square texture is its mean. (A side that is not a power of
two loses its odd row or column at each level: its last levels cover a little less
than the whole period; the bundled textures are powers of two.) A footprint of ``f`` texels
(:func:`~arches_render.materials.detail.footprint` divided by the texel size: the
camera's pixel at the first vertex, the integrator's ray cone at later ones) selects
the continuous level ``lambda = clamp(log2(max(f, 1)), 0, L - 1)``.

Stochastic level choice. Instead of blending the two levels around ``lambda``
(trilinear filtering: two bilinear taps), each shading point takes one:
``floor(lambda) + 1`` with probability ``lambda - floor(lambda)``, else
``floor(lambda)``, decided by a uniform number ``xi`` hashed from the shading
position (:func:`position_hash`). One bilinear tap per lookup, and the expectation
over ``xi`` is the trilinear value (Pharr et al. 2024: filtering after shading
with stochastic texture filtering); the pixel's samples, at different positions,
draw different ``xi``, so the choice averages out with the samples. The hash of the
position keeps a render bitwise reproducible.

The pyramid lives in one flat array (levels one after the other, channels
interleaved); a lookup gathers its level's width, height and offset, then the four
texels of a bilinear tap with wrap-around (``repeat``): the layer textures tile.

References
----------
Williams, L. (1983). Pyramidal parametrics. SIGGRAPH '83 (MIP maps).
Pharr, M., Wronski, B., Salvi, M., Fajardo, M. (2024). Filtering after shading
with stochastic texture filtering. Proceedings of the ACM on Computer Graphics
and Interactive Techniques 7(1) (I3D 2024).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

__all__ = ["mip_levels", "position_hash", "MipTexture"]


def mip_levels(arr: np.ndarray) -> list[np.ndarray]:
    """The box-filtered pyramid of ``arr`` (see the module docstring).

    Parameters
    ----------
    arr : numpy.ndarray
        ``(H, W, C)`` texels.

    Returns
    -------
    list of numpy.ndarray
        ``L`` float64 arrays, level 0 (``arr``) first.
    """
    h, w = arr.shape[:2]
    out = [np.asarray(arr, np.float64)]
    for _ in range(int(math.log2(min(h, w)))):
        g = out[-1]
        hh, ww = g.shape[0] // 2 * 2, g.shape[1] // 2 * 2
        out.append(g[:hh, :ww].reshape(hh // 2, 2, ww // 2, 2, g.shape[2]).mean(axis=(1, 3)))
    return out


def _mix(h):
    # Wellons' lowbias32 finaliser: every input bit flips each output bit with probability ~1/2.
    h ^= h >> 16
    h *= 0x7FEB352D
    h ^= h >> 15
    h *= 0x846CA68B
    h ^= h >> 16
    return h


def position_hash(p):
    """A uniform number in ``[0, 1)`` from the bits of a position (the level choice's ``xi``).

    Parameters
    ----------
    p : mi.Point3f
        Shading position.

    Returns
    -------
    mi.Float
        24 bits of the hash of the three coordinates' bit patterns: the same position
        gives the same number (renders stay reproducible), positions a ulp apart
        uncorrelated ones.
    """
    bits = [dr.reinterpret_array(mi.UInt32, mi.Float(c)) for c in (p.x, p.y, p.z)]
    h = _mix(bits[0] ^ _mix(bits[1] ^ _mix(bits[2] + 0x9E3779B9)))
    return mi.Float(h >> 8) * (1.0 / (1 << 24))


class MipTexture:
    """A texture and its pyramid, sampled bilinearly with wrap-around at a per-lane level.

    Parameters
    ----------
    arr : numpy.ndarray
        ``(H, W, C)`` texels.

    Attributes
    ----------
    count : int
        Number of levels ``L``.
    texels : int
        ``min(H, W)``: a footprint in metres times ``texels / scale`` is in texels.
    """

    def __init__(self, arr: np.ndarray):
        levels = mip_levels(arr)
        self.count = len(levels)
        self.channels = arr.shape[2]
        self.texels = min(arr.shape[0], arr.shape[1])
        self.shapes = [lv.shape for lv in levels]
        sizes = [lv.shape[0] * lv.shape[1] for lv in levels]
        self.data = mi.Float(np.concatenate([lv.reshape(-1) for lv in levels]).astype(np.float32))
        self.width = mi.Float([float(s[1]) for s in self.shapes])
        self.height = mi.Float([float(s[0]) for s in self.shapes])
        self.offset = mi.UInt32([int(v) for v in np.cumsum([0] + sizes[:-1])])

    def level_array(self, level: int) -> np.ndarray:
        """One level of the pyramid, read back from the flat array the lookups use.

        Parameters
        ----------
        level : int
            ``0 .. count - 1`` (0: the texture itself).

        Returns
        -------
        numpy.ndarray
            ``(h, w, C)`` float32 texels of that level.
        """
        h, w, c = self.shapes[level]
        start = int(self.offset.numpy()[level]) * c
        return self.data.numpy()[start:start + h * w * c].reshape(h, w, c)

    def level(self, footprint=None, xi=None):
        """The level of a footprint (texels), chosen stochastically by ``xi`` (see the module docstring).

        Parameters
        ----------
        footprint : mi.Float, optional
            Footprint in texels (``None``: level 0).
        xi : mi.Float, optional
            Uniform number in ``[0, 1)`` (``None``: the nearest level).

        Returns
        -------
        mi.UInt32
        """
        if footprint is None:
            return mi.UInt32(0)
        lam = dr.clip(dr.log2(dr.maximum(footprint, 1.0)), 0.0, self.count - 1.0)
        lo = dr.floor(lam)
        up = (lam - lo) > (0.5 if xi is None else xi)
        return mi.UInt32(dr.minimum(lo + dr.select(up, 1.0, 0.0), self.count - 1.0))

    def eval(self, uv, level, active=True):
        """Bilinear lookup at ``uv`` (periods of the texture) on level ``level``.

        Parameters
        ----------
        uv : mi.Point2f
        level : mi.UInt32
        active : mi.Bool

        Returns
        -------
        list of mi.Float
            One value per channel.
        """
        active = mi.Bool(active)
        w = dr.gather(mi.Float, self.width, level, active)
        h = dr.gather(mi.Float, self.height, level, active)
        off = dr.gather(mi.UInt32, self.offset, level, active)
        # Wrap to one period first: texel indices stay exact far from the origin.
        x = (uv.x - dr.floor(uv.x)) * w - 0.5
        y = (uv.y - dr.floor(uv.y)) * h - 0.5
        x0, y0 = dr.floor(x), dr.floor(y)
        fx, fy = x - x0, y - y0
        x0, y0 = dr.select(x0 < 0.0, x0 + w, x0), dr.select(y0 < 0.0, y0 + h, y0)
        x1, y1 = x0 + 1.0, y0 + 1.0
        x1, y1 = dr.select(x1 >= w, x1 - w, x1), dr.select(y1 >= h, y1 - h, y1)
        iw = mi.UInt32(w)
        ix0, ix1 = mi.UInt32(x0), mi.UInt32(x1)
        r0, r1 = off + mi.UInt32(y0) * iw, off + mi.UInt32(y1) * iw
        c = self.channels
        out = []
        for k in range(c):
            t00 = dr.gather(mi.Float, self.data, (r0 + ix0) * c + k, active)
            t01 = dr.gather(mi.Float, self.data, (r0 + ix1) * c + k, active)
            t10 = dr.gather(mi.Float, self.data, (r1 + ix0) * c + k, active)
            t11 = dr.gather(mi.Float, self.data, (r1 + ix1) * c + k, active)
            out.append(dr.lerp(dr.lerp(t00, t01, fx), dr.lerp(t10, t11, fx), fy))
        return out
