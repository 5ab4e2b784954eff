"""Chunked polygonization of large fields, with welded seams.

The field's sampling grid (origin ``o = lo - voxel``, spacing ``voxel``, the grid of
:func:`arches_render.mesh.polygonize.sample_grid`) is cut into chunks of ``n``
cells along X and Y; neighbouring chunks *share* their boundary plane of samples
(chunk ``i`` spans grid indices ``[i n, (i + 1) n]``). Marching cubes places a
vertex on a shared face from that face's two samples only, so both chunks create
the same vertices there. To make them the same *bits*, each chunk runs marching
cubes in index units and its vertices become world positions by one formula for
every chunk, ``x = o + (i0 + x_local) voxel`` (``i0 + x_local`` is exact: an integer
plus the chunk's own fraction). Seams are therefore welded: no cracks, no
T-junctions, and merging the chunks by exact vertex position restores the
single-piece mesh. Only one chunk's samples are in memory at a time.

Blocks proven free of surface are filled with ``+-voxel`` as in
:mod:`~arches_render.mesh.polygonize`; every cube edge crossing the surface joins
two exactly sampled voxels in both chunks, so the certification does not break
the seams.

References
----------
Lorensen, W. E., Cline, H. E. (1987). Marching cubes. SIGGRAPH '87.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..field import Node
from .polygonize import PolygonizeError, TriangleMesh, default_voxel, oriented_mesh, sample_blocks

__all__ = ["Chunk", "polygonize_chunks", "chunk_ranges"]


@dataclass
class Chunk:
    """One piece: its mesh and its grid index ``(ix, iy)``."""

    index: tuple
    mesh: TriangleMesh


def chunk_ranges(n_points: int, cells: int) -> list[tuple[int, int]]:
    """Inclusive index ranges ``[a, b]`` of ``cells`` cells sharing end points, covering ``n_points``."""
    out, a = [], 0
    while a < n_points - 1:
        b = min(a + cells, n_points - 1)
        out.append((a, b))
        a = b
    return out


def polygonize_chunks(node: Node, voxel: float | None = None, chunk_cells: int = 128,
                      progress=None) -> list[Chunk]:
    """Marching-cubes meshes of the field in XY chunks with welded seams.

    Parameters
    ----------
    node : Node
        Bounded field.
    voxel : float, optional
        Grid spacing (default :func:`~arches_render.mesh.polygonize.default_voxel`).
    chunk_cells : int
        Cells per chunk along X and Y (Z is not cut).
    progress : callable, optional
        ``progress(done, total)`` over chunks.

    Returns
    -------
    list of Chunk
        Non-empty chunks, row-major.
    """
    from skimage.measure import marching_cubes  # on use: slow to import (the CLI loads this module)
    voxel = float(voxel) if voxel else default_voxel(node)
    lo, hi = node.bounds()
    origin = np.asarray(lo, np.float64) - voxel
    shape = np.ceil((np.asarray(hi) + voxel - origin) / voxel).astype(int) + 1
    xs, ys = chunk_ranges(shape[0], chunk_cells), chunk_ranges(shape[1], chunk_cells)
    chunks, done = [], 0
    for iy, (y0, y1) in enumerate(ys):
        for ix, (x0, x1) in enumerate(xs):
            start = np.array([x0, y0, 0])
            vol = sample_blocks(node, origin, voxel, start, (x1 - x0 + 1, y1 - y0 + 1, shape[2]))
            done += 1
            if progress:
                progress(done, len(xs) * len(ys))
            if not (vol.max() > 0 > vol.min()):
                continue
            v, f, _, _ = marching_cubes(vol, level=0.0, spacing=(1.0, 1.0, 1.0))
            verts = (origin + (v.astype(np.float64) + start) * voxel).astype(np.float32)
            chunks.append(Chunk((ix, iy), oriented_mesh(node, verts, f, voxel)))
    if not chunks:
        raise PolygonizeError(f"the field has no surface inside its bounds at voxel {voxel:g} m")
    return chunks
