"""Dense polygonization of a field by marching cubes (scikit-image).

The field is sampled on a regular grid covering its bounds plus one voxel, and
``skimage.measure.marching_cubes`` extracts the level set ``f = 0``. Vertex normals
come from the field gradient (``-grad f``, outward), and faces are wound so that
their geometric normals agree with them: Mitsuba's ``diffuse`` is one-sided.

References
----------
Lorensen, W. E., Cline, H. E. (1987). Marching cubes. SIGGRAPH '87.
Lewiner, T. et al. (2003). Efficient implementation of marching cubes' cases with
topological guarantees. Journal of Graphics Tools 8(2) (scikit-image's variant).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..field import Node, evaluate


@dataclass
class TriangleMesh:
    """Plain arrays: ``vertices (N, 3)``, ``faces (M, 3)``, ``normals (N, 3)``."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray

    def to_trimesh(self):
        import trimesh
        return trimesh.Trimesh(self.vertices, self.faces, vertex_normals=self.normals, process=False)


def default_voxel(node: Node, cells: int = 256) -> float:
    """Voxel edge giving about ``cells`` cells along the longest side of the bounds."""
    lo, hi = node.bounds()
    return float(np.max(hi - lo)) / cells


def field_normals(node: Node, points: np.ndarray, h: float) -> np.ndarray:
    """Outward unit normals ``-grad f / |grad f|`` at numpy points (central differences)."""
    g = np.zeros_like(points, dtype=np.float64)
    for axis in range(3):
        d = np.zeros(3)
        d[axis] = h
        g[:, axis] = evaluate(node, points + d) - evaluate(node, points - d)
    g = -g
    n = np.linalg.norm(g, axis=1, keepdims=True)
    return (g / np.maximum(n, 1e-20)).astype(np.float32)


def sample_grid(node: Node, voxel: float, progress=None):
    """Sample the field on the grid covering its bounds grown by one voxel.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        The ``(nx, ny, nz)`` values and the grid origin.
    """
    lo, hi = node.bounds()
    lo, hi = lo - voxel, hi + voxel
    shape = np.ceil((hi - lo) / voxel).astype(int) + 1
    if np.prod(shape) > 600_000_000:
        raise ValueError(f"voxel {voxel:g} m gives a {shape.tolist()} grid: too large, use a larger voxel")
    xs, ys = (lo[i] + voxel * np.arange(shape[i]) for i in range(2))
    vol = np.empty(shape, dtype=np.float32)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    # Slabs of z keep each Dr.Jit launch bounded in memory.
    for k in range(shape[2]):
        z = lo[2] + voxel * k
        pts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], axis=1)
        vol[:, :, k] = evaluate(node, pts).reshape(X.shape)
        if progress:
            progress(k + 1, shape[2])
    return vol, lo


def polygonize(node: Node, voxel: float | None = None, progress=None) -> TriangleMesh:
    """Marching-cubes mesh of the surface ``f = 0``.

    Parameters
    ----------
    node : Node
        Bounded field.
    voxel : float, optional
        Grid spacing in metres (default :func:`default_voxel`).
    progress : callable, optional
        ``progress(done, total)`` over sampled slabs.

    Returns
    -------
    TriangleMesh
    """
    from skimage.measure import marching_cubes

    voxel = float(voxel) if voxel else default_voxel(node)
    vol, origin = sample_grid(node, voxel, progress)
    if not (vol.max() > 0 > vol.min()):
        raise ValueError("the field has no surface inside its bounds at this voxel size")
    verts, faces, _, _ = marching_cubes(vol, level=0.0, spacing=(voxel,) * 3)
    verts = (verts + origin).astype(np.float32)
    normals = field_normals(node, verts.astype(np.float64), 0.25 * voxel)
    faces = faces.astype(np.int64)
    a, b, c = (verts[faces[:, i]] for i in range(3))
    geo = np.cross(b - a, c - a)
    flip = np.einsum("ij,ij->i", geo, normals[faces].sum(axis=1)) < 0
    faces[flip] = faces[flip][:, ::-1]
    return TriangleMesh(verts, faces.astype(np.uint32), normals)


def export_mesh(mesh: TriangleMesh, path) -> None:
    """Write a mesh as PLY, OBJ or GLB (format from the extension), atomically."""
    from pathlib import Path

    from ..atomic import atomic_write
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in ("ply", "obj", "glb"):
        raise ValueError(f"{path}: unsupported mesh format '.{fmt}' (use .ply, .obj or .glb)")
    data = mesh.to_trimesh().export(file_type=fmt)
    if isinstance(data, str):
        data = data.encode()
    with atomic_write(path) as f:
        f.write(data)
