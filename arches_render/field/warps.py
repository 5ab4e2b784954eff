"""Noise-driven nodes: a noise field, displacement of a surface, and domain warping.

``Noise``: ``f(p) = a fbm(p / lambda)``; not a solid by itself (unbounded), used as
a mask for material blending or as an operand.

``Displace``: ``g(p) = f(p) + a fbm(p / lambda)``;
``L_g = L_f + a L_fbm / lambda``. The surface moves by at most ``a |fbm|_max``
along the field.

``DomainWarp``: ``g(p) = f(p + a W(p / lambda))`` with ``W`` a vector of three
decorrelated fBm; the Jacobian of the warp is ``I + (a / lambda) J_W`` with
``||J_W|| <= sqrt(3) L_fbm``, so ``L_g = L_f (1 + sqrt(3) a L_fbm / lambda)``.

Bounds of displaced or warped solids grow by the largest offset they can cause;
this assumes the child's field falls at least at unit rate away from its box,
which holds for the primitives, heightfields and Boolean operators of the language.

With a footprint (:mod:`~arches_render.field.lod`) the three nodes evaluate the
octaves their cone resolves, with the truncated sum's bounds: its range is at most
the full one (the boxes and the displacement's envelope stay valid), its slope is
the truncated slope within the reach ``rho`` of the point and the full slope times
``1 + kappa s`` beyond.

References
----------
Ebert, D. S. et al. (2003). Texturing and Modeling: A Procedural Approach, 3rd ed.,
Morgan Kaufmann (domain distortion, ch. 6).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .lod import OctaveLOD, lod_lipschitz
from .node import Node, hart_bounds, opaque_float
from .noise import fbm, fbm_lipschitz, fbm_range


class FbmParams:
    """Shared fBm parameters: amplitude, wavelength, octaves, lacunarity, gain, seed."""

    #: fBm fields evaluated per point (a domain warp needs three).
    noise_fields = 1

    def _init_fbm(self, amplitude, wavelength, octaves, lacunarity, gain, seed):
        if not wavelength > 0:
            raise ValueError("wavelength must be > 0")
        if not 1 <= int(octaves) <= 16:
            raise ValueError("octaves must be in [1, 16]")
        self.amplitude_np = float(amplitude)
        self.wavelength_np = float(wavelength)
        self.octaves = int(octaves)
        self.lacunarity_np = float(lacunarity)
        self.gain_np = float(gain)
        self.seed_np = int(seed) & 0xFFFFFFFF
        self.amplitude = opaque_float(amplitude)
        self.inv_wavelength = opaque_float(1.0 / wavelength)
        self.lacunarity = opaque_float(lacunarity)
        self.gain = opaque_float(gain)
        self.seed = dr.opaque(mi.UInt32, self.seed_np)
        self._lod = OctaveLOD(self.octaves, self.lacunarity_np, self.gain_np, self.amplitude_np,
                              self.wavelength_np)

    def _fbm(self, p, salt=0, level=None):
        return fbm(p * self.inv_wavelength, self.octaves, self.lacunarity, self.gain,
                   self.seed + salt * 7919, level)

    def _lod_hart(self, f, levels, L_rest, x, footprint, scale=1.0):
        """Distance bounds of ``f`` (this node's footprint field at level ``x``), whose
        Lipschitz bound is ``L_rest`` plus ``scale`` times the truncated noise's
        (module docstring)."""
        S, rho = self._lod.slope(x, footprint)
        loc = dr.rcp(L_rest + scale * S)
        glob = dr.rcp(L_rest + scale * self._lod.global_slope(footprint))
        out = []
        for c in levels:
            gap = dr.maximum(-f - c, 0.0)
            out.append(dr.maximum(gap * glob, dr.minimum(rho, gap * loc)))
        return tuple(out)

    @property
    def lod_kappa(self) -> float:
        return max([self._lod.kappa] + [c.lod_kappa for c in self.children])

    def octave_error(self, footprint):
        """Bound of ``|a fbm_fp - a fbm|``: how far this node's truncated octave sum
        (one of its fBm fields) is from the full one at ``footprint``, as ``mi.Float``
        (:meth:`arches_render.field.lod.OctaveLOD.error`; 0 for ``None``). A
        :class:`Noise` or a :class:`Displace` of an octave-free child is within it of
        its full field, a :class:`DomainWarp` within ``sqrt(3) L_child`` times it."""
        return self._lod.error(self._lod.level(footprint))

    def own_lod_error(self, radius):
        """Bound of ``|a fbm_fp - a fbm|`` (one fBm field) for footprints up to ``radius``."""
        return self._lod.error_within(radius)

    @property
    def cost(self) -> float:
        # One octave of gradient noise costs about six capsules.
        return 6.0 * self.octaves * self.noise_fields + sum(
            c.cost for c in self.children)

    @property
    def max_offset(self) -> float:
        return abs(self.amplitude_np) * fbm_range(self.octaves, self.gain_np)

    @property
    def fbm_slope(self) -> float:
        """Lipschitz bound of ``a fbm(p / lambda)`` in world units."""
        return abs(self.amplitude_np) * fbm_lipschitz(self.octaves, self.lacunarity_np,
                                                      self.gain_np) / self.wavelength_np


class Noise(FbmParams, Node):
    """fBm field ``a fbm(p / lambda)`` (unbounded; a mask or an operand)."""

    kind = "noise"

    def __init__(self, amplitude=1.0, wavelength=1.0, octaves=4, lacunarity=2.0, gain=0.5, seed=0):
        self._init_fbm(amplitude, wavelength, octaves, lacunarity, gain, seed)

    def eval(self, p):
        return self.amplitude * self._fbm(p)

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        x = self._lod.level(footprint)
        if x is None:
            return super().eval_bounds(p, levels, direction)
        f = self.amplitude * self._fbm(p, 0, x)
        return f, self._lod_hart(f, levels, 0.0, x, footprint)

    def bounds(self):
        return np.full(3, -np.inf), np.full(3, np.inf)

    def lod_error(self, radius):
        return self.own_lod_error(radius)

    @property
    def lipschitz(self):
        return self.fbm_slope


class Displace(FbmParams, Node):
    """Child surface displaced along its field by fBm (see module docstring)."""

    kind = "displace"

    def __init__(self, child, amplitude=1.0, wavelength=1.0, octaves=4, lacunarity=2.0, gain=0.5,
                 seed=0):
        self.children = (child,)
        self._init_fbm(amplitude, wavelength, octaves, lacunarity, gain, seed)

    def eval(self, p):
        return self.children[0].eval(p) + self.amplitude * self._fbm(p)

    #: Set by :func:`~arches_render.field.culling.with_culling`: skip the noise where
    #: the result is certainly below ``-skip_margin`` (None: never skip).
    skip_margin = None

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        # {f >= -c} lies inside {f_child >= -c - max_offset} (a truncated sum too).
        child = self.children[0]
        fc, dc = child.eval_bounds(p, tuple(c + self.max_offset for c in levels), direction, footprint)
        x = self._lod.level(footprint)
        lvl = (p, fc) if x is None else (p, fc, x)
        if self.skip_margin is None:
            f = fc + self.amplitude * self._fbm(p, 0, x)
        else:
            f = dr.if_stmt(lvl, fc + self.max_offset >= -self.skip_margin,
                           lambda p, fc, *x: fc + self.amplitude * self._fbm(p, 0, *x),
                           lambda p, fc, *x: fc + self.max_offset, label="displace_skip")
        if x is None:
            hart = hart_bounds(f, levels, self.lipschitz)
        else:
            hart = self._lod_hart(f, levels, lod_lipschitz(child, footprint), x, footprint)
        return f, tuple(dr.maximum(a, b) for a, b in zip(dc, hart))

    def bounds(self):
        lo, hi = self.children[0].bounds()
        return lo - self.max_offset, hi + self.max_offset

    def lod_error(self, radius):
        return self.children[0].lod_error(radius) + self.own_lod_error(radius)

    def box_range(self, lo, hi):
        a, b = self.children[0].box_range(lo, hi)
        return a - self.max_offset, b + self.max_offset

    @property
    def lipschitz(self):
        return self.children[0].lipschitz + self.fbm_slope


class DomainWarp(FbmParams, Node):
    """Child evaluated at ``p + a W(p / lambda)`` (see module docstring)."""

    kind = "warp"
    noise_fields = 3

    def __init__(self, child, amplitude=1.0, wavelength=1.0, octaves=3, lacunarity=2.0, gain=0.5,
                 seed=0):
        self.children = (child,)
        self._init_fbm(amplitude, wavelength, octaves, lacunarity, gain, seed)

    def eval(self, p):
        w = mi.Vector3f(self._fbm(p, 0), self._fbm(p, 1), self._fbm(p, 2))
        return self.children[0].eval(p + self.amplitude * w)

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        x = self._lod.level(footprint)
        if x is None:
            return super().eval_bounds(p, levels, direction)
        w = mi.Vector3f(self._fbm(p, 0, x), self._fbm(p, 1, x), self._fbm(p, 2, x))
        # The child's footprint field at the warped point (a culled child may answer
        # its far value there, below its own: the bound below stays safe).
        f = self.children[0].eval_bounds(p + self.amplitude * w, (), footprint=footprint)[0]
        # |grad| <= |J_w| A + s B with the child's A <= L_c, B <= kappa_c L_c (lod.py) and
        # |J_w| <= 1 + sqrt(3) S_W: L_c (1 + kappa_c s) + sqrt(3) L_c S_W.
        child = self.children[0]
        return f, self._lod_hart(f, levels, lod_lipschitz(child, footprint), x, footprint,
                                 math.sqrt(3.0) * child.lipschitz)

    def bounds(self):
        lo, hi = self.children[0].bounds()
        r = self.max_offset * math.sqrt(3.0)
        return lo - r, hi + r

    def box_range(self, lo, hi):
        # The child is read at points at most sqrt(3) max_offset away.
        r = self.max_offset * math.sqrt(3.0)
        return self.children[0].box_range(lo - r, hi + r)

    def lod_error(self, radius):
        # The warped point moves by at most sqrt(3) times one field's error.
        child = self.children[0]
        return child.lod_error(radius) + math.sqrt(3.0) * child.lipschitz * self.own_lod_error(radius)

    @property
    def lipschitz(self):
        return self.children[0].lipschitz * (1.0 + math.sqrt(3.0) * self.fbm_slope)
