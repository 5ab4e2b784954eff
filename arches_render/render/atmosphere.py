"""Aerial perspective: height-dependent exponential atmosphere, in closed form along every segment.

The ``[atmosphere]`` scene table (parsed by :mod:`arches_render.scene.loader`)
fills the air with up to three exponential components, each with a density that
falls off with height above the reference level ``z_g`` (``ground``) and stays
constant below it:

===========  ===================================  ==========  ============  ==================
component    sea-level extinction ``beta`` (1/m)  ``H`` (m)   albedo        phase
===========  ===================================  ==========  ============  ==================
Rayleigh     (5.802, 13.558, 33.1) e-6  (R, G, B)  8000        1             Rayleigh
aerosol      Preetham's turbidity ``T`` (below)    1200        ``omega_a``   Henyey-Greenstein
haze         ``haze.density`` (grey)               ``haze.     ``omega_a``   Henyey-Greenstein
                                                   height``
===========  ===================================  ==========  ============  ==================

``sigma_k(z) = s beta_k exp(-max(z - z_g, 0) / H_k)``, with ``s`` the ``density``
multiplier. The Rayleigh coefficients are Bruneton's (2017) for 680, 550 and 440
nm. The aerosol coefficient follows the ``sunsky`` light's turbidity through
Preetham, Shirley and Smits (1999, appendix): Angstrom's turbidity coefficient
``b = 0.04608 T - 0.04586``, vertical aerosol optical thickness
``tau_a(lambda) = b lambda^-1.3`` (lambda in micrometres), and ``beta_a = tau_a / H_a``
(T = 3: 1.6e-4 /m at 550 nm, a meteorological range, Koschmieder's ``3.912 /
sigma``, of about 20 km; T = 10: about 5 km). More turbid skies hence bring denser
haze, and the sky's colour and the haze's agree on how hazy the day is.

Optical depth (closed form). Along the segment ``x(u) = o + u d``, ``0 <= u <= t``,
the heights run linearly from ``z_0`` to ``z_1``. With ``v_i = (z_i - z_g) / H``,

    I(t) = int_0^t exp(-max(v(u), 0)) du
         = t f + t (1 - f) exp(-min(v_0+, v_1+)) phi(|v_1+ - v_0+|),

where ``v+ = max(v, 0)``, ``f`` is the fraction of the segment below ``z_g``
(where the density is constant) and ``phi(y) = (1 - e^-y) / y``. Written from
the denser end with ``|dv|``, no exponential overflows for steep or long rays,
and ``phi`` takes a Taylor series for ``y < 0.01``, so near-horizontal segments
(``dz -> 0``, the usual view of a landscape) have no ``1 - e^-y`` cancellation:
the limit ``I = t exp(-v_0+)`` comes out exactly. The optical depth is
``tau = s sum_k beta_k I_k`` and the transmittance ``Tr = exp(-tau)`` (per RGB
channel). No marching: a handful of ``exp`` per segment.

In-scattering with a sky (Koschmieder's law, the sky as background). In a scene
with a sky emitter (``sunsky``, ``constant`` or ``envmap``) the air fades whatever
lies behind it to the sky:

    L = L_0 Tr + L_in,    L_in = (1 - Tr) L_bg(d),

with ``L_bg(d)`` the radiance of the sky emitters (summed; a ``sunsky`` without its
sun disk) in the segment's direction ``d``, its elevation clamped to >= 0: a
downward ray fades to the horizon in its azimuth, an upward one to the sky in its
own direction. ``1 - Tr`` is per RGB channel (``tau phi(tau)``, no cancellation in
thin air): Rayleigh and aerosols extinguish blue most, so blue fades first. ``L_bg`` is read
from a table of the sky evaluated by Mitsuba once per scene
(:class:`~arches_render.render.sky_table.SkyTable`, four gathers per segment, 0.17 %
interpolation error at the 99th percentile). This is Koschmieder's (1924) law of the
apparent luminance of a distant object against the horizon sky, the usual practical
aerial perspective. Its reason is continuity with the sky model, which already holds
the atmosphere beyond the scene (its sky *is* the light that the whole air column
scatters): a ray that leaves the scene comes out as the sky, ``L_sky Tr + (1 - Tr)
L_sky = L_sky`` (up to the table's error), so the sky is unchanged by the fog and
fully fogged far ground meets it at the horizon without a seam. A long horizontal
ray tends to the horizon radiance in its azimuth; as the density goes to 0,
``L_in = tau L_bg -> 0``.

In-scattering without a sky (single scattering). With only ``directional`` suns
(or point and area lights), sunlight ``E_j`` (irradiance arriving from
direction ``s_j``) and the ambient radiance ``L_a`` of the ground scatter
into the ray:

    L_in = int_0^t Tr(u) sum_k sigma_k(u) omega_k [ sum_j E_j p_k(d . s_j) + L_a ] du.

On a straight segment the bracket ``S_k`` is constant, so for ``K`` components
that share one height profile ``int Tr sigma = 1 - Tr(t)`` exactly and

    L_in = phi(tau) sum_k tau_k omega_k S_k          ( = (1 - Tr) sum_k (tau_k / tau) omega_k S_k ).

This is Hoffman and Preetham's (2002) aerial perspective,
``L = L_0 F_ex + L_in``, with their constant density replaced by the segment's
closed-form optical depth of each component. Where the components' profiles
differ along the segment (a slanted ray through the thin haze layer and the thick
Rayleigh layer) the weights ``tau_k / tau`` are an approximation: exact on
horizontal segments and for components of equal albedo and phase (aerosol and
haze), off by the Rayleigh share times its colour difference otherwise
(``tests/test_atmosphere.py`` measures it against quadrature at the
physical density with a 15 m haze layer: below 0.15 % on segments up to 3 km,
1 % on a 5 km ray skimming the ground, 2 % on a 20 km ray climbing 2.8 km). ``phi(tau)`` keeps
the optically thin limit (``L_in -> sum tau_k omega_k S_k -> 0`` as the density
goes to 0) free of ``0 / 0``.

Phase functions: Rayleigh ``p_R(mu) = 3 (1 + mu^2) / (16 pi)``; aerosol and haze
Henyey-Greenstein ``p_HG(mu) = (1 - g^2) / (4 pi (1 + g^2 - 2 g mu)^1.5)``, ``g =
anisotropy`` (0.76, as in Hoffman and Preetham's and Bruneton's models), where
``mu = d . s_j`` is the cosine between the view ray and the direction to the sun
(forward scattering peaks when looking towards the sun).

Light sources of the single-scattering model (:func:`light_sources`). A
``sunsky`` light's sun and a ``directional`` light are suns: ``E_j`` is their
irradiance, integrated once from Mitsuba's own emitter (so it carries the sky
model's reddening at low sun). The sky's in-scatter takes its average radiance
(exact for an isotropic phase): ``L_a = (int_up L_sky dw + 2 rho_g E_h) / (4 pi)``,
the upper hemisphere of the ``sunsky`` sky, ``constant`` and ``envmap`` lights
plus a Lambertian ground of albedo ``rho_g`` (``ground_albedo``, default the
``sunsky`` albedo) lit by the horizontal irradiance ``E_h`` of suns and sky.
:meth:`Atmosphere.for_scene` uses them only without a sky (with one, the sky
replaces them all); they stay for scenes built with explicit suns. Point and area
lights do not scatter in the air (their light still reaches surfaces through ``Tr``).

Approximations, deliberately (closed forms, no marching, no extra rays):

- With a sky, the air's colour is the sky's, not its own single scattering: the
  haze's density sets how fast things fade, the sky model (its turbidity) the
  colour they fade to. What this gives up: the phase function's glow around the
  sun now comes only from the sky model's circumsolar region, seen in the
  segment's direction (a downward ray towards the sun fades to the horizon below
  it, which holds that glow only while the sun is low); and air in shadow (cave
  air, a shaded gorge) fades to the open sky's radiance as if the sky lit it.
  With realistic densities a cave holds ``tau`` ~ 0.01 per 50 m, so its air adds
  1 % of the sky's radiance; a dense low haze lights cave air more than it should.
- Without a sky, sun visibility along the segment is taken as 1: no volumetric
  shadows (god rays), as in Hoffman and Preetham; inside a cave the air still
  in-scatters sunlight (``omega tau S``, ``tau`` ~ 0.01 per 50 m, well below the
  cave's bounce light, but a dense low haze seen towards the sun lights cave air
  more than it should).
- The emitters already hold the atmosphere beyond the scene (the sky model's sky
  *is* in-scattered light, and its sun is the ground-level sun). So rays that
  leave the scene (misses, and shadow rays towards suns and skies) are fogged
  only up to where they leave the scene's bounding box (meshes and field): a far
  ground plane ends in haze, and surfaces keep the sun the sky model gives. With
  a sky, a miss comes out as the sky; without one, the sky above the horizon
  clears over the angle at which rays climb out of the box. Segments to a hit
  and to area and point lights are fogged over their length.
- Shadow rays carry ``Tr`` and no in-scatter, and that is consistent, not an
  approximation: the in-scatter of the segment a path takes next is added once, by
  the path itself, whether that segment hits or leaves the scene; next-event
  estimation and the BSDF-sampled hit of the emitter (weighted by MIS) share only
  the emitter's light, ``L_e Tr``. A white ground under a uniform sky stays exactly
  as bright as the sky in any haze (``tests/test_atmosphere.py``, the furnace test;
  adding the in-scatter to shadow rays as well made it 11 % too bright).
- Single scattering without a sky; the sun's extinction on its way to the
  scattering point is that of the sky model's ground-level sun.

References
----------
Hoffman, N., Preetham, A. J. (2002). Rendering outdoor light scattering in real
time. Game Developers Conference (aerial perspective ``L_0 F_ex + L_in``).
Preetham, A. J., Shirley, P., Smits, B. (1999). A practical analytic model for
daylight. SIGGRAPH 1999 (turbidity, Angstrom coefficient, appendix A.3).
Bruneton, E. (2017). A qualitative and quantitative evaluation of 8 clear sky
models. IEEE TVCG 23(12) (Rayleigh coefficients, aerosol ``g`` and albedo).
Henyey, L. G., Greenstein, J. L. (1941). Diffuse radiation in the galaxy.
Astrophysical Journal 93 (phase function).
Koschmieder, H. (1924). Theorie der horizontalen Sichtweite. Beitraege zur Physik der
freien Atmosphaere 12 (visibility 3.912 / sigma; ``L = L_0 Tr + (1 - Tr) L_horizon``).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .march import ray_box
from .sky_table import SkyTable

__all__ = ["RAYLEIGH_BETA", "RAYLEIGH_HEIGHT", "AEROSOL_HEIGHT", "aerosol_extinction", "phi",
           "column", "rayleigh_phase", "hg_phase", "light_sources", "Atmosphere"]

#: Rayleigh extinction at sea level for 680, 550, 440 nm (1/m), Bruneton (2017).
RAYLEIGH_BETA = (5.802e-6, 13.558e-6, 33.1e-6)
#: Scale heights (m) of air molecules and aerosols.
RAYLEIGH_HEIGHT, AEROSOL_HEIGHT = 8000.0, 1200.0
#: Wavelengths (micrometres) that stand for R, G, B, and Angstrom's exponent.
RGB_WAVELENGTHS_UM = (0.680, 0.550, 0.440)
ANGSTROM_ALPHA = 1.3
#: Below this ``phi`` takes its Taylor series (float32 relative error < 1e-5 on both sides).
PHI_SERIES_BELOW = 1e-2


def aerosol_extinction(turbidity: float, scale_height: float = AEROSOL_HEIGHT) -> tuple:
    """Sea-level aerosol extinction (1/m, R, G, B) of a turbidity.

    Parameters
    ----------
    turbidity : float
        Preetham's turbidity ``T`` in [1, 10] (1: pure air).
    scale_height : float
        Aerosol scale height ``H_a`` in metres.

    Returns
    -------
    tuple of 3 floats
        ``b lambda^-1.3 / H_a`` with ``b = 0.04608 T - 0.04586`` (Preetham et al.
        1999, appendix), clamped at 0.
    """
    b = max(0.04608365822050 * float(turbidity) - 0.04586025928522, 0.0)
    return tuple(b * lam ** -ANGSTROM_ALPHA / float(scale_height) for lam in RGB_WAVELENGTHS_UM)


def phi(y):
    """``(1 - exp(-y)) / y`` for ``y >= 0``, without cancellation near 0.

    Parameters
    ----------
    y : mi.Float or mi.Color3f
        Non-negative argument.

    Returns
    -------
    Same type as ``y``
        In (0, 1]; 1 at ``y = 0``. Below :data:`PHI_SERIES_BELOW` the Taylor series
        ``1 - y/2 + y^2/6 - y^3/24`` (truncation ``y^4/120`` < 1e-10).
    """
    series = dr.fma(y, dr.fma(y, dr.fma(y, -1.0 / 24.0, 1.0 / 6.0), -0.5), 1.0)
    direct = (1.0 - dr.exp(-y)) / dr.maximum(y, PHI_SERIES_BELOW)
    return dr.select(y < PHI_SERIES_BELOW, series, direct)


def column(z0, z1, t, ground, inv_h):
    """Closed-form ``int_0^t exp(-max(z(u) - ground, 0) / H) du`` along a straight segment.

    Parameters
    ----------
    z0, z1 : mi.Float
        Heights of the segment's start and end.
    t : mi.Float
        Segment length (finite, >= 0).
    ground : mi.Float
        Reference height: the density is 1 at and below it.
    inv_h : mi.Float
        ``1 / H``, the inverse scale height.

    Returns
    -------
    mi.Float
        ``t f + t (1 - f) exp(-min(v0+, v1+)) phi(|v1+ - v0+|)`` with ``v = (z - ground) / H``,
        ``v+ = max(v, 0)`` and ``f`` the fraction of the segment below ``ground``
        (see the module docstring). Exact for horizontal segments, no overflow for
        steep ones.
    """
    v0, v1 = (z0 - ground) * inv_h, (z1 - ground) * inv_h
    lo, span = dr.minimum(v0, v1), dr.abs(v1 - v0)
    f = dr.select(span > 0.0, dr.clip(-lo / dr.maximum(span, 1e-30), 0.0, 1.0),
                  dr.select(lo < 0.0, 1.0, 0.0))
    p0, p1 = dr.maximum(v0, 0.0), dr.maximum(v1, 0.0)
    above = dr.exp(-dr.minimum(p0, p1)) * phi(dr.abs(p1 - p0))
    return t * (f + (1.0 - f) * above)


def rayleigh_phase(mu):
    """Rayleigh phase function ``3 (1 + mu^2) / (16 pi)`` (per steradian) of the cosine ``mu``."""
    return (3.0 / (16.0 * math.pi)) * (1.0 + mu * mu)


def hg_phase(mu, g):
    """Henyey-Greenstein phase function ``(1 - g^2) / (4 pi (1 + g^2 - 2 g mu)^1.5)``.

    Parameters
    ----------
    mu : mi.Float
        Cosine between the view ray and the direction to the light.
    g : mi.Float or float
        Asymmetry in (-1, 1); > 0 scatters forward.
    """
    g2 = g * g
    den = dr.maximum(1.0 + g2 - 2.0 * g * mu, 1e-8)
    return (1.0 - g2) / (4.0 * math.pi) * dr.rsqrt(den * den * den)


def _integrate_emitter(light: dict, n: int = 1 << 16, seed: int = 7):
    """``int L dw`` over the upper hemisphere and the horizontal irradiance of one emitter dict (Monte Carlo with Mitsuba's own
    importance sampling, fixed seed: deterministic)."""
    scene = mi.load_dict({"type": "scene", "light": light})
    em = scene.emitters()[0]
    it = dr.zeros(mi.Interaction3f, n)
    rng = mi.PCG32(n, seed)
    ds, w = em.sample_direction(it, mi.Point2f(rng.next_float32(), rng.next_float32()), True)
    # A constant emitter returns one literal weight, not one per sample: broadcast.
    w = np.broadcast_to(np.asarray(w, np.float64).reshape(3, -1), (3, n))
    d = np.broadcast_to(np.asarray(ds.d, np.float64).reshape(3, -1), (3, n))
    w = np.where(np.isfinite(w), w, 0.0)
    up = d[2] > 0.0
    total = (w * up).mean(axis=1)
    e_h = (w * np.maximum(d[2], 0.0)).mean(axis=1)
    return total, e_h


def light_sources(lights, ground_albedo: float):
    """Suns and ambient radiance of a scene's lights, for the in-scatter.

    Parameters
    ----------
    lights : list of dict
        Mitsuba emitter dicts as built by the scene loader.
    ground_albedo : float
        Albedo of the Lambertian ground that replaces the lower hemisphere.

    Returns
    -------
    (list, numpy.ndarray)
        ``[(direction_to_sun (3,), irradiance (3,)), ...]`` and the ambient
        radiance ``L_a`` (3,), see the module docstring. Point lights add nothing.
    """
    suns, sky, e_h = [], np.zeros(3), np.zeros(3)
    for light in lights:
        kind = light["type"]
        if kind == "sunsky":
            # The sun disk spans 0.27 degrees: int L dw over it is the irradiance
            # on a plane facing the sun (none once the sun is below the horizon).
            e_sun, e_sun_h = _integrate_emitter(dict(light, sky_scale=0.0))
            total, sky_h = _integrate_emitter(dict(light, sun_scale=0.0))
            s = np.asarray(light["sun_direction"], np.float64)
            suns.append((s / np.linalg.norm(s), e_sun))
            sky += total
            e_h += e_sun_h + sky_h
        elif kind == "directional":
            s = -np.asarray(light["direction"], np.float64)
            s /= np.linalg.norm(s)
            e = np.asarray(light["irradiance"]["value"], np.float64) * np.ones(3)
            suns.append((s, e))
            e_h += e * max(s[2], 0.0)
        elif kind in ("constant", "envmap"):
            total, eh = _integrate_emitter(light)
            sky += total
            e_h += eh
    ambient = (sky + 2.0 * float(ground_albedo) * e_h) / (4.0 * math.pi)
    return suns, ambient


class Atmosphere:
    """The atmosphere of one scene, ready for the integrator (see module docstring).

    Parameters
    ----------
    settings : AtmosphereSettings
        From the scene loader: ``turbidity``, ``density``, ``ground``,
        ``rayleigh_height``, ``aerosol_height``, ``anisotropy``, ``aerosol_albedo``,
        ``haze_density``, ``haze_height`` (0 density: no haze layer).
    suns : list of (direction, irradiance)
        From :func:`light_sources`.
    ambient : sequence of 3 floats
        Ambient radiance ``L_a``.
    box : (lo, hi)
        The scene's bounding box: rays that leave the scene are fogged up to its exit.
    sky : SkyTable, optional
        The scene's sky (:class:`~arches_render.render.sky_table.SkyTable`): with one,
        the in-scatter fades to it and ``suns`` and ``ambient`` are not used.

    All values are held in opaque Dr.Jit variables: a new atmosphere with other
    numbers (same haze on/off, same sky or number of suns) re-uses the compiled kernels.
    """

    def __init__(self, settings, suns, ambient, box, sky=None):

        def op(v):
            return dr.opaque(mi.Float, float(v))

        def op3(v):
            return mi.Color3f(*(op(x) for x in v))

        s = float(settings.density)
        self.beta_r = op3([b * s for b in RAYLEIGH_BETA])
        self.beta_a = op3([b * s for b in aerosol_extinction(settings.turbidity, settings.aerosol_height)])
        self.inv_h_r = op(1.0 / settings.rayleigh_height)
        self.inv_h_a = op(1.0 / settings.aerosol_height)
        self.has_haze = settings.haze_density > 0.0
        if self.has_haze:
            self.beta_h = op(settings.haze_density * s)
            self.inv_h_h = op(1.0 / settings.haze_height)
        self.ground = op(settings.ground)
        self.g = op(settings.anisotropy)
        self.omega_a = op(settings.aerosol_albedo)
        self.suns = [(mi.Vector3f(*(op(x) for x in d)), op3(e)) for d, e in suns]
        self.ambient = op3(ambient)
        self.sky = sky
        lo, hi = box
        self.lo = [op(v) for v in lo]
        self.hi = [op(v) for v in hi]

    @classmethod
    def for_scene(cls, settings, lights, box):
        """An atmosphere of a scene's light dicts: faded to its sky (:class:`~.sky_table.SkyTable`)
        if it has one, else lit by its suns (:func:`light_sources`)."""
        sky = SkyTable.for_lights(lights)
        if sky is not None:
            return cls(settings, [], (0.0, 0.0, 0.0), box, sky)
        suns, ambient = light_sources(lights, settings.ground_albedo)
        return cls(settings, suns, ambient, box)

    def exit_distance(self, o, d):
        """Distance along ``o + t d`` to where the ray leaves the scene box (0 if it never is inside)."""

        t_in, t_out = ray_box(o, d, self.lo, self.hi)
        return dr.select(t_in <= t_out, dr.maximum(t_out, 0.0), 0.0)

    def optical_depths(self, o, d, t):
        """Optical depths ``(tau_rayleigh, tau_aerosol_and_haze)`` (``mi.Color3f``) of ``o + u d``, ``u in [0, t]``."""
        z0, z1 = o.z, o.z + d.z * t
        tau_r = self.beta_r * column(z0, z1, t, self.ground, self.inv_h_r)
        tau_a = self.beta_a * column(z0, z1, t, self.ground, self.inv_h_a)
        if self.has_haze:
            tau_a = tau_a + self.beta_h * column(z0, z1, t, self.ground, self.inv_h_h)
        return tau_r, tau_a

    def transmittance(self, o, d, t):
        """``exp(-tau)`` (``mi.Color3f``) of the segment ``o + u d``, ``u in [0, t]`` (``|d| = 1``)."""
        tau_r, tau_a = self.optical_depths(o, d, t)
        return dr.exp(-(tau_r + tau_a))

    def segment(self, o, d, t):
        """Transmittance and in-scattered radiance of the segment ``o + u d``, ``u in [0, t]``.

        Returns
        -------
        (mi.Color3f, mi.Color3f)
            ``Tr = exp(-tau)`` and ``L_in`` (module docstring), radiance arriving at
            ``o`` from the air: :meth:`sky_in_scatter` in a scene with a sky,
            :meth:`single_scattering` without one.
        """
        tau_r, tau_a = self.optical_depths(o, d, t)
        if self.sky is not None:
            return dr.exp(-(tau_r + tau_a)), self.sky_in_scatter(d, tau_r + tau_a)
        return dr.exp(-(tau_r + tau_a)), self.single_scattering(d, tau_r, tau_a)

    def sky_in_scatter(self, d, tau):
        """``L_in = (1 - Tr) L_bg(d)``: the air fades what lies behind it to the sky seen in
        direction ``d`` (its horizon in ``d``'s azimuth for downward ``d``; Koschmieder 1924).

        Parameters
        ----------
        d : mi.Vector3f
            Direction of the segment.
        tau : mi.Color3f
            Its optical depth (per channel).

        Returns
        -------
        mi.Color3f
            ``tau phi(tau) L_bg(d)``: ``tau phi(tau) = 1 - exp(-tau)`` without the
            cancellation of ``1 - exp(-tau)`` in thin air.
        """
        return tau * phi(tau) * self.sky.lookup(d)

    def single_scattering(self, d, tau_r, tau_a):
        """``L_in = phi(tau) (tau_R S_R + omega_a tau_a S_a)``: the suns and the ambient
        radiance scattered once by the Rayleigh and the aerosol (and haze) components.

        Parameters
        ----------
        d : mi.Vector3f
            Direction of the segment (``mu = d . s_j`` for the phase functions).
        tau_r, tau_a : mi.Color3f
            Optical depths of the Rayleigh and of the aerosol and haze components.

        Returns
        -------
        mi.Color3f
            The in-scatter of the module docstring's single-scattering model.
        """
        s_r, s_a = mi.Color3f(self.ambient), mi.Color3f(self.ambient)
        for direction, irradiance in self.suns:
            mu = dr.dot(d, direction)
            s_r += irradiance * rayleigh_phase(mu)
            s_a += irradiance * hg_phase(mu, self.g)
        return phi(tau_r + tau_a) * (tau_r * s_r + self.omega_a * tau_a * s_a)

    def segment_length(self, ray, si):
        """Length of the fogged segment of ``ray``: to its hit, else to the scene box's exit."""
        return dr.select(si.is_valid(), si.t, self.exit_distance(ray.o, ray.d))

    def shadow_transmittance(self, si, ds):
        """Transmittance of a next-event shadow ray from ``si`` towards the emitter sample ``ds``:
        over ``ds.dist`` for area and point lights, to the scene box's exit for suns and skies."""
        far = mi.has_flag(ds.emitter.flags(), mi.EmitterFlags.Infinite) | \
            mi.has_flag(ds.emitter.flags(), mi.EmitterFlags.DeltaDirection) | ~dr.isfinite(ds.dist)
        t = dr.select(far, self.exit_distance(si.p, ds.d), ds.dist)
        return self.transmittance(si.p, ds.d, t)
