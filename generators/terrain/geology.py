"""The geology model: a construction tree for the bedrock resistance ``rho(p)`` in [0, 1].

Paris et al. (2019, Sec. 4) define the resistance of the bedrock to erosion as a
procedural field ``rho : R^3 -> [0, 1]`` (0: least, 1: most resistant) built by a
construction tree of its own. Its nodes here are :class:`~arches_render.field.Node`
subclasses (so :func:`arches_render.field.evaluate` and the Dr.Jit kernels of the
terrain can evaluate them), but they are *not* solids: ``bounds()`` is infinite and
the value is a resistance. Each node also reports ``value_range`` (``lo, hi``) and a
Lipschitz bound derived from its math. The tree's value is clamped to ``[0, 1]``
where it is used (:func:`resistance`, :meth:`ResistanceNode.rho`); clamping keeps
the Lipschitz bound.

Leaves (Sec. 4.1, 4.2, 4.3 "local" primitives):

* :class:`Turbulence` ``rho = offset + amplitude t(p_z / lambda0)`` (horizontal strata
  of noisy resistance; ``strata=False``: ``t(p / lambda0)``, 3-D noise). ``t`` is our
  fBm (range ``+-1.2 sum gain^k``; the paper's ``n`` is in ``[0, 1]``, hence ``offset``).
* :class:`StrataPlane` ``rho = weight g(d(p) / R)``, ``d`` the distance to a plane.
  The paper's ``+ t(p / lambda0)`` is a :class:`Turbulence` blended beside it.
* :class:`Strata` the same for a periodic family of parallel planes (``spacing``).
* :class:`LocalSkeleton` ``rho = weight g(dist(p, [a, b]) / R)`` (points, segments).
* :class:`Constant`.

Operators: :class:`Blend` (``rho_{A+B} = rho_A + rho_B``, the paper's blend),
:class:`Fold` (warp ``rho(p + delta(p))``, ``delta = a W(p / lambda0)``, Sec. 4.3),
:class:`Fault` (Sec. 4.4).

Faults, deviation: the paper makes ``rho`` discontinuous on the fault surface
(``rho o omega_F^{-1}`` strictly inside ``Omega_F``). A discontinuous ``rho`` has no
Lipschitz bound, and the erosion node ``f - f_D (1 - rho)`` would then have none:
sphere tracing and certified polygonization need one. :class:`Fault` therefore
blends linearly from ``rho`` to the slipped ``rho(p + slip)`` over a gouge of
``width`` metres on the inner side of the fault plane; with a small ``width`` the
strata are visibly sheared, and ``L <= L_rho + min(L_rho |slip|, range) / width``.

References
----------
Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
38(5), Sec. 4.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render.field.node import Node, evaluate, opaque_float, opaque_point
from arches_render.field.noise import fbm, fbm_lipschitz, fbm_range

from .falloff import G_SLOPE, g_dr


class ResistanceNode(Node):
    """Base of the geology nodes: unbounded, with ``value_range`` and Lipschitz bounds."""

    kind = "resistance"

    def bounds(self):
        return np.full(3, -np.inf), np.full(3, np.inf)

    @property
    def value_range(self) -> tuple[float, float]:
        raise NotImplementedError

    def rho(self, p):
        """Resistance clamped to ``[0, 1]`` on ``mi.Point3f``."""
        return dr.clip(self.eval(p), 0.0, 1.0)


def _check(child):
    if not isinstance(child, ResistanceNode):
        raise ValueError(f"a resistance operator needs resistance nodes (got {type(child).__name__})")
    return child


class _Noise:
    def _init_noise(self, wavelength, octaves, lacunarity, gain, seed):
        if not wavelength > 0:
            raise ValueError("wavelength must be > 0")
        if not 1 <= int(octaves) <= 12:
            raise ValueError("octaves must be in [1, 12]")
        self.wavelength_np, self.octaves = float(wavelength), int(octaves)
        self.lacunarity_np, self.gain_np = float(lacunarity), float(gain)
        self._inv_wl = opaque_float(1.0 / wavelength)
        self._lac, self._gain = opaque_float(lacunarity), opaque_float(gain)
        self._seed = dr.opaque(mi.UInt32, int(seed) & 0xFFFFFFFF)

    def _t(self, q, salt=0):
        return fbm(q * self._inv_wl, self.octaves, self._lac, self._gain, self._seed + salt * 7919)

    @property
    def _t_range(self):
        return fbm_range(self.octaves, self.gain_np)

    @property
    def _t_slope(self):
        return fbm_lipschitz(self.octaves, self.lacunarity_np, self.gain_np) / self.wavelength_np


class Turbulence(_Noise, ResistanceNode):
    """``offset + amplitude t(p_z / lambda0)`` (``strata=True``) or ``t(p / lambda0)``.

    Parameters
    ----------
    wavelength : float
        Fundamental wavelength ``lambda0`` (metres).
    amplitude, offset : float
        Scale and centre of the resistance.
    octaves, lacunarity, gain, seed
        fBm parameters.
    strata : bool
        Resistance as a function of elevation only (the paper's turbulence primitive).
    """

    kind = "resistance_turbulence"

    def __init__(self, wavelength, amplitude=0.5, offset=0.5, octaves=4, lacunarity=2.0, gain=0.5, seed=0,
                 strata=True):
        self._init_noise(wavelength, octaves, lacunarity, gain, seed)
        self.amplitude_np, self.offset_np, self.strata = float(amplitude), float(offset), bool(strata)
        self._amp, self._off = opaque_float(amplitude), opaque_float(offset)

    def eval(self, p):
        q = mi.Point3f(0.0, 0.0, p.z) if self.strata else p
        return self._off + self._amp * self._t(q)

    @property
    def value_range(self):
        r = abs(self.amplitude_np) * self._t_range
        return self.offset_np - r, self.offset_np + r

    @property
    def lipschitz(self):
        return abs(self.amplitude_np) * self._t_slope

    @property
    def cost(self):
        return 6.0 * self.octaves


class StrataPlane(ResistanceNode):
    """``weight g(d(p) / R)`` with ``d`` the distance to the plane through ``point`` with ``normal``."""

    kind = "resistance_plane"

    def __init__(self, point, normal, R, weight=1.0):
        n = np.asarray(normal, dtype=np.float64).reshape(3)
        if not np.linalg.norm(n) > 0:
            raise ValueError("normal must be non-zero")
        if not R > 0:
            raise ValueError("R must be > 0")
        self.n_np = n / np.linalg.norm(n)
        self.point_np = np.asarray(point, dtype=np.float64).reshape(3)
        self.R_np, self.weight_np = float(R), float(weight)
        self._n, self._o = opaque_point(self.n_np), opaque_point(self.point_np)
        self._inv_R, self._w = opaque_float(1.0 / R), opaque_float(weight)

    def eval(self, p):
        d = dr.dot(self._n, p - self._o) * self._inv_R
        return self._w * g_dr(d * d)

    @property
    def value_range(self):
        return min(0.0, self.weight_np), max(0.0, self.weight_np)

    @property
    def lipschitz(self):
        return abs(self.weight_np) * G_SLOPE / self.R_np


class Strata(ResistanceNode):
    """Periodic layers: ``weight g(d(p) / R)``, ``d`` the distance to the nearest plane
    ``n . p = phase + k spacing`` (``k`` integer). Needs ``2R <= spacing``.
    """

    kind = "resistance_strata"

    def __init__(self, spacing, R, weight=1.0, normal=(0.0, 0.0, 1.0), phase=0.0):
        n = np.asarray(normal, dtype=np.float64).reshape(3)
        if not np.linalg.norm(n) > 0:
            raise ValueError("normal must be non-zero")
        if not (spacing > 0 and R > 0 and 2 * R <= spacing):
            raise ValueError("strata need spacing > 0 and 0 < R <= spacing / 2")
        self.n_np = n / np.linalg.norm(n)
        self.spacing_np, self.R_np, self.weight_np, self.phase_np = float(spacing), float(R), float(weight), \
            float(phase)
        self._n = opaque_point(self.n_np)
        self._sp, self._inv_sp = opaque_float(spacing), opaque_float(1.0 / spacing)
        self._inv_R, self._w, self._ph = opaque_float(1.0 / R), opaque_float(weight), opaque_float(phase)

    def eval(self, p):
        x = dr.dot(self._n, p) - self._ph
        d = (x - self._sp * dr.round(x * self._inv_sp)) * self._inv_R
        return self._w * g_dr(d * d)

    @property
    def value_range(self):
        return min(0.0, self.weight_np), max(0.0, self.weight_np)

    @property
    def lipschitz(self):
        # g is flat (g' = 0) where the nearest plane switches (d = spacing/2 >= R).
        return abs(self.weight_np) * G_SLOPE / self.R_np


class LocalSkeleton(ResistanceNode):
    """``weight g(dist(p, [a, b]) / R)``: a local harder (weight > 0) or softer region."""

    kind = "resistance_skeleton"

    def __init__(self, a, b=None, R=1.0, weight=1.0):
        if not R > 0:
            raise ValueError("R must be > 0")
        self.a_np = np.asarray(a, dtype=np.float64).reshape(3)
        self.b_np = self.a_np.copy() if b is None else np.asarray(b, dtype=np.float64).reshape(3)
        self.R_np, self.weight_np = float(R), float(weight)
        self._a, self._ba = opaque_point(self.a_np), opaque_point(self.b_np - self.a_np)
        self._inv_l2 = opaque_float(1.0 / max(float(np.sum((self.b_np - self.a_np) ** 2)), 1e-30))
        self._inv_R, self._w = opaque_float(1.0 / R), opaque_float(weight)

    def eval(self, p):
        pa = p - self._a
        t = dr.clip(dr.dot(pa, self._ba) * self._inv_l2, 0.0, 1.0)
        return self._w * g_dr(dr.squared_norm(pa - self._ba * t) * dr.square(self._inv_R))

    @property
    def value_range(self):
        return min(0.0, self.weight_np), max(0.0, self.weight_np)

    @property
    def lipschitz(self):
        return abs(self.weight_np) * G_SLOPE / self.R_np


class Constant(ResistanceNode):
    """A constant resistance."""

    kind = "resistance_constant"

    def __init__(self, value):
        self.value_np = float(value)
        self._v = opaque_float(value)

    def eval(self, p):
        return mi.Float(0.0) + self._v

    @property
    def value_range(self):
        return self.value_np, self.value_np

    @property
    def lipschitz(self):
        return 0.0


class Blend(ResistanceNode):
    """``sum_i rho_i`` (the paper's blend of geology sub-trees)."""

    kind = "resistance_blend"

    def __init__(self, *children):
        if not children:
            raise ValueError("resistance_blend needs at least one operand")
        self.children = tuple(_check(c) for c in children)

    def eval(self, p):
        v = self.children[0].eval(p)
        for c in self.children[1:]:
            v = v + c.eval(p)
        return v

    @property
    def value_range(self):
        return (sum(c.value_range[0] for c in self.children), sum(c.value_range[1] for c in self.children))

    @property
    def lipschitz(self):
        return sum(c.lipschitz for c in self.children)


class Fold(_Noise, ResistanceNode):
    """``rho(p + a W(p / lambda0))``: folds by a turbulent warp (``W``: three fBm)."""

    kind = "resistance_fold"

    def __init__(self, child, amplitude, wavelength, octaves=3, lacunarity=2.0, gain=0.5, seed=0):
        self.children = (_check(child),)
        self._init_noise(wavelength, octaves, lacunarity, gain, seed)
        self.amplitude_np = float(amplitude)
        self._amp = opaque_float(amplitude)

    def eval(self, p):
        w = mi.Vector3f(self._t(p, 0), self._t(p, 1), self._t(p, 2))
        return self.children[0].eval(p + self._amp * w)

    @property
    def value_range(self):
        return self.children[0].value_range

    @property
    def lipschitz(self):
        return self.children[0].lipschitz * (1.0 + math.sqrt(3.0) * abs(self.amplitude_np) * self._t_slope)

    @property
    def cost(self):
        return 18.0 * self.octaves + self.children[0].cost


class Fault(ResistanceNode):
    """A fault: on the side ``(p - point) . normal > 0`` the strata slip by ``slip``.

    ``rho_F(p) = rho(p) + w(p) (rho(p + slip) - rho(p))``, ``w = clamp(d / width, 0, 1)``,
    ``d = (p - point) . normal`` (see the module docstring for the gouge ``width``).
    """

    kind = "resistance_fault"

    def __init__(self, child, point, normal, slip, width=1.0):
        n = np.asarray(normal, dtype=np.float64).reshape(3)
        if not np.linalg.norm(n) > 0:
            raise ValueError("normal must be non-zero")
        if not width > 0:
            raise ValueError("fault width must be > 0")
        self.children = (_check(child),)
        self.n_np = n / np.linalg.norm(n)
        self.point_np = np.asarray(point, dtype=np.float64).reshape(3)
        self.slip_np = np.asarray(slip, dtype=np.float64).reshape(3)
        self.width_np = float(width)
        self._n, self._o, self._slip = (opaque_point(v) for v in (self.n_np, self.point_np, self.slip_np))
        self._inv_w = opaque_float(1.0 / width)

    def eval(self, p):
        # Away from the gouge one evaluation of the child suffices (at p or at the
        # slipped p); the second one runs only for packets with lanes in the gouge.
        w = dr.clip(dr.dot(self._n, p - self._o) * self._inv_w, 0.0, 1.0)
        first = self.children[0].eval(dr.select(w >= 1.0, p + self._slip, p))

        def gouge(p, w, first):
            return first + w * (self.children[0].eval(p + self._slip) - first)

        def outside(p, w, first):
            return first

        return dr.if_stmt((p, w, first), (w > 0.0) & (w < 1.0), gouge, outside, label="fault_gouge")

    @property
    def value_range(self):
        return self.children[0].value_range

    @property
    def lipschitz(self):
        c = self.children[0]
        lo, hi = c.value_range
        jump = min(c.lipschitz * float(np.linalg.norm(self.slip_np)), hi - lo)
        return c.lipschitz + jump / self.width_np

    @property
    def cost(self):
        return 1.0 + 2.0 * self.children[0].cost


def resistance(node: ResistanceNode, points) -> np.ndarray:
    """``rho`` clamped to ``[0, 1]`` at numpy points, in one batched Dr.Jit evaluation.

    Parameters
    ----------
    node : ResistanceNode
        Root of the geology tree.
    points : array_like
        ``(N, 3)`` positions (metres).

    Returns
    -------
    numpy.ndarray
        ``(N,)`` float32 resistances.
    """
    if not isinstance(node, ResistanceNode):
        raise ValueError(f"resistance() needs a geology node (got {type(node).__name__})")
    return np.clip(evaluate(node, np.asarray(points, dtype=np.float64).reshape(-1, 3)), 0.0, 1.0)
