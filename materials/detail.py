"""Procedural surface detail of a ``triplanar`` material, and the pixel footprint that limits it.

Textures repeat and photographs hold one scale; rock is rough at every scale.
The detail layer is a 3-D gradient-noise fBm evaluated at the shading position
(no projection, hence no seam and no period):

    h(p) = sum_{k < K} c_k g^k n(2^k p / lambda + o_k) / (s_n sqrt(sum_k g^2k)),

with ``n`` the improved gradient noise of :mod:`arches_render.field.noise`,
``lambda`` the largest wavelength (``detail_wavelength``), ``g`` the gain
(``detail_gain``), ``o_k`` a fixed per-octave offset and ``s_n`` = 0.27 the
standard deviation of one octave (measured over 10^6 random points), so that
``h`` has unit standard deviation at full detail. From the same ``h``:

* albedo ``a' = a max(1 + A h, 0)`` (``A = detail_albedo``);
* Oren-Nayar roughness ``sigma' = sigma max(1 + R h, 0)`` (``R = detail_roughness``);
* a bump: the height field ``H = sum_k c_k g^k n_k`` scaled so that its surface
  gradient has RMS ``B = detail_bump`` at full detail (each octave's gradient
  component has standard deviation 0.70 ``2^k g^k / lambda``); the shading
  normal becomes ``n' = normalize(n - (grad H - (grad H . n) n))`` (Blinn 1978,
  bump mapping by the surface gradient of a height field), so ``B`` is the RMS
  slope of the bumps (0.15: about 8.5 degrees). The gradient is the noise's
  analytic one (:func:`~arches_render.field.noise.gradient_noise_grad`), evaluated
  with the value in one pass over the cell's corners: one noise evaluation per
  octave instead of four taps of a finite difference.

Footprint cutoff. A pixel of the camera covers, at distance ``t``, a disc of
radius ``r = t spread`` on a surface facing it (``spread`` = the pixel's
angular size, :func:`pixel_spread`), stretched by ``1 / cos`` at grazing
incidence; the footprint used here is ``t spread / sqrt(max(|cos theta_i|,
0.05))``, the geometric mean of the ellipse's axes. Octave ``k`` has wavelength
``lambda_k = lambda / 2^k``; its weight

    c_k = smoothstep((lambda_k / (LOD_FACTOR footprint) - 1)),   LOD_FACTOR = 2,

is 1 above four footprints and 0 at two (Nyquist), continuous in the footprint,
so far terrain does not alias or sparkle and near terrain keeps every octave.
This is the footprint of the ray cones of Amanatides (1984) and of the "LOD"
contract of the field nodes (``footprint = r0 + t spread``, here ``r0 = 0``).
At secondary vertices the integrator passes its ray cone instead (widened by
each non-specular bounce), so the fine octaves are dropped where the bounce
integrates them away.

References
----------
Perlin, K. (2002). Improving noise. ACM TOG 21(3) (the noise).
Blinn, J. F. (1978). Simulation of wrinkled surfaces. SIGGRAPH '78 (bump mapping).
Amanatides, J. (1984). Ray tracing with cones. SIGGRAPH '84 (pixel footprint).
Musgrave, F. K. et al. (1989). The synthesis and rendering of eroded fractal
terrains. SIGGRAPH '89 (fBm detail).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..field.noise import gradient_noise_grad

__all__ = ["DETAIL_KEYS", "LOD_FACTOR", "MAX_OCTAVES", "Detail", "footprint", "pixel_spread", "octave_weight"]

#: Octaves are dropped below ``LOD_FACTOR`` footprints (faded in up to twice that).
LOD_FACTOR = 2.0
MAX_OCTAVES = 10
#: Plugin properties of the detail layer and their defaults (``detail_octaves = 0``: none).
DETAIL_KEYS = {"detail_octaves": 0, "detail_wavelength": 4.0, "detail_gain": 0.6, "detail_albedo": 0.3,
               "detail_roughness": 0.3, "detail_bump": 0.15, "detail_seed": 0}
#: Standard deviation of one octave of the gradient noise (10^6 random points: 0.270), and of
#: each component of its gradient (5 10^5 points, central differences: 0.69-0.72).
NOISE_STD, GRAD_STD = 0.27, 0.70


def pixel_spread(fov_deg: float, width: int) -> float:
    """Angular size (radians) of one pixel of a perspective camera.

    Parameters
    ----------
    fov_deg : float
        Horizontal field of view, degrees.
    width : int
        Image width in pixels.

    Returns
    -------
    float
        ``2 tan(fov / 2) / width``: at distance ``t`` a pixel is ``t * spread`` wide.
    """
    return 2.0 * math.tan(math.radians(float(fov_deg)) * 0.5) / max(int(width), 1)


def footprint(si, spread, cone_radius=None):
    """Pixel footprint (metres) at a surface interaction (see the module docstring).

    Parameters
    ----------
    si : mi.SurfaceInteraction3f
        Needs ``t`` and ``wi`` (local).
    spread : mi.Float
        Pixel angular size (0: no footprint, full detail).
    cone_radius : mi.Float, optional
        The radius of the path's ray cone at ``si`` where the integrator tracks one
        (:mod:`arches_render.render.integrator`: a bounce widens it by the BSDF
        lobe), used instead of ``si.t * spread / 2``: at a secondary vertex the bounce
        length alone under-estimates the footprint and keeps detail that the
        bounce integrates away.

    Returns
    -------
    mi.Float
    """
    cos = dr.maximum(dr.abs(mi.Float(si.wi.z)), 0.05)
    if cone_radius is not None:
        return 2.0 * cone_radius * dr.rsqrt(cos)
    t = dr.select(dr.isfinite(si.t), si.t, 0.0)
    return t * spread * dr.rsqrt(cos)


def octave_weight(wavelength, fp):
    """Weight of an octave of ``wavelength`` metres under a footprint ``fp`` (1 far above, 0 at Nyquist)."""
    r = wavelength * dr.rcp(dr.maximum(LOD_FACTOR * fp, 1e-12)) - 1.0
    r = dr.clip(r, 0.0, 1.0)
    return r * r * (3.0 - 2.0 * r)


class Detail:
    """The detail layer of one material (see the module docstring).

    Parameters
    ----------
    octaves : int
        ``K`` (1 .. :data:`MAX_OCTAVES`; a structural constant).
    wavelength, gain, albedo, roughness, bump : float
        ``lambda`` (m), ``g``, ``A``, ``R``, ``B``.
    seed : int
        Noise seed.
    """

    def __init__(self, octaves, wavelength, gain, albedo, roughness, bump, seed=0):
        self.octaves = int(octaves)
        if not 1 <= self.octaves <= MAX_OCTAVES:
            raise ValueError(f"triplanar: detail_octaves {octaves} is outside 1..{MAX_OCTAVES}")
        checks = {"detail_wavelength": (wavelength, 1e-6, 1e6), "detail_gain": (gain, 0.0, 1.0),
                  "detail_albedo": (albedo, 0.0, 1.0), "detail_roughness": (roughness, 0.0, 1.0),
                  "detail_bump": (bump, 0.0, 4.0)}
        for key, (v, lo, hi) in checks.items():
            if not lo <= float(v) <= hi:
                raise ValueError(f"triplanar: {key} {v} is outside [{lo:g}, {hi:g}]")

        def op(v):
            return dr.opaque(mi.Float, float(v))

        self.params = {"detail_wavelength": op(wavelength), "detail_gain": op(gain),
                       "detail_albedo": op(albedo), "detail_roughness": op(roughness),
                       "detail_bump": op(bump)}
        self.seed = dr.opaque(mi.UInt32, int(seed) & 0xFFFFFFFF)

    @classmethod
    def from_props(cls, props):
        """The detail of a plugin's properties, or ``None`` when ``detail_octaves`` is 0 or absent."""
        get = {k: props.get(k, d) for k, d in DETAIL_KEYS.items()}
        if int(get["detail_octaves"]) == 0:
            return None
        return cls(get["detail_octaves"], get["detail_wavelength"], get["detail_gain"], get["detail_albedo"],
                   get["detail_roughness"], get["detail_bump"], get["detail_seed"])

    def eval(self, p, n, fp, active=True):
        """Albedo factor, roughness factor and bumped normal at ``p``.

        Octave ``k`` contributes ``c_k g^k n_k`` to ``h`` and ``c_k g^k 2^k grad n_k /
        lambda`` to ``grad H`` (the noise's analytic gradient,
        :func:`~arches_render.field.noise.gradient_noise_grad`); an octave whose
        weight ``c_k`` is 0 in every lane of a SIMD packet is not evaluated there
        (a symbolic branch), so distant terrain and secondary vertices, whose wide
        footprints drop the fine octaves, cost a few octaves, not ``K``.

        Parameters
        ----------
        p : mi.Point3f
            Shading position.
        n : mi.Vector3f
            Unit shading normal (world).
        fp : mi.Float
            Footprint in metres (:func:`footprint`).
        active : mi.Bool

        Returns
        -------
        (mi.Float, mi.Float, mi.Vector3f)
        """
        P = self.params
        wl = P["detail_wavelength"]
        inv_wl = dr.rcp(wl)
        total, grad = mi.Float(0.0), mi.Vector3f(0.0)
        amp, var, slope_var = mi.Float(1.0), mi.Float(0.0), mi.Float(0.0)
        q = p * inv_wl
        for k in range(self.octaves):
            weight = dr.select(active, octave_weight(wl * (0.5 ** k), fp), 0.0)

            def octave(total, grad, q, weight, amp, k=k):
                # Fixed irrational offsets per octave hide the shared lattice origin.
                v, g = gradient_noise_grad(q + 31.7 * (k + 1), self.seed + k)
                c = weight * amp
                return total + c * v, grad + g * (c * (2.0 ** k))

            total, grad = dr.if_stmt((total, grad, q, weight, amp), weight > 0.0, octave,
                                     lambda total, grad, q, weight, amp: (total, grad), label="detail_octave")
            var += amp * amp
            slope_var += dr.square(amp * (2.0 ** k))
            q = q * 2.0
            amp = amp * P["detail_gain"]
        h = total * dr.rsqrt(var) * (1.0 / NOISE_STD)
        # grad_p H = grad / lambda; unit RMS slope at full detail: per-axis gradient std
        # GRAD_STD 2^k g^k / lambda per octave, scaled to B.
        slope = grad * (P["detail_bump"] * dr.rsqrt(slope_var) * (1.0 / (GRAD_STD * math.sqrt(2.0))))
        tangential = slope - dr.dot(slope, n) * n
        n_bumped = dr.normalize(n - tangential)
        albedo = dr.maximum(1.0 + P["detail_albedo"] * h, 0.0)
        rough = dr.maximum(1.0 + P["detail_roughness"] * h, 0.0)
        return albedo, rough, n_bumped

    def traverse(self, callback):
        """Expose the opaque parameters (``detail_wavelength``, ... without ``detail_octaves``)."""
        for k, v in self.params.items():
            callback.put(k, v, mi.ParamFlags.NonDifferentiable)
