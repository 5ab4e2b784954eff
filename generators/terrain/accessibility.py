"""Accessibility of surface points, by ray casting against a coarse terrain mesh.

The stress of sea waves on a coast is the product of a falloff from sea level and
the *accessibility* ``alpha`` of the point (Paris et al. 2019, section 6.1, after
Miller 1994): a point at the back of a cave or under an overhang is sheltered,
one on an open cliff face is exposed. Miller defines accessibility as the radius
of the largest sphere that touches the point without entering the surface; we
use its ray-cast form, the *openness* of the point within a distance ``D``:

    alpha(p) = (1 / K) sum_k [ray p + t w_k, 0 < t < D, misses the terrain],

with ``K`` directions ``w_k`` stratified over the hemisphere around the outward
normal ``n(p)``. A point whose largest empty touching sphere has radius ``r`` has
(almost) all of its rays blocked within ``~2r``, so ``alpha`` at scale ``D`` is
a monotone proxy of Miller's radius for ``r < D / 2``. The rays are traced with
Embree (embreex) against a triangle mesh of the current terrain (a heightfield
grid, or a marching-cubes mesh of the construction tree once it has caves).

References
----------
Miller, G. (1994). Efficient algorithms for local and global accessibility
shading. SIGGRAPH '94, 319-326.
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), section 6.1.
"""

from __future__ import annotations

import numpy as np

__all__ = ["heightfield_mesh", "hemisphere_directions", "accessibility", "RayCaster"]


def heightfield_mesh(heights, extent, step=1):
    """Triangle mesh of a heightfield grid (two triangles per cell).

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` elevations; sample ``[j, i]`` at ``(x0 + i dx, y0 + j dy)``.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` in metres.
    step : int
        Keep every ``step``-th sample in each direction (a coarse mesh).

    Returns
    -------
    trimesh.Trimesh
        Faces wound counter-clockwise seen from above (normals point up).
    """
    import trimesh
    H = np.asarray(heights, dtype=np.float64)
    ny, nx = H.shape
    x0, y0, x1, y1 = (float(v) for v in extent)
    js = np.unique(np.r_[np.arange(0, ny, step), ny - 1])
    iis = np.unique(np.r_[np.arange(0, nx, step), nx - 1])
    xs = x0 + iis * (x1 - x0) / (nx - 1)
    ys = y0 + js * (y1 - y0) / (ny - 1)
    X, Y = np.meshgrid(xs, ys)
    V = np.stack([X.ravel(), Y.ravel(), H[np.ix_(js, iis)].ravel()], axis=1)
    m, n = len(js), len(iis)
    idx = np.arange(m * n).reshape(m, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    F = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return trimesh.Trimesh(V, F, process=False)


def hemisphere_directions(normals, count, rng):
    """``count`` stratified, cosine-weighted directions around each normal.

    Parameters
    ----------
    normals : numpy.ndarray
        ``(N, 3)`` unit normals.
    count : int
        Directions per point (stratified on a ``sqrt(count)`` square grid when
        ``count`` is a square, jittered).
    rng : numpy.random.Generator
        Source of the jitter and of a random rotation per point.

    Returns
    -------
    numpy.ndarray
        ``(N, count, 3)`` unit directions with ``dot(w, n) > 0``.
    """
    N = len(normals)
    k = int(round(np.sqrt(count)))
    if k * k == count:
        gu, gv = np.meshgrid(np.arange(k), np.arange(k))
        u = (gu.ravel()[None, :] + rng.random((N, count))) / k
        v = (gv.ravel()[None, :] + rng.random((N, count))) / k
    else:
        u, v = rng.random((N, count)), rng.random((N, count))
    r = np.sqrt(u)
    phi = 2 * np.pi * v + rng.random((N, 1)) * 2 * np.pi
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1 - u, 1e-6))], axis=-1)
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    # Frisvad's orthonormal basis (branch on the sign of n_z).
    s = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (s + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t1 = np.stack([1 + s * n[:, 0] ** 2 * a, s * b, -s * n[:, 0]], axis=1)
    t2 = np.stack([b, s + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return (local[..., 0:1] * t1[:, None] + local[..., 1:2] * t2[:, None] + local[..., 2:3] * n[:, None])


class RayCaster:
    """Occlusion queries against a triangle mesh with Embree (embreex).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The terrain (or any triangle soup).
    """

    def __init__(self, mesh):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh
        V = np.asarray(mesh.vertices, dtype=np.float64)
        # Rays are traced in a frame centred on the mesh: float32 keeps its precision there.
        self.origin = V.mean(axis=0)
        self.scene = rtcore_scene.EmbreeScene()
        TriangleMesh(scene=self.scene, vertices=(V - self.origin).astype(np.float32),
                     indices=np.asarray(mesh.faces, dtype=np.int32))

    def _rays(self, origins, directions, max_distance):
        """Embree's arguments: float32 origins in the mesh's frame, directions, tfar."""
        o = (np.asarray(origins, dtype=np.float64) - self.origin).astype(np.float32)
        return o, np.asarray(directions, dtype=np.float32), np.full(len(o), np.float32(max_distance), dtype=np.float32)

    def hit_distance(self, origins, directions, max_distance):
        """Distance to the first hit along each ray, ``inf`` when it is farther than ``max_distance``."""
        o, d, dists = self._rays(origins, directions, max_distance)
        # A miss returns the ray's tfar unchanged: compare in float32, where it is exactly tfar.
        t = np.asarray(self.scene.run(o, d, dists=dists, query="DISTANCE"), dtype=np.float32)
        return np.where(t < np.float32(max_distance), t.astype(np.float64), np.inf)

    def first_hit(self, origins, directions, max_distance):
        """``(t, n)``: :meth:`hit_distance` and the unit normal of the triangle hit
        (``(N, 3)``, its winding's side; 0 on a miss)."""
        o, d, dists = self._rays(origins, directions, max_distance)
        out = self.scene.run(o, d, dists=dists, output=1)
        hit = np.asarray(out["primID"]) >= 0
        n = np.asarray(out["Ng"], dtype=np.float64)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
        return np.where(hit, np.asarray(out["tfar"], dtype=np.float64), np.inf), np.where(hit[:, None], n, 0.0)


def accessibility(mesh, points, normals, distance, rays=32, offset=None, seed=0, caster=None):
    """Openness ``alpha`` in ``[0, 1]`` of surface points (see module docstring).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Terrain mesh the rays are traced against.
    points : array_like
        ``(N, 3)`` points on (or very near) the surface.
    normals : array_like
        ``(N, 3)`` outward normals at the points.
    distance : float
        ``D``: a ray that travels this far without a hit escapes (metres).
    rays : int
        ``K`` directions per point.
    offset : float, optional
        Rays start this far along the normal, off the surface; default
        ``1e-3 D``.
    seed : int
        Seed of the stratified directions (same seed, same result).
    caster : RayCaster, optional
        A caster built on ``mesh`` (reused across calls).

    Returns
    -------
    numpy.ndarray
        ``(N,)`` fraction of the rays that escape.

    References
    ----------
    Miller, G. (1994). Efficient algorithms for local and global accessibility
    shading. SIGGRAPH '94.
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(P) == 0:
        return np.zeros(0)
    Nn = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    caster = caster or RayCaster(mesh)
    rng = np.random.default_rng(seed)
    W = hemisphere_directions(Nn, rays, rng)
    off = 1e-3 * distance if offset is None else float(offset)
    O = P + off * Nn / np.maximum(np.linalg.norm(Nn, axis=1, keepdims=True), 1e-12)
    O = np.repeat(O, rays, axis=0)
    hit = np.isfinite(caster.hit_distance(O, W.reshape(-1, 3), distance))
    return 1.0 - hit.reshape(len(P), rays).mean(axis=1)
