"""River erosion: canyons with undercut walls (Paris et al. 2019, section 6.1).

The impact of a river on its walls is approximated by the *stream power* of the
heightfield, ``sigma = A^(1/2) s`` (drainage area ``A`` by Freeman's multiple flow
direction after depression filling, local slope ``s``; see
:mod:`~arches_render.generators.terrain.hydrology`). Steps:

1. ``sigma`` is normalised by a reference stream power ``sigma_ref`` (by default
   a high quantile of ``sigma``), and the *riverbed* is the set of cells whose
   ``sigma / sigma_ref`` exceeds ``bed_threshold``.
2. "A small convolution extends the influence of the riverbed to the banks, to
   account for the impact of flooding": the bed's normalised stress is spread
   by a grey dilation of radius ``bank_width`` and smoothed by a Gaussian of half
   that width, giving the stress map ``S(x, y)`` in ``[0, 1]``. The water level
   ``z_w(x, y)`` is the lowest bed height within the same radius.
3. Poisson-disc samples of the terrain *surface* (a mesh, so canyon walls are
   sampled) where ``S > 0`` and ``0 <= z - z_w <= flood_height`` get the stress
   ``sigma(p) = S(p_xy) g(z - z_w, flood_height)`` (strongest at the water line)
   and the intensity ``e(rho(p), sigma(p))``; each kept sample carves a sphere of
   radius ``e * max_radius``. Where soft strata cross the walls the spheres are
   larger, which undercuts the walls into overhangs.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), section 6.1, Fig. 15.
Cordonnier, G. et al. (2016). Large scale terrain generation from tectonic uplift
and fluvial erosion. CGF 35(2) (stream power).
"""

from __future__ import annotations

import numpy as np

from .falloff import g
from .hydrology import fill_depressions, stream_power
from .shallow_erosion import ErosionPrimitives, erosion_intensity, sample_mesh

__all__ = ["river_stress", "river_erosion"]


def river_stress(heights, extent, bed_threshold=0.25, bank_width=None, sigma_ref=None, quantile=0.995):
    """Normalised stream-power stress of the riverbed spread to its banks.

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations over ``extent``.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` in metres.
    bed_threshold : float
        Riverbed: cells with ``sigma / sigma_ref`` above this.
    bank_width : float, optional
        Reach of the banks from the bed, metres; default 3 cells.
    sigma_ref : float, optional
        Reference stream power; default the ``quantile`` of ``sigma``.
    quantile : float
        Quantile of ``sigma`` used as ``sigma_ref``.

    Returns
    -------
    dict
        ``stress`` ``S`` (ny, nx) in [0, 1], ``water`` ``z_w`` (ny, nx), ``bed``
        (bool mask), ``sigma`` (raw stream power), ``area`` (``A``, m^2),
        ``slope``, ``sigma_ref``.
    """
    from scipy.ndimage import gaussian_filter, grey_dilation, grey_erosion
    H = np.asarray(heights, dtype=np.float64)
    ny, nx = H.shape
    x0, y0, x1, y1 = extent
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    sigma, A, s = stream_power(H, (dx, dy))
    ref = float(np.quantile(sigma, quantile)) if sigma_ref is None else float(sigma_ref)
    if not ref > 0:  # a flat DEM: no stream power anywhere, no river
        z = np.zeros_like(H)
        return dict(stress=z, water=H.copy(), bed=z.astype(bool), sigma=sigma, area=A, slope=s, sigma_ref=ref)
    sn = np.clip(sigma / ref, 0.0, 1.0)
    bed = sn > bed_threshold
    width = 3.0 * min(dx, dy) if bank_width is None else float(bank_width)
    k = max(1, int(round(width / min(dx, dy))))
    if k <= 8:
        yy, xx = np.mgrid[-k:k + 1, -k:k + 1]
        reach = dict(footprint=(xx * dx) ** 2 + (yy * dy) ** 2 <= (k * min(dx, dy)) ** 2)
    else:  # wide banks: a square (separable, fast at any width) instead of the disc
        reach = dict(size=(2 * k + 1, 2 * k + 1))
    S = grey_dilation(np.where(bed, sn, 0.0), **reach)
    S = np.clip(gaussian_filter(S, 0.5 * k), 0.0, 1.0)
    S[S < 1e-3] = 0.0
    # Water level: the lowest filled bed height within reach (banks see their river's level).
    Z = fill_depressions(H)
    water = grey_erosion(np.where(bed, Z, np.inf), **reach)
    water = np.where(np.isfinite(water), water, Z)
    return dict(stress=S, water=water, bed=bed, sigma=sigma, area=A, slope=s, sigma_ref=ref)


def _bilinear(grid, extent, x, y):
    ny, nx = grid.shape
    x0, y0, x1, y1 = extent
    u = np.clip((x - x0) / (x1 - x0) * (nx - 1), 0, nx - 1)
    v = np.clip((y - y0) / (y1 - y0) * (ny - 1), 0, ny - 1)
    i = np.minimum(u.astype(np.int64), nx - 2)
    j = np.minimum(v.astype(np.int64), ny - 2)
    fu, fv = u - i, v - j
    return ((grid[j, i] * (1 - fu) + grid[j, i + 1] * fu) * (1 - fv)
            + (grid[j + 1, i] * (1 - fu) + grid[j + 1, i + 1] * fu) * fv)


def river_erosion(heights, extent, mesh, resistance, spacing, max_radius, flood_height,
                  beta=0.2, threshold=0.05, bed_threshold=0.25, bank_width=None, seed=0, stress=None,
                  min_slope_deg=0.0):
    """River-erosion primitives on the walls of the valleys of a heightfield.

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations over ``extent``.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` in metres.
    mesh : trimesh.Trimesh
        The terrain surface (for sampling the walls).
    resistance : callable
        ``rho(points (N, 3)) -> (N,)`` in ``[0, 1]``.
    spacing : float
        Poisson-disc distance between samples, metres.
    max_radius : float
        Cavity radius at ``e = 1``, metres.
    flood_height : float
        Height above the water level that the river erodes, metres.
    beta, threshold : float
        ``beta`` of ``e(rho, sigma)``; drop samples with ``e < threshold``.
    bed_threshold, bank_width : float
        See :func:`river_stress`.
    seed : int
        Seed of the sampling.
    stress : dict, optional
        A precomputed :func:`river_stress` result.
    min_slope_deg : float
        Sample only faces at least this steep: the walls, not the floor of a
        flat-floored canyon (where a dent would be no overhang).

    Returns
    -------
    ErosionPrimitives
        Spheres carving the walls.
    """
    rng = np.random.default_rng(seed)
    st = stress or river_stress(heights, extent, bed_threshold, bank_width)
    S, water = st["stress"], st["water"]
    if not S.any():
        return ErosionPrimitives.empty()
    tri = np.asarray(mesh.triangles)
    cx, cy = tri[:, :, 0].mean(axis=1), tri[:, :, 1].mean(axis=1)
    above = tri[:, :, 2].max(axis=1) - _bilinear(water, extent, cx, cy)
    weight = ((_bilinear(S, extent, cx, cy) > 0) & (above >= 0)
              & (tri[:, :, 2].min(axis=1) - _bilinear(water, extent, cx, cy) <= flood_height)
              & (mesh.face_normals[:, 2] <= np.cos(np.radians(min_slope_deg)) + 1e-12))
    points, _ = sample_mesh(mesh, spacing, weight.astype(np.float64), rng)
    if len(points) == 0:
        return ErosionPrimitives.empty()
    h = points[:, 2] - _bilinear(water, extent, points[:, 0], points[:, 1])
    sigma = _bilinear(S, extent, points[:, 0], points[:, 1]) * np.where(h >= 0, g(h, flood_height), 0.0)
    e = erosion_intensity(np.asarray(resistance(points), dtype=np.float64), sigma, beta)
    keep = e >= threshold
    c = points[keep]
    return ErosionPrimitives(c, c.copy(), e[keep] * max_radius, e[keep])
