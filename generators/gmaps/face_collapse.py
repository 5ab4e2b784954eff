"""A vertex reaching a face it is joined to by edges (paper §3.4 Fig. 7b/c, §3.5 Fig. 8).

When vertex P of volume V lands at point Y inside face F of V and P is joined by
edges to two consecutive corners Q_i, Q_{i+1} of F, the triangle (P, Q_i, Q_{i+1})
lies flat on F: the matter between them is gone. :func:`vertex_face_collapse`

1. stars F from a new vertex X at Y (cell insertion: an edge from X to every
   corner, :func:`star_face`), so F's triangle (X, Q_i, Q_{i+1}) lies under the
   flattened triangle;
2. removes every such pair of coincident triangles, gluing (α2) the faces beyond
   their matching edges, and merges P with X;
3. checks whether P is now a pinching point (the faces of V around P form more
   than one cycle, §3.5) and if so splits P and V in two (Fig. 8c,
   :func:`operations.volume_pinch`).

This is how the Fig. 7 cases with two or more connecting edges are realised here:
the paper's wording ("a new edge is created", "all edges are contracted except
extremal edges") describes the same collapse of the flattened triangles onto the
face, which we perform as face-pair removals so that every step is a kernel
operation and the map stays valid.
"""

from __future__ import annotations

from . import operations as op
from .gmap import GMap, GMapError, VERTEX


def star_face(g: GMap, face: int, y) -> int:
    """Insert a vertex at ``y`` inside ``face`` joined to all its corners (both α3 sides).

    Each edge k of the face becomes the base of triangle T_k = (c_k, c_{k+1}, X):
    four new darts a_k, b_k (spoke k, at c_k and X) and b'_k, a'_k (spoke k+1,
    at X and c_{k+1}) per triangle and side. Returns the new vertex id.
    """
    cyc = g.face_cycle(face)
    if len(set(g.vertex(c) for c in cyc)) != len(cyc) // 2:
        raise GMapError("star_face: the face repeats a corner (holed face)")
    x = g.add_point(y)
    sides = [cyc]
    if not g.is_free(3, face):
        sides.append([g.a(3, c) for c in cyc])
    made = []
    for c in sides:
        n = len(c) // 2
        vol = g.volume(c[0])
        a, b, bp, ap = ([g.new_darts(1, volume=vol)[0] for _ in range(n)] for _ in range(4))
        for k in range(n):
            ck, dk = c[2 * k], c[2 * k + 1]           # edge k: ck at corner k, dk at corner k+1
            g.set_vertex((a[k],), g.vertex(ck))
            g.set_vertex((b[k], bp[k]), x)
            g.set_vertex((ap[k],), g.vertex(dk))
        for k in range(n):
            g.unlink(1, c[2 * k])                     # the corners get the spokes in between
        for k in range(n):
            ck, dk = c[2 * k], c[2 * k + 1]
            g.link(1, ck, a[k])
            g.link(0, a[k], b[k])
            g.link(1, b[k], bp[k])
            g.link(0, bp[k], ap[k])
            g.link(1, ap[k], dk)
            g.link(2, a[k], ap[k - 1])                # spoke k seen from T_k and T_{k-1}
            g.link(2, b[k], bp[k - 1])
        made.append(a + b + bp + ap)
    if len(made) == 2:
        for u, w in zip(*made):
            g.link(3, u, w)
    return x


def _remove_face_pair(g: GMap, t1: int, t2: int, shared: set) -> None:
    """Remove two triangles of one volume that share an edge and coincide.

    Their other edges are matched by vertex (corners in ``shared`` map to
    themselves; the apexes are merged by the caller) and the faces beyond them
    are α2-linked; both triangles' darts are deleted.
    """
    c1, c2 = g.face_cycle(t1), g.face_cycle(t2)
    for x in c1:
        if not g.is_free(3, x):
            raise GMapError("collapse: a flattened triangle is shared with another volume")
    key = lambda d: (g.vertex(d) in shared, g.vertex(d) if g.vertex(d) in shared else -1,  # noqa: E731
                     g.vertex(g.a(0, d)) in shared,
                     g.vertex(g.a(0, d)) if g.vertex(g.a(0, d)) in shared else -1)
    m2 = {key(d): d for d in c2}
    pairs = []
    for d in c1:
        k = key(d)
        if k[0] and k[2]:
            continue                                  # the shared edge itself goes away
        if k not in m2:
            raise GMapError("collapse: the triangles do not coincide")
        pairs.append((g.a(2, d), g.a(2, m2[k])))
    for u, w in pairs:
        g.alpha[2, u] = u
        g.alpha[2, w] = w
    for u, w in pairs:
        g.link(2, u, w)
    g.delete(c1 + c2)


def vertex_face_collapse(g: GMap, v: int, label: int, face: int, y, new_label=None) -> dict:
    """Vertex ``v`` of volume ``label`` lands at ``y`` inside ``face``, joined to
    consecutive corners of it (Fig. 7b/c); see the module docstring.

    Returns
    -------
    dict
        ``vertex`` (the merged vertex id), ``removed`` (flattened triangle pairs)
        and ``pinch`` (new volume labels if the volume was split, Fig. 8).
    """
    corners = g.face_vertices(face)
    n = len(corners)
    nb = set(op.neighbours(g, v, label))
    pairs = [(corners[k], corners[(k + 1) % n]) for k in range(n)
             if corners[k] in nb and corners[(k + 1) % n] in nb]
    flat = []
    for qa, qb in pairs:
        tri = [d for d in op.faces_at(g, v, label)
               if len(g.face_cycle(d)) == 6 and set(g.face_vertices(d)) == {v, qa, qb}]
        if len(tri) == 1:
            flat.append((tri[0], qa, qb))
    if not flat:
        raise GMapError("vertex_face_collapse: no triangle of the vertex lies on an edge of the face")
    g.points[v] = y
    x = star_face(g, face, y)
    for t, qa, qb in flat:
        under = [d for d in op.faces_at(g, x, label)
                 if set(g.face_vertices(d)) == {x, qa, qb}]
        if len(under) != 1:
            raise GMapError("vertex_face_collapse: no star triangle under the flattened one")
        _remove_face_pair(g, t, under[0], {qa, qb})
    merged = set()
    for d in op.darts_at(g, x) + op.darts_at(g, v):
        merged.update(g.orbit(d, VERTEX))
    g.set_vertex(merged, v)
    new = op.volume_pinch(g, v, label, new_label)
    return dict(vertex=v, removed=len(flat), pinch=new)
