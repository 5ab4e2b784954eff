"""Baking the triplanar material (and the field's normals) into UV-atlas textures.

For every texel centre ``(u, v)`` of the atlas the triangle covering it is found
by rasterizing the triangles in UV space (barycentric coordinates, numba); the
texel's surface point is ``p = sum_i lambda_i P_i`` and its normal the field's
``-grad f / |grad f|`` at ``p`` (finer than the mesh's interpolated normals).
The material is then evaluated at ``(p, n)`` exactly as the renderer shades it
(:meth:`TriplanarBSDF.albedo`: layer rules, masks and triplanar textures), so
the baked albedo is the renderer's diffuse reflectance. Albedo is stored
sRGB-encoded (8-bit colour); the normal map holds world-space normals as
``(n + 1) / 2`` (linear data). Texels outside every chart are filled from the
nearest covered texel (edge dilation), so that bilinear filtering and mipmaps
at chart borders do not fetch the background.

References
----------
Peytavie, A. et al. (2009). Arches, section 6 (triplanar texturing).
Pineda, J. (1988). A parallel algorithm for polygon rasterization. SIGGRAPH '88
(edge functions / barycentric coverage test).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..backend import variant
from ..imaging.preview import to_srgb8
from ..mesh.polygonize import default_voxel, field_normals
from .uv_atlas import UVMesh

__all__ = ["BakedTextures", "rasterize_uv", "bake_material"]


@dataclass
class BakedTextures:
    """``albedo`` (uint8 sRGB, ``(H, W, 3)``), ``normal`` (uint8 ``(n+1)/2``), ``coverage`` (bool)."""

    albedo: np.ndarray
    normal: np.ndarray
    coverage: np.ndarray


def _raster_kernel():
    import numba  # on use: slow to import, only baking needs it

    @numba.njit(cache=True)
    def raster(uv, faces, width, height, tri, bary):
        for f in range(faces.shape[0]):
            a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
            # Texel centres are at (i + 0.5, j + 0.5) in pixel units; row 0 is v = 1.
            ax, ay = uv[a, 0] * width, (1.0 - uv[a, 1]) * height
            bx, by = uv[b, 0] * width, (1.0 - uv[b, 1]) * height
            cx, cy = uv[c, 0] * width, (1.0 - uv[c, 1]) * height
            den = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy)
            if abs(den) < 1e-12:
                continue
            x0 = max(int(np.floor(min(ax, bx, cx))), 0)
            x1 = min(int(np.ceil(max(ax, bx, cx))), width - 1)
            y0 = max(int(np.floor(min(ay, by, cy))), 0)
            y1 = min(int(np.ceil(max(ay, by, cy))), height - 1)
            for j in range(y0, y1 + 1):
                py = j + 0.5
                for i in range(x0, x1 + 1):
                    px = i + 0.5
                    l0 = ((by - cy) * (px - cx) + (cx - bx) * (py - cy)) / den
                    l1 = ((cy - ay) * (px - cx) + (ax - cx) * (py - cy)) / den
                    l2 = 1.0 - l0 - l1
                    if l0 >= -1e-6 and l1 >= -1e-6 and l2 >= -1e-6:
                        tri[j, i] = f
                        bary[j, i, 0] = l0
                        bary[j, i, 1] = l1
                        bary[j, i, 2] = l2
    return raster


def rasterize_uv(mesh: UVMesh) -> tuple[np.ndarray, np.ndarray]:
    """Triangle index (-1: none) and barycentrics of every texel centre of the atlas.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        ``(H, W)`` int64 and ``(H, W, 3)`` float64.
    """
    h, w = mesh.height, mesh.width
    tri = np.full((h, w), -1, np.int64)
    bary = np.zeros((h, w, 3), np.float64)
    _raster_kernel()(mesh.uvs.astype(np.float64), mesh.faces.astype(np.int64), w, h, tri, bary)
    return tri, bary


def _dilate(img: np.ndarray, covered: np.ndarray) -> np.ndarray:
    from scipy.ndimage import distance_transform_edt  # on use, as numba above
    if covered.all() or not covered.any():
        return img
    _, (iy, ix) = distance_transform_edt(~covered, return_indices=True)
    return img[iy, ix]


def bake_material(mesh: UVMesh, bsdf, field=None) -> BakedTextures:
    """Bake a material's albedo and the surface normals into the mesh's atlas.

    Parameters
    ----------
    mesh : UVMesh
        Mesh with a UV atlas (:func:`arches_render.mesh.uv_atlas.uv_atlas`).
    bsdf : mi.BSDF
        A ``triplanar`` BSDF (its ``albedo``), or any BSDF with
        ``eval_diffuse_reflectance``.
    field : Node, optional
        The field the mesh was polygonized from: normals from its gradient where
        it has one (default, and where the field is flat: interpolated vertex normals).

    Returns
    -------
    BakedTextures

    References
    ----------
    See the module docstring.
    """
    variant()

    tri, bary = rasterize_uv(mesh)
    covered = tri >= 0
    idx = tri[covered]
    lam = bary[covered]
    faces = mesh.faces.astype(np.int64)[idx]
    p = np.einsum("nk,nkd->nd", lam, mesh.vertices.astype(np.float64)[faces])
    n = np.einsum("nk,nkd->nd", lam, mesh.normals.astype(np.float64)[faces])
    if field is not None:
        # The field's normal where it has one; where it lies flat (a clamped field next
        # to its surface, issue 38) the mesh's normal.
        g = field_normals(field, p, 0.05 * default_voxel(field)).astype(np.float64)
        n = np.where(np.linalg.norm(g, axis=1, keepdims=True) > 0.5, g, n)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-20)

    si = dr.zeros(mi.SurfaceInteraction3f, len(p))
    si.p = mi.Point3f(*(mi.Float(p[:, i].astype(np.float32)) for i in range(3)))
    nn = mi.Normal3f(*(mi.Float(n[:, i].astype(np.float32)) for i in range(3)))
    si.n = nn
    si.sh_frame = mi.Frame3f(nn)
    si.wi = mi.Vector3f(0.0, 0.0, 1.0)
    albedo_fn = getattr(bsdf, "albedo", None) or bsdf.eval_diffuse_reflectance
    a = mi.Color3f(albedo_fn(si, True))
    dr.eval(a)
    rgb = np.zeros(covered.shape + (3,), np.float32)
    rgb[covered] = np.stack([a.x.numpy(), a.y.numpy(), a.z.numpy()], axis=-1)
    nmap = np.zeros(covered.shape + (3,), np.float32)
    nmap[covered] = n
    rgb, nmap = _dilate(rgb, covered), _dilate(nmap, covered)
    normal8 = np.round(np.clip((nmap + 1.0) * 0.5, 0.0, 1.0) * 255.0).astype(np.uint8)
    return BakedTextures(albedo=to_srgb8(rgb), normal=normal8, coverage=covered)
