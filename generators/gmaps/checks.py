"""Geometric checks of an evolved map: volumes, closedness, self-intersections.

The topological validity of the map is :meth:`GMap.check`; these check what the
topology cannot: each volume's enclosed volume (to verify that displacements only
remove matter, paper §3.1) and that its boundary surface does not cross itself.
"""

from __future__ import annotations

import numpy as np

from .geometry import face_triangles, oriented_faces, signed_volume


def volumes_by_label(g) -> dict:
    """Enclosed volume (m³) per label, summed over the label's connected volumes."""
    out = {}
    for label, faces in oriented_faces(g):
        tris, _ = face_triangles(g, faces)
        out[label] = out.get(label, 0.0) + signed_volume(g.points, tris)
    return out


def self_intersections(mesh, tol: float = 1e-9) -> list[tuple[int, int]]:
    """Pairs (edge index, triangle index) where an edge of the mesh crosses a triangle.

    A triangle mesh intersects itself (beyond shared edges and vertices) exactly
    when some edge crosses the interior of a triangle that does not contain one
    of its end vertices (Möller's triangle–triangle test reduces to it for
    non-coplanar pairs). Touching at shared vertices is not a crossing; crossings
    are counted with a relative tolerance ``tol`` (interior only).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Vertices must be merged (shared ids on shared corners).

    Returns
    -------
    list of (int, int)
        Empty for a surface without self-intersection.
    """
    v = np.asarray(mesh.vertices, dtype=float)
    f = np.asarray(mesh.faces, dtype=np.int64)
    e = np.asarray(mesh.edges_unique, dtype=np.int64)
    scale = max(float(np.ptp(v, axis=0).max()), 1e-300)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    out = []
    for k in range(0, len(e), 256):
        ek = e[k:k + 256]
        p, q = v[ek[:, 0]][:, None], v[ek[:, 1]][:, None]           # (E,1,3)
        d = q - p
        e1, e2 = (b - a)[None], (c - a)[None]
        h = np.cross(d, e2)
        det = np.einsum("ijk,ijk->ij", np.broadcast_to(e1, h.shape), h)
        ok = np.abs(det) > 1e-14 * scale ** 3
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = p - a[None]
        u = inv * np.einsum("ijk,ijk->ij", s, h)
        qv = np.cross(s, np.broadcast_to(e1, s.shape))
        w = inv * np.einsum("ijk,ijk->ij", np.broadcast_to(d, qv.shape), qv)
        t = inv * np.einsum("ijk,ijk->ij", np.broadcast_to(e2, qv.shape), qv)
        hit = ok & (u > tol) & (w > tol) & (u + w < 1 - tol) & (t > tol) & (t < 1 - tol)
        shares = np.zeros_like(hit)
        for col in range(3):
            shares |= (f[None, :, col] == ek[:, 0:1]) | (f[None, :, col] == ek[:, 1:2])
        hit &= ~shares
        for i, j in zip(*np.nonzero(hit)):
            out.append((k + int(i), int(j)))
    return out


def map_mesh(g):
    """All volumes' triangles in one mesh over the map's vertex ids (shared corners merged).

    Volumes touching along sewn faces share vertices there, so
    :func:`self_intersections` of this mesh finds volumes that interpenetrate.
    """
    import trimesh
    tris = [face_triangles(g, faces)[0] for _, faces in oriented_faces(g)]
    return trimesh.Trimesh(g.points.copy(), np.concatenate(tris), process=False)
