"""Plain-array operations on triangle meshes: merged vertices, face and vertex normals, areas.

The far field's ground and sea meshes are built in every render process of a
landscape; trimesh did these three things for them and cost 0.5 s to import
(networkx, scipy.optimize) in each of those processes, a twentieth of the default
scene's render. They are a few lines of numpy each, so they are written here;
trimesh remains the library for mesh files and export (:mod:`.polygonize`,
:mod:`.textured`).

Vertex normals are angle-weighted (Thürrner and Wüthrich 1998), as trimesh's are:
each face adds its unit normal times its corner angle at the vertex, and the sum is
normalized, so a vertex's normal does not depend on how the faces around it are cut.

References
----------
Thürrner, G., Wüthrich, C. A. (1998). Computing vertex normals from polygonal facets.
Journal of Graphics Tools 3(1), 43-46.
"""

from __future__ import annotations

import numpy as np

__all__ = ["merged_vertices", "face_normals", "face_areas", "vertex_normals"]


def merged_vertices(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices equal in all three coordinates made one; unreferenced vertices dropped.

    Parameters
    ----------
    vertices : numpy.ndarray
        ``(N, 3)`` positions.
    faces : numpy.ndarray
        ``(M, 3)`` vertex indices.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        The distinct referenced vertices (sorted lexicographically) and the faces on them.
    """
    vertices, faces = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    used = np.zeros(len(vertices), bool)
    used[faces] = True
    kept = np.nonzero(used)[0]
    v = vertices[kept]
    order = np.lexsort(v.T[::-1])  # by x, then y, then z
    s = v[order]
    new = np.r_[True, np.any(s[1:] != s[:-1], axis=1)]
    remap = np.full(len(vertices), -1, np.int64)
    remap[kept[order]] = np.cumsum(new) - 1
    return s[new], remap[faces]


def _cross(vertices, faces):
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return np.cross(b - a, c - a)


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(M, 3)`` unit normals ``(b - a) x (c - a)`` of the faces, zero for degenerate ones."""
    n = _cross(np.asarray(vertices, np.float64), np.asarray(faces, np.int64))
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0.0)


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(M,)`` areas of the faces."""
    return 0.5 * np.linalg.norm(_cross(np.asarray(vertices, np.float64), np.asarray(faces, np.int64)), axis=1)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(N, 3)`` angle-weighted unit vertex normals (module docstring); zero at vertices no
    non-degenerate face uses."""
    vertices, faces = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    fn = face_normals(vertices, faces)
    corners = vertices[faces]  # (M, 3, 3)
    summed = np.zeros_like(vertices)
    for k in range(3):
        u = corners[:, (k + 1) % 3] - corners[:, k]
        v = corners[:, (k + 2) % 3] - corners[:, k]
        cos = np.einsum("ij,ij->i", u, v) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1), 1e-300)
        weighted = fn * np.arccos(np.clip(cos, -1.0, 1.0))[:, None]
        for axis in range(3):
            summed[:, axis] += np.bincount(faces[:, k], weights=weighted[:, axis], minlength=len(vertices))
    length = np.linalg.norm(summed, axis=1, keepdims=True)
    return np.divide(summed, length, out=np.zeros_like(summed), where=length > 0.0)
