"""Dense polygonization of a field by marching cubes (scikit-image).

The field is sampled on a regular grid covering its bounds plus one voxel, and
``skimage.measure.marching_cubes`` extracts the level set ``f = 0``. Only blocks of
16^3 voxels that may hold surface are sampled: at a block's centre, the field's
rigorous distance bound (``Node.eval_bounds``) or Hart's bound inside matter
proves whether the surface stays farther than the block's half-diagonal plus one
voxel; such a block is filled with a constant of the right sign, and since no
surface lies within a voxel of it, every cube edge that the surface crosses joins
two exactly sampled voxels. The mesh is therefore the dense mesh of the grid. Vertex normals
come from the field gradient (``-grad f``, outward), and the mesh is wound so that
its faces look the same way: Mitsuba's ``diffuse`` is one-sided. Where the field is
flat at a vertex (no gradient: a clamped field such as the ``blocks`` node's margin
lies flat next to a surface that rises within one voxel, and marching cubes puts
the vertex on the flat side), the vertex takes the area-weighted normal of its faces
instead (:func:`oriented_mesh`): a zero normal made Mitsuba's interpolated shading
normal NaN on every face whose three vertices had one (issue 38).

References
----------
Lorensen, W. E., Cline, H. E. (1987). Marching cubes. SIGGRAPH '87.
Lewiner, T. et al. (2003). Efficient implementation of marching cubes' cases with
topological guarantees. Journal of Graphics Tools 8(2) (scikit-image's variant).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

from ..atomic import atomic_write
from ..backend import variant
from ..field import Node, evaluate
from ..field.node import jit_points


@dataclass
class TriangleMesh:
    """Plain arrays: ``vertices (N, 3)``, ``faces (M, 3)``, ``normals (N, 3)``."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray

    def to_trimesh(self):
        import trimesh  # on use: slow to import, only export needs it
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


BLOCK = 16
MAX_VOXELS = 400_000_000


class PolygonizeError(ValueError):
    """The field cannot be polygonized at this voxel size (no surface, or too many voxels).

    A mistake of the user's (scene or voxel size), which commands report in one line.
    """


def classify_blocks(node: Node, lo, voxel, nblocks):
    """Per block: 0 = may hold surface, -1 = certainly air, +1 = certainly matter."""
    variant()
    idx = np.stack(np.meshgrid(*(np.arange(n) for n in nblocks), indexing="ij"), -1).reshape(-1, 3)
    centres = lo + (idx * BLOCK + (BLOCK - 1) / 2.0) * voxel
    # Certify a ball of the block's half-diagonal plus one voxel.
    radius = (np.sqrt(3.0) * (BLOCK - 1) / 2.0 + np.sqrt(3.0)) * voxel
    p = jit_points(centres)
    f, (d,) = node.eval_bounds(p, (0.0,))
    dr.eval(f, d)
    f, d = f.numpy(), d.numpy()
    state = np.zeros(len(idx), dtype=np.int8)
    state[d > radius] = -1
    state[f / node.lipschitz > radius] = 1
    return state.reshape(tuple(nblocks))


def sample_grid(node: Node, voxel: float, progress=None):
    """Sample the field on the grid covering its bounds grown by one voxel.

    Blocks proven free of surface are filled with ``-voxel`` (air) or ``+voxel``
    (matter) instead of being sampled (see module docstring).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        The ``(nx, ny, nz)`` values and the grid origin.
    """
    lo, hi = node.bounds()
    lo, hi = lo - voxel, hi + voxel
    shape = np.ceil((hi - lo) / voxel).astype(int) + 1
    if np.prod(shape) > MAX_VOXELS:
        raise PolygonizeError(f"voxel {voxel:g} m gives a {shape.tolist()} grid ({np.prod(shape):.3g} voxels, "
                         f"at most {MAX_VOXELS:.3g}): use a larger voxel")
    return sample_blocks(node, lo, voxel, (0, 0, 0), shape, progress), lo


def sample_blocks(node: Node, origin, voxel: float, start, shape, progress=None) -> np.ndarray:
    """Field values at grid indices ``start + [0, shape)`` of the grid ``origin + index voxel``.

    Blocks of ``BLOCK``³ samples that :func:`classify_blocks` proves free of
    surface are filled with ``-voxel`` (air) or ``+voxel`` (matter); the others are
    evaluated. A sample's position is ``origin + (start + i) voxel`` in float64 rounded
    to float32, whatever the part of the grid asked: a whole grid and its chunks give
    the same bits at the same index (:mod:`.chunks`).

    Parameters
    ----------
    node : Node
    origin : array_like
        Position of grid index ``(0, 0, 0)``.
    voxel : float
    start, shape : sequence of 3 ints
        First index and size of the part sampled.
    progress : callable, optional
        ``progress(done, total)`` over the candidate blocks.

    Returns
    -------
    numpy.ndarray
        ``shape`` float32 values.
    """
    origin = np.asarray(origin, np.float64)
    start, shape = np.asarray(start, np.int64), np.asarray(shape, np.int64)
    nblocks = -(-shape // BLOCK)
    state = classify_blocks(node, origin + start * voxel, voxel, nblocks)
    vol = np.empty(tuple(shape), dtype=np.float32)
    for bi, bj, bk in np.argwhere(state != 0):
        vol[bi * BLOCK:(bi + 1) * BLOCK, bj * BLOCK:(bj + 1) * BLOCK,
            bk * BLOCK:(bk + 1) * BLOCK] = state[bi, bj, bk] * voxel
    # Sample the candidate blocks in batches of whole blocks, block by block: points
    # (block, i, j, k) built per axis and values written back as one slab per block
    # (with flat index arrays and a fancy-indexed write, bookkeeping took 3-6 times
    # as long as evaluating the field). A block's samples past the far faces are
    # evaluated too and dropped.
    todo = np.argwhere(state == 0)
    local = np.arange(BLOCK)
    axes = ((slice(None), slice(None), None, None), (slice(None), None, slice(None), None),
            (slice(None), None, None, slice(None)))
    per_batch = max(1, (1 << 21) // BLOCK ** 3)
    for first in range(0, len(todo), per_batch):
        blocks = todo[first:first + per_batch]
        pts = np.empty((len(blocks), BLOCK, BLOCK, BLOCK, 3), np.float32)
        for axis, where in enumerate(axes):
            index = start[axis] + blocks[:, axis, None] * BLOCK + local
            pts[..., axis] = (origin[axis] + index * voxel)[where]
        vals = evaluate(node, pts.reshape(-1, 3)).reshape(len(blocks), BLOCK, BLOCK, BLOCK)
        for (bi, bj, bk), v in zip(blocks, vals):
            dst = vol[bi * BLOCK:(bi + 1) * BLOCK, bj * BLOCK:(bj + 1) * BLOCK, bk * BLOCK:(bk + 1) * BLOCK]
            dst[...] = v[:dst.shape[0], :dst.shape[1], :dst.shape[2]]
        if progress:
            progress(min(first + per_batch, len(todo)), len(todo))
    return vol



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

    Raises
    ------
    PolygonizeError
        When the grid would exceed :data:`MAX_VOXELS` or holds no surface.
    """
    from skimage.measure import marching_cubes  # on use: slow to import (the CLI loads this module)

    voxel = float(voxel) if voxel else default_voxel(node)
    vol, origin = sample_grid(node, voxel, progress)
    if not (vol.max() > 0 > vol.min()):
        raise PolygonizeError(f"the field has no surface inside its bounds at voxel {voxel:g} m")
    verts, faces, _, _ = marching_cubes(vol, level=0.0, spacing=(voxel,) * 3)
    return oriented_mesh(node, (verts + origin).astype(np.float32), faces, voxel)


def oriented_mesh(node: Node, verts: np.ndarray, faces: np.ndarray, voxel: float) -> TriangleMesh:
    """A marching-cubes mesh of ``node`` with its vertex normals and one outward winding.

    Parameters
    ----------
    node : Node
        The field the mesh was extracted from.
    verts : numpy.ndarray
        ``(N, 3)`` float32 vertices (world space).
    faces : numpy.ndarray
        ``(M, 3)`` vertex indices, consistently wound (scikit-image's output).
    voxel : float
        The grid's voxel edge (the gradient's step is a quarter of it).

    Returns
    -------
    TriangleMesh
        Normals ``-grad f / |grad f|``, or where that is flat or faces away from
        the vertex's faces the area-weighted normal of its faces
        (:func:`shading_normals`); faces wound to agree with the normals.
    """
    normals = field_normals(node, verts.astype(np.float64), 0.25 * voxel)
    faces = np.asarray(faces, np.int64)
    # scikit-image winds all faces consistently; orient the whole mesh once by
    # the field normals (a per-face vote would flip slivers at random).
    a, b, c = (verts[faces[:, i]].astype(np.float64) for i in range(3))
    geo = np.cross(b - a, c - a)
    if np.einsum("ij,ij->", geo, normals[faces].sum(axis=1)) < 0:
        faces, geo = faces[:, ::-1], -geo
    return TriangleMesh(verts, faces.astype(np.uint32), shading_normals(normals, faces, geo))


def shading_normals(normals: np.ndarray, faces: np.ndarray, face_normals: np.ndarray) -> np.ndarray:
    """Unit vertex normals a renderer can shade with: the field's, except where they are
    unusable, replaced by the sum of the vertex's faces' area-weighted normals.

    Unusable: zero or NaN (the field is flat there), or facing away from the vertex's
    faces (``n . sum A_f n_f <= 0``). The second happens at features smaller than the
    voxel (a river undercut on a 20 m grid): the field's gradient at the vertex sees
    the feature, the coarse faces around it do not, and a shading normal on the other
    side of the surface from its geometric normal renders black (Mitsuba's BSDFs
    return nothing below the shading frame's horizon).

    Parameters
    ----------
    normals : numpy.ndarray
        ``(N, 3)`` vertex normals, unit or zero.
    faces : numpy.ndarray
        ``(M, 3)`` vertex indices.
    face_normals : numpy.ndarray
        ``(M, 3)`` ``(b - a) x (c - a)`` of each face, wound as the mesh.

    Returns
    -------
    numpy.ndarray
        ``(N, 3)`` float32 unit normals (+z for a vertex whose faces' normals cancel).
    """
    n = len(normals)
    # (bincount: np.add.at takes ~100 ns an entry, 0.6 s on a 2M-face mesh)
    acc = np.stack([sum(np.bincount(faces[:, k], weights=face_normals[:, c], minlength=n) for k in range(3))
                    for c in range(3)], axis=1)
    with np.errstate(invalid="ignore"):  # (a NaN normal fails both tests)
        usable = (np.linalg.norm(normals, axis=1) > 0.5) & (np.einsum("ij,ij->i", normals, acc) > 0)
    if usable.all():
        return normals
    out = np.array(normals, np.float32)
    acc = acc[~usable]
    length = np.linalg.norm(acc, axis=1)
    # Faces that cancel, or are all degenerate: any unit normal beats a NaN shading frame.
    none = ~(length > 0)
    acc[none], length[none] = (0.0, 0.0, 1.0), 1.0
    out[~usable] = acc / length[:, None]
    return out


def export_mesh(mesh: TriangleMesh, path) -> None:
    """Write a mesh as PLY, OBJ or GLB (format from the extension), atomically."""
    from pathlib import Path

    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in ("ply", "obj", "glb"):
        raise ValueError(f"{path}: unsupported mesh format '.{fmt}' (use .ply, .obj or .glb)")
    data = mesh.to_trimesh().export(file_type=fmt)
    if isinstance(data, str):
        data = data.encode()
    with atomic_write(path) as f:
        f.write(data)
