"""Gradient noise and fBm in Dr.Jit, with rigorous Lipschitz bounds.

Gradient noise (Perlin 2002, "improved noise"): on the integer lattice, each corner
``c`` of the cell holding ``p`` gets a pseudo-random gradient ``g_c`` among the 12
vectors ``(+-1, +-1, 0)`` and permutations (picked by an integer hash of the corner
and the seed: no permutation table to gather); with local coordinates
``u = p - floor(p)`` and the quintic fade ``s(t) = 6t^5 - 15t^4 + 10t^3``,

    n(p) = sum_c W_c(u) g_c . (u - c),    W_c = prod_k (c_k ? s(u_k) : 1 - s(u_k)).

Lipschitz bound (proved, not measured). ``grad n = sum_c A_c(u) g_c`` with
``A_c = grad W_c (u - c)^T + W_c I``; over all choices of the ``g_c`` its largest norm
is ``max_|e|=1 sum_c M2(A_c^T e)`` (``M2``: sum of the two largest ``|.|``).
:mod:`~arches_render.field.noise_bound` bounds this by a computer-assisted proof
(cube net of directions with a proved angle, interval bounds of ``A_c`` on
adaptive cubes, symmetries of the cell): ``|grad n| <= 3.758``, hence

    NOISE_LIPSCHITZ = 3.76.

It is tight: at ``u = (1/2, 1/2, 1/2)`` the gradients ``g_c = -sigma_x (0, sigma_y,
sigma_z)`` (``sigma = 2c - 1``) give ``|grad n| = 15/4``; random gradients reach
about 3.08.

For the range, ``|g . d| <= M2(d)`` (the sum of the two largest ``|d_k|``), so
``|n(u)| <= R(u) = sum_c W_c(u) M2(u - c)``, a function of ``u`` alone. Its maximum
on a 65^3 grid of the cell is 1.036; ``R`` is at most 12-Lipschitz (a crude
chain-rule bound, ``M2`` being sqrt(2)-Lipschitz) and every point of the cell is
within 0.0135 of the grid, so ``|n| <= 1.036 + 12 * 0.0135 < 1.2``
(NOISE_RANGE; sampling finds 0.92).

Curvature along a line (proved by hand; used by second-order line bounds). On a
line ``u(s) = u0 + s e``, ``|e| = 1``, ``n'' = sum_c W_c'' phi_c + 2 W_c' (g_c . e)`` with
``phi_c = g_c . (u - c)`` (linear, so ``phi_c'' = 0``). Per corner ``|phi_c| <= M2(u - c) <= 2``
and ``|g_c . e| <= M2(e)``; the fade's ``s' = 30 t^2 (t - 1)^2 <= 15/8`` and
``|s''| = 60 |t (2t - 1)(t - 1)| <= 10 / sqrt(3)``; summing the weights' derivatives over
the corners (the factors of the other axes sum to 1),
``sum_c |W_c'| <= 2 s'_max |e|_1`` and
``sum_c |W_c''| <= 2 s''_max + 4 s'_max^2 (|e|_1^2 - 1)``. Hence

    |n''| <= 2 (2 s''_max + 4 s'_max^2 (|e|_1^2 - 1)) + 4 s'_max M2(e) |e|_1,

which is 66.22 for directions in a coordinate plane (``|e|_1^2 <= 2``, ``M2(e) <= sqrt 2``;
what a heightfield's fBm at ``(x, y, const)`` sees) and 97.72 for any direction: crude,
the triangle inequality over corners. For the plane ``z = const``,
:mod:`~arches_render.field.noise_curvature` maximises ``sum_c M2(W_c'' (u - c) + 2 W_c' e)``
(the exact maximum over gradient configurations) by interval branch and bound and
certifies 15.50 (sampled maximum 13.86), hence NOISE_PLANAR_CURVATURE = 15.51
(float64 rounding of the intervals is below 1e-12).

fBm sums octaves ``k = 0..K-1`` of ``gain^k n(lacunarity^k p)`` with per-octave
seeds, so ``L = NOISE_LIPSCHITZ sum_k (gain lacunarity)^k``,
``|fbm| <= NOISE_RANGE sum_k gain^k`` and, along a line,
``|fbm''| <= C sum_k (gain lacunarity^2)^k`` (:func:`fbm_curvature`).

References
----------
Perlin, K. (2002). Improving noise. ACM Transactions on Graphics, 21(3), 681-682.
Musgrave, F. K., Kolb, C. E., Mace, R. S. (1989). The synthesis and rendering of
eroded fractal terrains. SIGGRAPH '89, 41-50.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

# Certified by arches_render/field/noise_bound.py (python -m arches_render.field.noise_bound):
# sup |grad n| <= 3.7580 = max over adaptive cubes of [net max of Phi / cos(delta) + V(cube)],
# e.g. the cube at u = (1/2,1/2,1/2): 3.6927 / 0.98425 + 0.0049 = 3.7567; lower bound 15/4 = 3.75.
NOISE_LIPSCHITZ = 3.76
NOISE_RANGE = 1.2
# Certified by arches_render/field/noise_curvature.py (python -m arches_render.field.noise_curvature
# --target 15.5): sup |n''| along lines in the plane z = const <= 15.50 (sampled 13.86).
NOISE_PLANAR_CURVATURE = 15.51


def corner_hash(hx, hy, hz):
    """Hash of a lattice corner from its per-axis products (one multiply-xorshift).

    The per-axis terms ``h_k = i_k * P_k`` (large odd constants) are computed once
    per cell and shared by the 8 corners; only the top 4 bits are used, which a
    single multiply mixes well.
    """
    h = (hx ^ hy ^ hz) * 0x27D4EB2D
    h ^= h >> 15
    h *= 0x165667B1
    return h >> 28


def grad_dot(h, x, y, z):
    """``g . (x, y, z)`` for the improved-noise gradient picked by the hash ``h``."""
    b = h
    u = dr.select(b < 8, x, y)
    v = dr.select(b < 4, y, dr.select((b == 12) | (b == 14), x, z))
    return dr.select((b & 1) == 0, u, -u) + dr.select((b & 2) == 0, v, -v)


def fade(t):
    """Perlin's quintic fade ``6t^5 - 15t^4 + 10t^3`` (C2 interpolation weight)."""
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def gradient_noise(p, seed):
    """Improved gradient noise at ``p`` (``mi.Point3f``); ``seed`` is a ``mi.UInt32``.

    Returns
    -------
    mi.Float
        Values in ``[-NOISE_RANGE, NOISE_RANGE]``, Lipschitz ``NOISE_LIPSCHITZ``.
    """
    fl = dr.floor(p)
    i = mi.Vector3i(fl)
    u = p - fl
    w = mi.Vector3f(fade(u.x), fade(u.y), fade(u.z))
    ix, iy, iz = (mi.UInt32(v) for v in (i.x, i.y, i.z))
    hx = (ix * 0x8DA6B343 ^ seed, (ix + 1) * 0x8DA6B343 ^ seed)
    hy = (iy * 0xD8163841, (iy + 1) * 0xD8163841)
    hz = (iz * 0xCB1AB31F, (iz + 1) * 0xCB1AB31F)
    result = mi.Float(0.0)
    for cx in (0, 1):
        wx = w.x if cx else 1.0 - w.x
        for cy in (0, 1):
            wxy = wx * (w.y if cy else 1.0 - w.y)
            for cz in (0, 1):
                wz = w.z if cz else 1.0 - w.z
                h = corner_hash(hx[cx], hy[cy], hz[cz])
                result += wxy * wz * grad_dot(h, u.x - cx, u.y - cy, u.z - cz)
    return result


def fade_derivative(t):
    """``s'(t) = 30 t^2 (t - 1)^2``, the derivative of :func:`fade`."""
    return 30.0 * t * t * dr.square(t - 1.0)


def corner_gradient(h):
    """The improved-noise gradient ``g`` that :func:`grad_dot` dots with, as a vector.

    ``grad_dot(h, d) = s1 d_a + s2 d_b`` with axis ``a = x`` (``h < 8``) else ``y``,
    axis ``b = y`` (``h < 4``), ``x`` (``h`` 12 or 14) else ``z``, and signs from bits
    0 and 1 of ``h``; so ``g = s1 e_a + s2 e_b``.
    """
    s1 = dr.select((h & 1) == 0, 1.0, -1.0)
    s2 = dr.select((h & 2) == 0, 1.0, -1.0)
    b_is_x = (h >= 4) & ((h == 12) | (h == 14))
    gx = dr.select(h < 8, s1, 0.0) + dr.select(b_is_x, s2, 0.0)
    gy = dr.select(h < 8, 0.0, s1) + dr.select(h < 4, s2, 0.0)
    gz = dr.select((h >= 4) & ~b_is_x, s2, 0.0)
    return mi.Vector3f(gx, gy, gz)


def gradient_noise_grad(p, seed):
    """:func:`gradient_noise` and its gradient at ``p``, in one pass over the corners.

    With ``n = sum_c W_c(u) g_c . (u - c)`` (module docstring), the product rule gives
    ``grad n = sum_c (grad W_c) (g_c . (u - c)) + W_c g_c``, where the ``k``-th
    component of ``grad W_c`` replaces factor ``k`` of ``W_c`` by ``+-s'(u_k)``.
    Bitwise the same value as :func:`gradient_noise`; about 1.5 times its cost, against
    4 evaluations for a finite-difference (tetrahedron) gradient.

    Returns
    -------
    (mi.Float, mi.Vector3f)
    """
    fl = dr.floor(p)
    i = mi.Vector3i(fl)
    u = p - fl
    w = mi.Vector3f(fade(u.x), fade(u.y), fade(u.z))
    dw = mi.Vector3f(fade_derivative(u.x), fade_derivative(u.y), fade_derivative(u.z))
    ix, iy, iz = (mi.UInt32(v) for v in (i.x, i.y, i.z))
    hx = (ix * 0x8DA6B343 ^ seed, (ix + 1) * 0x8DA6B343 ^ seed)
    hy = (iy * 0xD8163841, (iy + 1) * 0xD8163841)
    hz = (iz * 0xCB1AB31F, (iz + 1) * 0xCB1AB31F)
    value, grad = mi.Float(0.0), mi.Vector3f(0.0)
    for cx in (0, 1):
        wx, dx = (w.x, dw.x) if cx else (1.0 - w.x, -dw.x)
        for cy in (0, 1):
            wy, dy = (w.y, dw.y) if cy else (1.0 - w.y, -dw.y)
            wxy = wx * wy
            for cz in (0, 1):
                wz, dz = (w.z, dw.z) if cz else (1.0 - w.z, -dw.z)
                h = corner_hash(hx[cx], hy[cy], hz[cz])
                d = grad_dot(h, u.x - cx, u.y - cy, u.z - cz)
                weight = wxy * wz
                value += weight * d
                grad += mi.Vector3f(dx * wy * wz, wx * dy * wz, wxy * dz) * d + weight * corner_gradient(h)
    return value, grad


def fbm(p, octaves: int, lacunarity, gain, seed, level=None):
    """Fractional Brownian motion: ``sum_k gain^k n(lacunarity^k p)``.

    Parameters
    ----------
    p : mi.Point3f
        Points, already divided by the base wavelength.
    octaves : int
        Number of octaves (a structural constant: it shapes the kernel).
    lacunarity, gain : float or mi.Float
        Frequency and amplitude ratio between octaves.
    seed : mi.UInt32
        Base seed; octave ``k`` uses ``seed + k``.
    level : mi.Float, optional
        Footprint level of detail (:mod:`arches_render.field.lod`): octave ``k`` is
        weighted by ``clamp(level - k, 0, 1)`` and not evaluated where that is 0 (a
        symbolic branch: packets where no lane needs it skip it). ``None``: every
        octave, bitwise as with a level above ``octaves``.

    Returns
    -------
    mi.Float
    """
    total = mi.Float(0.0)
    amp = mi.Float(1.0)
    q = mi.Point3f(p)
    for k in range(int(octaves)):
        # A fixed irrational offset per octave hides the shared lattice origin.
        if level is None:
            total += amp * gradient_noise(q + 17.31 * k, seed + k)
        else:
            w = dr.clip(level - k, 0.0, 1.0)
            total = dr.if_stmt((total, amp, q, w, seed), w > 0.0,
                               lambda total, amp, q, w, seed, k=k:
                               total + w * (amp * gradient_noise(q + 17.31 * k, seed + k)),
                               lambda total, amp, q, w, seed: total, label="fbm_octave")
        q = q * lacunarity
        amp = amp * gain
    return total


def fbm_gradient(p, octaves: int, lacunarity, gain, seed, level=None):
    """:func:`fbm` and its gradient with the octaves' weights held fixed, in one pass.

    Bitwise the value of :func:`fbm` (the same operations in the same order, see
    :func:`gradient_noise_grad`). With a ``level`` the gradient is that of
    ``sum_k w_k gain^k n(lacunarity^k p)`` for the weights ``w_k`` *at p*: the fade of
    the weights along a ray is the caller's to bound
    (:mod:`arches_render.field.lod`).

    Returns
    -------
    (mi.Float, mi.Vector3f)
        The value and its gradient with respect to ``p`` (units of the base
        wavelength).
    """
    total, grad = mi.Float(0.0), mi.Vector3f(0.0)
    amp, freq = mi.Float(1.0), mi.Float(1.0)
    q = mi.Point3f(p)
    for k in range(int(octaves)):
        if level is None:
            v, g = gradient_noise_grad(q + 17.31 * k, seed + k)
            total += amp * v
            grad += (amp * freq) * g
        else:
            w = dr.clip(level - k, 0.0, 1.0)

            def octave(total, grad, amp, freq, q, w, seed, k=k):
                v, g = gradient_noise_grad(q + 17.31 * k, seed + k)
                return total + w * (amp * v), grad + (w * (amp * freq)) * g

            total, grad = dr.if_stmt((total, grad, amp, freq, q, w, seed), w > 0.0, octave,
                                     lambda total, grad, amp, freq, q, w, seed: (total, grad),
                                     label="fbm_gradient_octave")
        q = q * lacunarity
        amp = amp * gain
        freq = freq * lacunarity
    return total, grad


def fbm_curvature(octaves: int, lacunarity: float, gain: float) -> list[float]:
    """Bounds of ``|d^2/ds^2 fbm(u0 + s e)|`` for unit ``e`` in the xy plane (units of
    the base wavelength), for the first ``n = 0..octaves`` octaves:
    ``NOISE_PLANAR_CURVATURE sum_{k<n} (gain lacunarity^2)^k`` (module docstring)."""
    terms = [NOISE_PLANAR_CURVATURE * (gain * lacunarity ** 2) ** k for k in range(int(octaves))]
    return [sum(terms[:n]) for n in range(int(octaves) + 1)]


def fbm_lipschitz(octaves: int, lacunarity: float, gain: float) -> float:
    """Lipschitz bound of :func:`fbm` (in units of the base wavelength)."""
    return NOISE_LIPSCHITZ * sum((gain * lacunarity) ** k for k in range(int(octaves)))


def fbm_range(octaves: int, gain: float) -> float:
    """Bound of ``|fbm|``."""
    return NOISE_RANGE * sum(gain ** k for k in range(int(octaves)))
