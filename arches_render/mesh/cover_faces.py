"""The boundary of a set of voxels as quads: a closed cover around the cells where a surface may be.

Given a boolean voxel mask (``(z, y, x)`` order) over a grid of edge ``h`` at ``lo``, the
faces between a voxel in the set and one outside it (or outside the grid) bound the
set exactly: each such face is emitted once, as two triangles, with the axis and sign
of its outward normal. A ray that starts outside the set enters it only through a
face whose outward normal faces the ray (``d . n < 0``), and leaves it through one
that does not, so a ray tracer over these triangles finds where a ray enters and
leaves the set without walking the voxels between.

Coplanar faces of the same orientation are merged into rectangles, row by row and
then across rows (greedy meshing), so flat stretches of the set's boundary cost two
triangles, not two a voxel.

References
----------
Lysenko, M. (2012). Meshing in a Minecraft game (greedy meshing of voxel faces).
Mitsuba 3, ``src/shapes/sdfgrid.cpp`` (the surface voxels of an SDF grid handed to a
ray tracer as boxes, an exact solve inside each).
"""

from __future__ import annotations

import numpy as np

__all__ = ["boundary_quads", "quads_to_triangles"]


def _rectangles(plane):
    """Greedy cover of the ``True`` cells of a 2-D boolean array by disjoint rectangles: a
    list of ``(row, col, rows, cols)``. Each run of a row still uncovered is grown down
    over the rows below while they are ``True`` along its whole length."""
    plane = plane.copy()
    out = []
    nr = plane.shape[0]
    for r in range(nr):
        row = plane[r]
        if not row.any():
            continue
        padded = np.concatenate(([False], row, [False]))
        edges = np.flatnonzero(padded[1:] != padded[:-1])
        for c0, c1 in zip(edges[::2], edges[1::2]):
            rows = 1
            while r + rows < nr and plane[r + rows, c0:c1].all():
                rows += 1
            plane[r:r + rows, c0:c1] = False
            out.append((r, c0, rows, c1 - c0))
    return out


def boundary_quads(mask, lo, h, merge=True, grow=0.0):
    """The faces of a voxel set's boundary.

    Parameters
    ----------
    mask : numpy.ndarray
        ``(nz, ny, nx)`` booleans: the voxels in the set.
    lo : array_like
        ``(x, y, z)`` of the grid's low corner.
    h : float
        Voxel edge.
    merge : bool
        Merge coplanar faces of one orientation into rectangles (module docstring).
    grow : float
        Each face is grown by this much past its edges, in its plane, so that faces
        that meet at an edge (or at a T-junction of merged rectangles) overlap: a ray
        tracer that is not watertight cannot slip between them.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        ``corners`` ``(Q, 4, 3)`` float64 (counter-clockwise seen from outside) and
        ``outward`` ``(Q,)`` uint8: ``2 axis + (normal along +axis)``, axis 0 = x.
    """
    mask = np.asarray(mask, dtype=bool)
    lo = np.asarray(lo, dtype=np.float64)
    corners, outward = [], []
    for axis in range(3):
        a = 2 - axis  # array axis of this world axis
        pad = [(0, 0)] * 3
        pad[a] = (1, 1)
        m = np.pad(mask, pad)
        lower = np.take(m, np.arange(m.shape[a] - 1), axis=a)
        upper = np.take(m, np.arange(1, m.shape[a]), axis=a)
        for sign, faces in ((1, lower & ~upper), (0, upper & ~lower)):
            # faces[..., k, ...] is the face at world coordinate lo + k h along `axis`.
            faces = np.moveaxis(faces, a, 0)  # (k, u, v) with (u, v) the other array axes
            # World axes of the plane's rows and columns (array order z, y, x).
            u_axis, v_axis = [ax for ax in (2, 1, 0) if ax != axis]
            for k in np.flatnonzero(faces.reshape(len(faces), -1).any(axis=1)):
                plane = faces[k]
                rects = _rectangles(plane) if merge else [(r, c, 1, 1) for r, c in np.argwhere(plane)]
                for r, c, nr, nc in rects:
                    q = np.zeros((4, 3))
                    q[:, axis] = lo[axis] + k * h
                    u0, u1 = lo[u_axis] + r * h - grow, lo[u_axis] + (r + nr) * h + grow
                    v0, v1 = lo[v_axis] + c * h - grow, lo[v_axis] + (c + nc) * h + grow
                    q[:, u_axis] = (u0, u0, u1, u1)
                    q[:, v_axis] = (v0, v1, v1, v0)
                    corners.append(q)
                    outward.append(2 * axis + sign)
    if not corners:
        return np.zeros((0, 4, 3)), np.zeros(0, dtype=np.uint8)
    return np.asarray(corners), np.asarray(outward, dtype=np.uint8)


def quads_to_triangles(corners):
    """``(vertices (4Q, 3) float32, faces (2Q, 3) uint32)`` of quads ``(Q, 4, 3)``; each
    quad's two triangles are faces ``2 q`` and ``2 q + 1``."""
    q = len(corners)
    vertices = np.ascontiguousarray(corners.reshape(-1, 3), dtype=np.float32)
    base = 4 * np.arange(q, dtype=np.uint32)[:, None]
    faces = np.concatenate([base + np.array([0, 1, 2], np.uint32), base + np.array([0, 2, 3], np.uint32)], axis=1)
    return vertices, faces.reshape(-1, 3)
