"""Geometry on a 3-G-map: oriented faces, polygon triangulation, segment–face tests.

* :func:`oriented_faces` orients each volume's boundary (a G-map is not oriented:
  the two darts of a corner give the two orientations; a 2-colouring of the
  volume's darts by the parity of the α0/α1/α2 path picks one) and flips it so the
  enclosed volume is positive (outward normals).
* :func:`triangulate_polygon` ear-clips a planar polygon, including the weakly
  simple polygons of holed faces whose hole is joined to the border by a bridge
  edge (paper Fig. 6: the bridge vertices appear twice in the cycle).
* :func:`first_hit` intersects a displacement segment with triangles, with the
  symbolic perturbation of paper §3.1: a hit exactly on an edge or vertex of the
  triangulation is assigned to exactly one triangle, as if the segment were moved
  by an infinitesimal generic offset ``ε (1, ε, ε²)``.
"""

from __future__ import annotations

import numpy as np

from .gmap import VOLUME, GMap, GMapError

EPS_REL = 1e-10
PERTURB = np.array([1.0, 1e-3, 1e-6])   # generic direction of the symbolic offset


def newell_normal(pts: np.ndarray) -> np.ndarray:
    """Area-weighted normal of a polygon (Newell's method); length = 2 × area."""
    p = np.asarray(pts, dtype=float)
    q = np.concatenate([p[1:], p[:1]])
    d, s = p - q, p + q
    return np.array([d[:, 1] @ s[:, 2], d[:, 2] @ s[:, 0], d[:, 0] @ s[:, 1]])


def project(pts, normal):
    """2-D coordinates of points in a plane of normal ``normal`` (right-handed basis)."""
    nx, ny, nz = (float(c) for c in normal)
    ln = (nx * nx + ny * ny + nz * nz) ** 0.5 or 1.0
    nx, ny, nz = nx / ln, ny / ln, nz / ln
    # u = n x (1,0,0) or n x (0,1,0); v = n x u
    if abs(nx) < 0.9:
        ux, uy, uz = 0.0, nz, -ny
    else:
        ux, uy, uz = -nz, 0.0, nx
    lu = (ux * ux + uy * uy + uz * uz) ** 0.5
    ux, uy, uz = ux / lu, uy / lu, uz / lu
    vx, vy, vz = ny * uz - nz * uy, nz * ux - nx * uz, nx * uy - ny * ux
    pts = np.asarray(pts, dtype=float)
    return pts @ np.array([[ux, vx], [uy, vy], [uz, vz]])


def triangulate_polygon(pts: np.ndarray, ids=None) -> list[tuple[int, int, int]]:
    """Triangles (local indices, same orientation) of a planar polygon by ear clipping.

    Parameters
    ----------
    pts : ndarray, shape (n, 3)
        Polygon corners in order (weakly simple: repeated vertices allowed).
    ids : sequence of int, optional
        Vertex ids; corners with the id of an ear corner never block that ear.

    Returns
    -------
    list of (i, j, k)
        ``n - 2`` triangles; every corner is used (no T-junctions).
    """
    n = len(pts)
    if n < 3:
        raise GMapError("a face needs three corners")
    ids = list(range(n)) if ids is None else list(ids)
    nrm = newell_normal(pts)
    if not np.linalg.norm(nrm) > 0:
        raise GMapError("degenerate (zero-area) face")
    xy = project(pts, nrm)
    scale = np.ptp(xy, axis=0).max() or 1.0
    eps = 1e-12 * scale * scale
    idx = list(range(n))
    tris = []

    def cross(a, b, c):
        return (xy[b, 0] - xy[a, 0]) * (xy[c, 1] - xy[a, 1]) - (xy[b, 1] - xy[a, 1]) * (xy[c, 0] - xy[a, 0])

    def inside(p, a, b, c):
        return cross(a, b, p) >= -eps and cross(b, c, p) >= -eps and cross(c, a, p) >= -eps

    while len(idx) > 3:
        m = len(idx)
        best = None
        for t in range(m):
            a, b, c = idx[t - 1], idx[t], idx[(t + 1) % m]
            area = cross(a, b, c)
            if area <= eps:
                continue
            corners = {ids[a], ids[b], ids[c]}
            blocked = False
            for q in idx:
                if ids[q] in corners:
                    continue
                if inside(q, a, b, c):
                    blocked = True
                    break
            if not blocked:
                best = t
                break
        if best is None:
            raise GMapError("face polygon is not simple (no ear found)")
        a, b, c = idx[best - 1], idx[best], idx[(best + 1) % len(idx)]
        tris.append((a, b, c))
        idx.pop(best)
    tris.append(tuple(idx))
    return tris


def volume_orientation(g: GMap, d: int) -> dict:
    """Parity (0/1) of every dart of the volume of ``d`` (α0, α1, α2 flip it)."""
    par = {d: 0}
    stack = [d]
    while stack:
        x = stack.pop()
        for i in VOLUME:
            y = g.a(i, x)
            if y not in par:
                par[y] = 1 - par[x]
                stack.append(y)
            elif par[y] == par[x]:
                raise GMapError(f"volume of dart {d} is not orientable")
    return par


def oriented_faces(g: GMap, label: int | None = None):
    """Faces of each volume as outward-oriented vertex-id cycles.

    Returns
    -------
    list of (label, [(face_dart, [vertex ids])...])
        One entry per volume (⟨α0, α1, α2⟩ orbit), optionally only label ``label``.
    """
    out = []
    done = np.zeros(g.capacity, dtype=bool)
    pts = g.points
    for d0 in g.darts():
        d0 = int(d0)
        if done[d0] or (label is not None and g.volume(d0) != label):
            continue
        par = volume_orientation(g, d0)
        done[list(par)] = True
        faces, seen = [], set()
        for d, s in par.items():
            if s or d in seen:
                continue
            cyc = g.face_cycle(d)
            seen.update(cyc)
            faces.append((d, [g.vertex(x) for x in cyc[0::2]]))
        vol = 0.0
        for _, f in faces:
            p = pts[f]
            vol += np.dot(p[0], newell_normal(p)) / 6.0
        if vol < 0:
            faces = [(d, f[::-1]) for d, f in faces]
        out.append((g.volume(d0), faces))
    return out


def face_triangles(g: GMap, faces) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (vertex ids, shape (m, 3)) and their face darts from oriented faces."""
    tris, owner = [], []
    pts = g.points
    for d, f in faces:
        if len(f) == 3:
            tris.append(f)
            owner.append(d)
            continue
        for a, b, c in triangulate_polygon(pts[f], f):
            tris.append([f[a], f[b], f[c]])
            owner.append(d)
    return np.asarray(tris, dtype=np.int64).reshape(-1, 3), np.asarray(owner, dtype=np.int64)


def signed_volume(pts, tris) -> float:
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def winding_number(pts, tris, q) -> float:
    """Generalized winding number of point ``q`` w.r.t. a closed triangle mesh."""
    a, b, c = pts[tris[:, 0]] - q, pts[tris[:, 1]] - q, pts[tris[:, 2]] - q
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la \
        + np.einsum("ij,ij->i", c, a) * lb
    return float(np.sum(2 * np.arctan2(det, den)) / (4 * np.pi))


def _perturbed_positive(value, grad):
    """Sign of ``value + ε grad·PERTURB`` for infinitesimal ε (SoS-style tie-break)."""
    if value != 0.0:
        return value > 0
    for k in range(3):
        if grad[k] != 0.0:
            return grad[k] > 0
    return False


def first_hit(p0, p1, pts, tris, skip_vertex=None):
    """Earliest crossing of segment ``p0 → p1`` with the triangles.

    Triangles incident to vertex ``skip_vertex`` are ignored (they move with it).
    Barycentric coordinates that vanish exactly are decided by the symbolic
    perturbation (paper §3.1), so a segment through a shared edge hits exactly
    one of the triangles.

    Returns
    -------
    (t, k, point) or None
        Parameter in (0, 1], triangle index and hit point.
    """
    if len(tris) == 0:
        return None
    d = p1 - p0
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    e1, e2 = b - a, c - a
    n = np.cross(e1, e2)
    denom = n @ d
    scale = max(np.abs(pts).max(), 1.0)
    s = p0 - a
    t = np.einsum("ij,ij->i", n, -s) / np.where(denom == 0, np.inf, denom)
    ok = (denom != 0) & (t > 1e-12) & (t <= 1.0 + 1e-12)
    if skip_vertex is not None:
        ok &= ~np.any(tris == skip_vertex, axis=1)
    best = None
    for k in np.flatnonzero(ok):
        x = p0 + t[k] * d
        # barycentrics via areas in the triangle plane
        nk = n[k]
        nn = nk @ nk
        w = []
        for (u, v) in ((b[k], c[k]), (c[k], a[k]), (a[k], b[k])):
            w.append(np.cross(v - u, x - u) @ nk / nn)
        inside = True
        for m, (u, v) in enumerate(((b[k], c[k]), (c[k], a[k]), (a[k], b[k]))):
            val = w[m] if abs(w[m]) > 1e-12 * scale else 0.0
            if val < 0:
                inside = False
                break
            if val == 0.0:
                # gradient of the barycentric w.r.t. the hit point, along the plane
                grad = np.cross(nk, v - u) / nn
                if not _perturbed_positive(0.0, grad):
                    inside = False
                    break
        if inside and (best is None or t[k] < best[0]):
            best = (float(t[k]), int(k), x)
    return best
