"""Sea erosion: undercut cliffs, sea caves and arches (Paris et al. 2019, section 6.1).

The stress of the waves at a point ``p`` of the coast is

    sigma(p) = w(p) min(alpha(p) / alpha_open, 1),

with ``w`` a compact falloff of the distance to sea level (waves act within
``sea_range`` metres of it: ``w = g(|p_z - z_sea|, sea_range)``, the paper's 8 m
in Fig. 11) and ``alpha`` the accessibility of the point (ray-cast openness, see
:mod:`~arches_render.generators.terrain.accessibility`): a cave's back wall is
sheltered, the open cliff foot takes the waves. The paper multiplies ``w`` by
``alpha``; with ray-cast openness a vertical cliff over a flat sea floor has
``alpha = 1/2`` at best (the lower half of its hemisphere meets the floor), so we
take ``alpha_open = 1/2`` as full exposure. With the resistance ``rho`` of the
geology at ``p``, the intensity is ``e(rho, sigma)``
(:func:`~arches_render.generators.terrain.shallow_erosion.erosion_intensity`).

Samples are Poisson-disc points of the current terrain *surface* (a triangle
mesh, so vertical cliffs are sampled as densely as flats) in the sea band. Each
kept sample (``e >= threshold``) becomes a sphere carving a cavity of radius
``e * max_radius`` centred on the surface. Running several *steps*, each on the
mesh of the terrain carved by the previous ones, lets caves deepen where the rock
is soft and stay sheltered where it is not (Fig. 11: three steps).

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), section 6.1, Fig. 11, 13.
Miller, G. (1994). Efficient algorithms for local and global accessibility
shading. SIGGRAPH '94.
"""

from __future__ import annotations

import numpy as np

from .accessibility import RayCaster, accessibility
from .falloff import g
from .shallow_erosion import ErosionPrimitives, erosion_intensity, sample_mesh

__all__ = ["sea_stress_band", "sea_erosion_step", "ALPHA_OPEN"]

#: Accessibility of an open cliff face (half its hemisphere sees the sea floor).
ALPHA_OPEN = 0.5


def sea_stress_band(z, sea_level, sea_range):
    """``w(p) = g(|p_z - z_sea|, sea_range)``: the sea-level falloff of the stress."""
    return g(np.abs(np.asarray(z, dtype=np.float64) - sea_level), sea_range)


def _within_reach(V, F, points, D):
    """The faces a ray of length ``D`` from ``points`` can meet (a sub-mesh for Embree).

    A face is kept when its box comes within ``D`` of the points' box vertically and
    its centroid lies in a cell (of a 2-D grid of edge ``D``) next to a cell holding a
    point; faces are assumed smaller than ``D`` (grid and band meshes are).
    """
    import trimesh
    Z = V[F][:, :, 2]
    lo, hi = points[:, 2].min() - D, points[:, 2].max() + D
    keep = (Z.max(axis=1) >= lo) & (Z.min(axis=1) <= hi)
    c = V[F[keep]].mean(axis=1)[:, :2]
    origin = points[:, :2].min(axis=0) - 2 * D
    cell = np.floor((points[:, :2] - origin) / D).astype(np.int64)
    shape = cell.max(axis=0) + 3
    occ = np.zeros(tuple(shape), dtype=bool)
    occ[cell[:, 0], cell[:, 1]] = True
    from scipy.ndimage import binary_dilation
    occ = binary_dilation(occ, np.ones((3, 3), dtype=bool))
    q = np.floor((c - origin) / D).astype(np.int64)
    inside = np.all((q >= 0) & (q < shape), axis=1)
    near = np.zeros(len(q), dtype=bool)
    near[inside] = occ[q[inside, 0], q[inside, 1]]
    idx = np.flatnonzero(keep)[near]
    return trimesh.Trimesh(V, F[idx], process=False)


def sea_erosion_step(mesh, resistance, sea_level, sea_range, spacing, max_radius, beta=0.2,
                     threshold=0.05, rays=32, reach=None, seed=0, face_mask=None):
    """One step of sea erosion on a terrain mesh.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The current terrain surface, outward normals.
    resistance : callable
        ``rho(points (N, 3)) -> (N,)`` in ``[0, 1]`` (the geology tree).
    sea_level : float
        ``z_sea`` in metres.
    sea_range : float
        Half-height of the band the waves reach, metres (paper: 8 m).
    spacing : float
        Poisson-disc distance between samples, metres.
    max_radius : float
        Cavity radius carved at ``e = 1``, metres.
    beta : float
        ``beta`` of ``e(rho, sigma)``.
    threshold : float
        Samples with ``e`` below this are dropped.
    rays : int
        Rays per sample for the accessibility.
    reach : float, optional
        Ray length ``D`` of the accessibility; default ``4 max_radius``.
    seed : int
        Seed of the sampling and of the ray directions.
    face_mask : numpy.ndarray of bool, optional
        Faces that may be sampled (e.g. not the cut faces of a partial mesh).

    Returns
    -------
    ErosionPrimitives
        Spheres (``end == center``), radii ``e * max_radius``, intensities ``e``.
    """
    rng = np.random.default_rng(seed)
    tri_z = np.asarray(mesh.vertices)[np.asarray(mesh.faces)][:, :, 2]
    # Only faces where e can reach the threshold: e <= sigma <= w, so a face whose nearest
    # point to sea level has w < threshold (a sea floor, a plateau) holds no kept sample.
    near = np.clip(sea_level, tri_z.min(axis=1), tri_z.max(axis=1))
    in_band = sea_stress_band(near, sea_level, sea_range) >= threshold
    if face_mask is not None:
        in_band &= np.asarray(face_mask, dtype=bool)
    points, faces = sample_mesh(mesh, spacing, in_band.astype(np.float64), rng)
    w = sea_stress_band(points[:, 2], sea_level, sea_range) if len(points) else np.zeros(0)
    keep = w > 0
    points, faces, w = points[keep], faces[keep], w[keep]
    if len(points) == 0:
        return ErosionPrimitives.empty()
    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
    tri = V[F[faces]]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    D = 4.0 * max_radius if reach is None else float(reach)
    alpha = accessibility(mesh, points, normals, D, rays=rays, seed=seed + 1,
                          caster=RayCaster(_within_reach(V, F, points, D)))
    # A vertical wall above a flat sea floor sees half of its hemisphere blocked: take
    # that as full exposure (alpha_open = 1/2), so sheltered points still score low.
    sigma = w * np.minimum(alpha / ALPHA_OPEN, 1.0)
    rho = np.asarray(resistance(points), dtype=np.float64)
    e = erosion_intensity(rho, sigma, beta)
    keep = e >= threshold
    c = points[keep]
    return ErosionPrimitives(c, c.copy(), e[keep] * max_radius, e[keep])
