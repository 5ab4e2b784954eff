"""Cracks, fractures and tunnels by sweeping a profile along a curve (Peytavie et al. 2009, 4.2).

A skeleton curve through control points ``P_k`` (a Catmull-Rom spline, sampled into
short segments) carries a cross-section *profile*: a closed 2-D curve in the
curve's frame (``u`` sideways, ``v`` up), given as a polygon smoothed by a closed
Catmull-Rom spline (the paper's piecewise cubic profile curves, which may be
non-convex). Profiles may differ per control point (same number of vertices) and
are interpolated along the curve, as is an optional per-point scale. The carving
volume ``V`` is the union of the prisms swept by the profile along each segment
("a union of implicit prism primitives"), and the terrain becomes
``min(f, -f_V)``: every level of a stack axis inside ``V`` becomes air.

Modes:

* ``tunnel``: the curve is used as given (caves and tunnels); the frame's up
  vector is ``+Z`` made orthogonal to the tangent.
* ``crack``: the control points are first projected vertically onto the terrain
  (the paper projects the graph onto the surface) and the frame's up vector is the
  local surface normal, so a profile hanging below ``v = 0`` cuts into the ground.

An optional ``roughness`` scales the profile by ``1 + roughness * noise`` (seeded
3-D value noise) so that swept walls are not machined.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .editing import Region, axis_mask, value_noise
from .material_stacks import AIR, MaterialStacks


def catmull_rom(points, samples_per_span, closed=False):
    """Uniform Catmull-Rom spline through ``points`` (``(n, d)``), densely sampled."""
    P = np.asarray(points, dtype=np.float64)
    n = len(P)
    if n < 2:
        return P.copy()
    if closed:
        ext = np.concatenate([P[-1:], P, P[:2]])
        spans = n
    else:
        ext = np.concatenate([2 * P[:1] - P[1:2], P, 2 * P[-1:] - P[-2:-1]])
        spans = n - 1
    t = np.linspace(0, 1, samples_per_span, endpoint=False)[:, None]
    out = []
    for k in range(spans):
        p0, p1, p2, p3 = ext[k], ext[k + 1], ext[k + 2], ext[k + 3]
        out.append(0.5 * ((2 * p1) + (-p0 + p2) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t ** 2
                          + (-p0 + 3 * p1 - 3 * p2 + p3) * t ** 3))
    if not closed:
        out.append(P[-1:])
    return np.concatenate(out)


def _surface_normal(stacks: MaterialStacks, x, y):
    H = stacks.heights()
    gy, gx = np.gradient(H, stacks.cell)
    x0, y0, _ = stacks.origin
    i = np.clip(((np.asarray(x) - x0) / stacks.cell - 0.5).round().astype(int), 0, stacks.nx - 1)
    j = np.clip(((np.asarray(y) - y0) / stacks.cell - 0.5).round().astype(int), 0, stacks.ny - 1)
    n = np.stack([-gx[j, i], -gy[j, i], np.ones_like(gx[j, i])], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True), H[j, i]


def sweep(stacks: MaterialStacks, path, profile, mode="tunnel", scale=None, depth_offset=0.0,
          roughness=0.0, seed=0):
    """Carve the volume swept by a profile along a curve.

    Parameters
    ----------
    stacks : MaterialStacks
    path : array_like
        ``(n, 3)`` control points (``n >= 2``); in ``crack`` mode their ``z`` is
        replaced by the terrain height plus ``depth_offset``.
    profile : array_like
        ``(m, 2)`` profile polygon ``(u, v)`` in metres (``m >= 3``), or ``(n, m, 2)``:
        one profile per control point, interpolated along the curve.
    mode : {'tunnel', 'crack'}
    scale : array_like, optional
        ``(n,)`` profile scale per control point (default 1).
    depth_offset : float
        ``crack`` mode: height of the curve above the projected surface.
    roughness : float
        Relative amplitude of the noise on the profile size, in ``[0, 0.9]``.
    seed : int
        Noise seed.

    Returns
    -------
    MaterialStacks
    """
    P = np.asarray(path, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 2 or not np.all(np.isfinite(P)):
        raise ValueError("sweep path must be at least 2 finite [x, y, z] points")
    if mode not in ("tunnel", "crack"):
        raise ValueError(f"sweep mode must be 'tunnel' or 'crack' (got {mode!r})")
    prof = np.asarray(profile, dtype=np.float64)
    if prof.ndim == 2:
        prof = np.broadcast_to(prof, (len(P),) + prof.shape)
    if prof.ndim != 3 or prof.shape[0] != len(P) or prof.shape[2] != 2 or prof.shape[1] < 3 \
            or not np.all(np.isfinite(prof)):
        raise ValueError("sweep profile must be >= 3 finite [u, v] points, or one such list per path point")
    sc = np.ones(len(P)) if scale is None else np.asarray(scale, dtype=np.float64).reshape(-1)
    if len(sc) != len(P) or not np.all(sc > 0):
        raise ValueError(f"sweep scale must hold {len(P)} numbers > 0 (one per path point)")
    if not 0.0 <= roughness <= 0.9:
        raise ValueError(f"sweep roughness must be in [0, 0.9] (got {roughness})")
    if mode == "crack":
        _, h = _surface_normal(stacks, P[:, 0], P[:, 1])
        P = P.copy()
        P[:, 2] = h + depth_offset
    # Dense skeleton: spans of about half a cell, with interpolated profiles and scales.
    length = np.linalg.norm(np.diff(P, axis=0), axis=1).max()
    per = int(np.clip(np.ceil(2 * length / stacks.cell), 2, 256))
    C = catmull_rom(P, per)
    param = np.linspace(0, len(P) - 1, len(C))
    k = np.clip(np.floor(param).astype(int), 0, len(P) - 2)
    t = (param - k)[:, None]
    smooth = np.stack([catmull_rom(pr, 4, closed=True) for pr in prof])   # (n, m', 2)
    profs = (1 - t[..., None]) * smooth[k] + t[..., None] * smooth[k + 1]
    scales = (1 - t[:, 0]) * sc[k] + t[:, 0] * sc[k + 1]
    profs = profs * scales[:, None, None]
    # Frames: tangent, side, up.
    T = np.gradient(C, axis=0)
    T /= np.maximum(np.linalg.norm(T, axis=1, keepdims=True), 1e-12)
    if mode == "crack":
        ref, _ = _surface_normal(stacks, C[:, 0], C[:, 1])
    else:
        ref = np.tile([0.0, 0.0, 1.0], (len(C), 1))
    side = np.cross(T, ref)
    bad = np.linalg.norm(side, axis=1) < 1e-6
    side[bad] = np.cross(T[bad], [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    up = np.cross(side, T)
    reach = np.abs(profs).max() * (1 + roughness)
    region = Region(stacks, C.min(axis=0) - reach, C.max(axis=0) + reach)
    if region.empty:
        return stacks.copy()
    wavelength = max(2.0 * stacks.cell, reach)
    profs = np.ascontiguousarray(profs)

    def inside_fn(pts):
        grow = np.ones(len(pts))
        if roughness > 0:
            grow = 1.0 + roughness * value_noise(pts, wavelength, seed)
        return _inside_sweep(np.ascontiguousarray(pts), grow, C, T, side, up, profs, reach)

    inside = axis_mask(stacks, region, inside_fn)
    block = np.where(inside, AIR, -1).astype(np.int16)
    return stacks.rewrite(region.cols, region.lev0, block)


@njit(cache=True)
def _in_polygon(u, v, poly):
    inside = False
    m = len(poly)
    for a in range(m):
        b = (a + 1) % m
        ua, va, ub, vb = poly[a, 0], poly[a, 1], poly[b, 0], poly[b, 1]
        if (va > v) != (vb > v):
            x = ua + (v - va) * (ub - ua) / (vb - va)
            if u < x:
                inside = not inside
    return inside


@njit(cache=True)
def _inside_sweep(pts, grow, C, T, side, up, profs, reach):
    out = np.zeros(len(pts), dtype=np.bool_)
    nseg = len(C) - 1
    for s in range(nseg):
        a = C[s]
        b = C[s + 1]
        d = b - a
        L2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        lo0 = min(a[0], b[0]) - reach
        hi0 = max(a[0], b[0]) + reach
        lo1 = min(a[1], b[1]) - reach
        hi1 = max(a[1], b[1]) + reach
        lo2 = min(a[2], b[2]) - reach
        hi2 = max(a[2], b[2]) + reach
        for n in range(len(pts)):
            if out[n]:
                continue
            x, y, z = pts[n, 0], pts[n, 1], pts[n, 2]
            if x < lo0 or x > hi0 or y < lo1 or y > hi1 or z < lo2 or z > hi2:
                continue
            # Parameter along the segment; the prisms overlap a little at the joints.
            t = ((x - a[0]) * d[0] + (y - a[1]) * d[1] + (z - a[2]) * d[2]) / max(L2, 1e-20)
            if t < -0.25 or t > 1.25:
                continue
            w = min(max(t, 0.0), 1.0)
            # Frame and profile interpolated along the segment.
            u = 0.0
            v = 0.0
            for q in range(3):
                r = (x, y, z)[q] - (a[q] + w * d[q])
                u += r * ((1 - w) * side[s, q] + w * side[s + 1, q])
                v += r * ((1 - w) * up[s, q] + w * up[s + 1, q])
            poly = (1 - w) * profs[s] + w * profs[s + 1]
            g = grow[n]
            if _in_polygon(u / g, v / g, poly):
                out[n] = True
    return out
