"""The atomic topological operations of the paper (§3.2–3.5) on a :class:`GMap`.

=====================  ===========  ==============================================
operation              paper        what it does to the map
=====================  ===========  ==============================================
``triangulate_face``   §3.1         ear-clipping edges inserted in a face (planar
                                    faces only: a moving vertex keeps triangles)
``vertex_split``       §3.2 Fig. 3  unsew the interface faces around a vertex shared
                                    by two volumes; the moving volume gets a copy
``slide_edge``         §3.3 Fig. 4  a vertex sliding on a face reaches one of its
                       Fig. 9       edges: insert a vertex there and relink α1 at the
                                    two corners (face split, vertex orbits merged)
``vertex_face_hole``   §3.4 Fig. 5  a vertex crosses a face not joined to it by an
                       Fig. 6       edge: the face gets a polygonal hole (the
                                    crossings of the vertex's edges) and a bridge
                                    edge; the cap beyond is removed (5c) or given to
                                    the volume behind the face (5d)
``contract_to_face``   §3.4 Fig. 7a a vertex reaches a face it is joined to by one
                                    edge: the edge is contracted
``volume_pinch``       §3.5 Fig. 8  the faces around a vertex form several cycles in
                                    one volume: one vertex per cycle, and each
                                    connected part becomes its own volume
=====================  ===========  ==============================================

Each operation keeps the map valid (:meth:`GMap.check`); faces shared by two
volumes are changed on both sides (α3), so the volumes stay closed.
"""

from __future__ import annotations

import numpy as np

from .geometry import newell_normal, project, triangulate_polygon
from .gmap import CORNER, VERTEX, VERTEX_BITS, GMap, GMapError


# ---------------------------------------------------------------- helpers
def darts_at(g: GMap, v: int, label: int | None = None) -> list[int]:
    return [int(d) for d in g.vertex_darts(v) if label is None or g.volume(int(d)) == label]


def faces_at(g: GMap, v: int, label: int | None = None) -> list[int]:
    """One corner dart (at ``v``) per face side incident to vertex ``v``."""
    out, seen = [], set()
    for d in darts_at(g, v, label):
        if d in seen:
            continue
        cyc = g.face_cycle(d)
        seen.update(cyc)
        out.append(d)
    return out


def face_plane(g: GMap, d: int):
    """(point, unit normal) of the face side of ``d`` (Newell normal of its corners)."""
    p = g.points[g.face_vertices(d)]
    n = newell_normal(p)
    ln = np.linalg.norm(n)
    return p.mean(axis=0), (n / ln if ln > 0 else n)   # a zero-area face has no plane


def in_plane(g: GMap, d: int, direction, tol=1e-9) -> bool:
    """Whether ``direction`` lies in the plane of the face of ``d``."""
    _, n = face_plane(g, d)
    dn = np.linalg.norm(direction)
    return dn > 0 and n @ n > 0 and abs(n @ direction) <= tol * dn


def neighbours(g: GMap, v: int, label: int | None = None) -> list[int]:
    """Vertex ids joined to ``v`` by an edge (in volume ``label``)."""
    return sorted({g.vertex(g.a(0, d)) for d in darts_at(g, v, label)})


# ----------------------------------------------------------- triangulation
def triangulate_face(g: GMap, d: int, apex: int | None = None) -> int:
    """Split the face of ``d`` into triangles (both α3 sides); returns the edges inserted.

    With ``apex`` (a vertex of the face), a fan from it when every fan triangle
    keeps the face's orientation (the face is star-shaped from the apex), so that
    every new triangle moves with the apex; otherwise ear clipping. Used on the
    faces around a vertex before it leaves their plane (paper §3.1: non-planar
    faces are triangulated).
    """
    cyc = g.face_cycle(d)
    corner = cyc[0::2]
    if len(corner) <= 3:
        return 0
    vids = [g.vertex(c) for c in corner]
    if apex is not None and vids.count(apex) == 1:
        k = vids.index(apex)
        pts = g.points[vids]
        nrm = newell_normal(pts)
        n = len(vids)
        fan_ok = all(np.cross(pts[(k + i) % n] - pts[k], pts[(k + i + 1) % n] - pts[k]) @ nrm
                     > 1e-12 * (nrm @ nrm) for i in range(1, n - 1))
        if fan_ok:
            c = corner[k]
            added = 0
            while len(g.face_cycle(c)) > 6:
                new = g.split_face(c, g.face_cycle(c)[4])
                c = g.a(2, new)                 # the rest of the face, at the apex
                added += 1
            return added
    tris = triangulate_polygon(g.points[vids], vids)
    # Replay the clipping order: ear (a, b, c) is cut off by the diagonal a–c.
    idx = list(range(len(corner)))
    cur = dict(enumerate(corner))
    n = 0
    for a, b, c in tris[:-1]:
        t = idx.index(b)
        assert idx[t - 1] == a and idx[(t + 1) % len(idx)] == c
        new = g.split_face(cur[a], cur[c])
        # the ear keeps cur[a]; the rest starts at the new dart at a (b_u)
        cur[a] = g.a(2, new)
        idx.pop(t)
        n += 1
    return n


def prepare_motion(g: GMap, v: int, direction, label: int | None = None) -> int:
    """Triangulate the faces around ``v`` that ``direction`` would bend out of plane."""
    n = 0
    changed = True
    while changed:
        changed = False
        for d in faces_at(g, v, label):
            if len(g.face_cycle(d)) > 6 and not in_plane(g, d, direction):
                n += triangulate_face(g, d, apex=v)
                changed = True
                break
    return n


# -------------------------------------------------------------- §3.2 split
def vertex_split(g: GMap, v: int, moving: int, direction, rng=None) -> int:
    """Split vertex ``v`` so that volume ``moving`` gets a copy of its own (Fig. 3).

    The interface faces around ``v`` between ``moving`` and each other volume are
    triangulated (unless ``direction`` slides in their plane), so that only the
    triangles touching ``v`` are unsewn ("new faces to connect them to their
    respective volume"). Volumes are separated pairwise in a random order, as in
    the paper for a vertex in more than two volumes.

    Returns
    -------
    int
        The vertex id carried by ``moving``'s darts (``v`` itself if ``v``
        belonged to ``moving`` only).
    """
    labels = sorted({g.volume(d) for d in darts_at(g, v)})
    if moving not in labels:
        raise GMapError(f"vertex {v} is not in volume {moving}")
    others = [lab for lab in labels if lab != moving]
    if rng is not None:
        rng.shuffle(others)
    for other in others:
        for d in faces_at(g, v, moving):
            e = g.a(3, d)
            if e != d and g.volume(e) == other and not in_plane(g, d, direction):
                triangulate_face(g, d, apex=v)
        for d in faces_at(g, v, moving):
            e = g.a(3, d)
            if e != d and g.volume(e) == other:
                g.unsew3(d)
    mine = darts_at(g, v, moving)
    orb = set()
    for d in mine:
        if d not in orb:
            orb.update(g.orbit(d, VERTEX))
    if any(g.volume(d) != moving for d in orb):
        raise GMapError("vertex_split: the vertex is still shared after unsewing")
    if len(orb) == len(g.vertex_darts(v)):
        return v
    nv = g.add_point(g.points[v].copy())
    g.set_vertex(orb, nv)
    return nv


# -------------------------------------------------------------- §3.3 slide
def slide_edge(g: GMap, corner: int, edge_dart: int, x) -> int:
    """A vertex sliding on a face hits one of the face's edges at ``x`` (Fig. 4, 9).

    Parameters
    ----------
    corner : int
        Dart at the sliding vertex P in the face F (any of its two darts in F).
    edge_dart : int
        A dart of the hit edge, in F.
    x : array_like
        The collision point (on the edge).

    The edge gets a new vertex X at ``x`` (cell insertion); the α1 links at P's
    and X's corners of F are swapped (Fig. 9: α1(a) = d, α1(b) = c), so F splits
    in two and P, X become one vertex orbit, placed at ``x``. A part with two
    edges (when F was a triangle) is a digon and is removed.

    Returns
    -------
    int
        The vertex id of P (now on the edge).
    """
    v = g.vertex(corner)
    nx = g.insert_vertex(edge_dart, x)
    xv = g.vertex(nx)
    cyc = g.face_cycle(corner)
    j = next(k for k in range(0, len(cyc), 2) if g.vertex(cyc[k]) == xv)
    c2 = cyc[j]
    g.relink_corners(corner, c2)
    merged = g.orbit(corner, VERTEX)
    g.set_vertex(merged, v)
    g.points[v] = x
    for d in (corner, c2):
        if g.alpha[0, d] >= 0 and len(g.face_cycle(d)) == 4:
            g.remove_digon(d)
    return v


# ------------------------------------------------------- §3.4 vertex–face
def point_in_polygon(q, poly):
    """Whether the 2-D point ``q`` lies inside the polygon ``poly`` ``(n, 2)`` (even-odd rule)."""
    inside = False
    n = len(poly)
    for i in range(n):
        a, b = poly[i], poly[(i + 1) % n]
        if (a[1] > q[1]) != (b[1] > q[1]):
            xc = a[0] + (q[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            if q[0] < xc:
                inside = not inside
    return inside


def _segments_cross(p, q, a, b):
    def orient(u, v, w):
        return (v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0])
    d1, d2 = orient(a, b, p), orient(a, b, q)
    d3, d4 = orient(p, q, a), orient(p, q, b)
    return (d1 * d2 < 0) and (d3 * d4 < 0)


def _ring_around(g: GMap, v: int, label: int):
    """Darts at ``v`` in ``label`` ordered around it: [(dart on edge i, face corner)]"""
    start = darts_at(g, v, label)[0]
    ring, d = [], start
    while True:
        ring.append(d)
        d = g.a(2, g.a(1, d))           # next edge around v inside the volume
        if d == start:
            break
        if len(ring) > 4 * g.capacity:
            raise GMapError("vertex link does not close")
    return ring


def vertex_face_hole(g: GMap, v: int, label: int, face: int) -> dict:
    """Vertex ``v`` of volume ``label`` has crossed face ``face`` of that volume (Fig. 5).

    The faces around ``v`` must be triangles (see :func:`prepare_motion`) and ``v``
    must have no edge to a vertex of the face. Each edge (v, w) is cut where it
    crosses the face's plane (new vertices H_i, the hole's corners); each
    triangle (v, w_i, w_{i+1}) is split by the edge H_i–H_{i+1}; the face gets
    the polygonal hole H and a bridge edge from a hole corner to the nearest
    visible corner of its border (Fig. 6). The cap (v, H_i, H_{i+1}) is
    deleted with ``v`` if the face is on the outer boundary (Fig. 5c: the extra
    volume is removed); if the face is shared with another volume, the cap joins
    that volume, as a dip that ``v`` keeps drilling (Fig. 5d).

    Returns
    -------
    dict
        ``ring`` (hole vertex ids), ``behind`` (label of the volume behind or
        None), ``vertex`` (``v`` if it survives, else None).
    """
    fverts = g.face_vertices(face)
    if v in fverts or set(neighbours(g, v, label)) & set(fverts):
        raise GMapError("vertex_face_hole: the vertex is joined to the face by an edge (Fig. 7 case)")
    o, n = face_plane(g, face)
    pv = g.points[v]
    sv = (pv - o) @ n
    ring = _ring_around(g, v, label)
    for d in faces_at(g, v, label):
        if len(g.face_cycle(d)) != 6:
            raise GMapError("vertex_face_hole: faces around the vertex must be triangles")
    outer2d_all = project(g.points[fverts], n)
    proj = lambda p: project(np.atleast_2d(p), n)[0]  # noqa: E731
    # 1. hole corners on the edges around v (all checked before the map changes)
    cuts = []
    for d in ring:
        w = g.vertex(g.a(0, d))
        pw = g.points[w]
        sw = (pw - o) @ n
        if not (sv * sw < 0):
            raise GMapError("vertex_face_hole: a neighbour of the vertex is not on the other side of the face")
        h = pv + sv / (sv - sw) * (pw - pv)
        if not point_in_polygon(proj(h), outer2d_all):
            raise GMapError("vertex_face_hole: the hole would leave the face")
        cuts.append(h)
    m = len(ring)
    # bridge (Fig. 6): nearest visible (border corner, hole corner) pair, chosen now
    fcyc = g.face_cycle(face)
    outer_c = fcyc[0::2]
    outer2d = project(g.points[[g.vertex(c) for c in outer_c]], n)
    ring_xy = project(np.asarray(cuts), n)
    area_outer = _signed_area(outer2d)
    ring_order = list(range(m))
    if np.sign(_signed_area(ring_xy)) == np.sign(area_outer):
        ring_order = ring_order[::-1]
    # bridge: nearest (outer corner, hole corner) pair whose segment crosses nothing
    segs = [(outer2d[k], outer2d[(k + 1) % len(outer2d)]) for k in range(len(outer2d))]
    segs += [(ring_xy[k], ring_xy[(k + 1) % m]) for k in range(m)]
    best = None
    for k in range(len(outer_c)):
        for j in range(m):
            dist = np.linalg.norm(outer2d[k] - ring_xy[j])
            if best is not None and dist >= best[0]:
                continue
            if any(_segments_cross(outer2d[k], ring_xy[j], a, b) for a, b in segs):
                continue
            best = (dist, k, j)
    if best is None:
        raise GMapError("vertex_face_hole: no bridge edge fits")
    _, ko, jh = best
    start = ring_order.index(jh)
    hole = []
    for d, h in zip(ring, cuts):
        hole.append(g.vertex(g.insert_vertex(d, h)))
    # 2. split each triangle (v, H_i, w_i, w_{i+1}, H_{i+1}) between H_i and H_{i+1}
    cap_edge = []                        # per i: (cap-side dart at H_i on ring edge)
    for i, d in enumerate(ring):
        # triangle of d (face of d): corners v, H_i, w_i, w_{i+1}, H_{i+1} in some order
        cyc = g.face_cycle(d)
        hs = {hole[i], hole[(i - 1) % m], hole[(i + 1) % m]}
        hc = [k for k in range(0, len(cyc), 2) if g.vertex(cyc[k]) in hs]
        if len(hc) != 2:
            raise GMapError("vertex_face_hole: unexpected face around the vertex")
        a_, b_ = cyc[hc[0]], cyc[hc[1]]
        new = g.split_face(a_, b_)
        # the part containing v is the cap: the new dart's face or its α2 side
        cap = new if v in g.face_vertices(new) else g.a(2, new)
        cap_edge.append(cap)
    capset = set()
    for c in cap_edge:
        capset.update(g.face_cycle(c))
    # 3. the hole in the face, with the bridge chosen above (Fig. 6)
    ring_seq = [hole[ring_order[(start + s) % m]] for s in range(m)]
    sides = [outer_c[ko]]
    behind = None
    if not g.is_free(3, face):
        sides.append(g.a(3, outer_c[ko]))
        behind = g.volume(sides[1])
    made = [_hole_side(g, c, ring_seq) for c in sides]
    if len(made) == 2:
        for x, y in zip(made[0]["all"], made[1]["all"]):
            g.link(3, x, y)
    # 4. sew ring edges: rest side -> this face's hole; cap -> the face behind (5d) or gone (5c)
    for c in cap_edge:
        ca, cb = c, g.a(0, c)               # cap darts on ring edge at its two ends
        ra, rb = g.a(2, ca), g.a(2, cb)     # rest-side darts
        key = (g.vertex(ca), g.vertex(cb))
        g.unlink(2, ca)
        g.unlink(2, cb)
        ha, hb = made[0]["edge"][frozenset(key)]
        if g.vertex(ha) != g.vertex(ra):
            ha, hb = hb, ha
        g.link(2, ra, ha)
        g.link(2, rb, hb)
        if behind is not None:
            pa, pb = g.a(3, ha), g.a(3, hb)
            g.link(2, ca, pa)
            g.link(2, cb, pb)
    if behind is None:
        if any(not g.is_free(3, x) for x in capset):   # pragma: no cover - faces at v are exposed
            raise GMapError("vertex_face_hole: the cap is shared with another volume")
        g.delete(sorted(capset))
        return dict(ring=hole, behind=None, vertex=None)
    for x in capset:
        g.attr[x] = (behind << VERTEX_BITS) | (int(g.attr[x]) & ((1 << VERTEX_BITS) - 1))
    return dict(ring=hole, behind=behind, vertex=v)


def _signed_area(xy):
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _hole_side(g: GMap, c_o: int, ring_seq) -> dict:
    """Insert bridge + hole ring at corner dart ``c_o`` of one face side.

    The new cycle is: ... p –α1– b1o –α0– b1h –α1– (ring) –α1– b2h –α0– b2o –α1– c_o.
    """
    vol = g.volume(c_o)
    o_vid = g.vertex(c_o)
    p = g.a(1, c_o)
    m = len(ring_seq)
    b1o, b1h, b2h, b2o = g.new_darts(4, volume=vol)
    g.set_vertex((b1o, b2o), o_vid)
    g.set_vertex((b1h, b2h), ring_seq[0])
    ringd = g.new_darts(2 * m, volume=vol)
    edges = {}
    for i in range(m):
        a, b = ringd[2 * i], ringd[2 * i + 1]
        va, vb = ring_seq[i], ring_seq[(i + 1) % m]
        g.set_vertex((a,), va)
        g.set_vertex((b,), vb)
        g.link(0, a, b)
        if i + 1 < m:
            g.link(1, b, ringd[2 * i + 2])
        edges[frozenset((va, vb))] = (a, b)
    g.unlink(1, c_o)
    g.link(1, p, b1o)
    g.link(0, b1o, b1h)
    g.link(1, b1h, ringd[0])
    g.link(1, ringd[-1], b2h)
    g.link(0, b2h, b2o)
    g.link(1, b2o, c_o)
    g.link(2, b1o, b2o)
    g.link(2, b1h, b2h)
    return dict(all=[b1o, b1h, b2h, b2o] + ringd, edge=edges)


def contract_to_face(g: GMap, v: int, label: int, face: int) -> int:
    """Fig. 7a: ``v`` reaches ``face`` and is joined to it by exactly one edge: contract it.

    The merged vertex keeps the face vertex's id and position (it stays on the
    face); faces that had the contracted edge and become digons are removed.

    Returns
    -------
    int
        The surviving vertex id (the face's vertex).
    """
    fverts = set(g.face_vertices(face))
    joins = [d for d in darts_at(g, v, label) if g.vertex(g.a(0, d)) in fverts]
    targets = {g.vertex(g.a(0, d)) for d in joins}
    if len(targets) != 1:
        raise GMapError(f"contract_to_face: the vertex is joined to the face by {len(targets)} edges "
                        "(Fig. 7b/c cases are not implemented)")
    d = joins[0]
    w = g.vertex(g.a(0, d))
    reps = [g.a(1, x) for x in g.orbit(d, (0, 2, 3))]
    g.contract_edge(g.a(0, d), g.points[w].copy())
    for r in reps:
        if g.alpha[0, r] >= 0 and len(g.face_cycle(r)) == 4:
            g.remove_digon(r)
    return w


# ----------------------------------------------------------- §3.5 pinching
def pinch_cycles(g: GMap, v: int, label: int) -> list[list[int]]:
    """The cycles of faces around ``v`` inside volume ``label`` (⟨α1, α2⟩ orbits).

    More than one cycle means ``v`` is a pinching point (paper §3.5).
    """
    out, seen = [], set()
    for d in darts_at(g, v, label):
        if d in seen:
            continue
        orb = g.orbit(d, CORNER)
        seen.update(orb)
        out.append(orb)
    return out


def volume_pinch(g: GMap, v: int, label: int, new_label=None) -> list[int]:
    """Split a pinched vertex and the volume it pinches (Fig. 8c).

    Every cycle around ``v`` but the first gets its own vertex (same position);
    then every connected part (⟨α0, α1, α2⟩ orbit) of volume ``label`` but the one
    holding the first cycle gets a label from ``new_label()``.

    Returns
    -------
    list of int
        The new labels (empty if ``v`` was not a pinching point).
    """
    cycles = pinch_cycles(g, v, label)
    if len(cycles) < 2:
        return []
    for orb in cycles[1:]:
        full = set()
        for d in orb:
            full.update(g.orbit(d, VERTEX))
        g.set_vertex(full, g.add_point(g.points[v].copy()))
    parts, seen = [], set()
    for d in g.darts():
        d = int(d)
        if d in seen or g.volume(d) != label:
            continue
        orb = g.orbit(d, (0, 1, 2))
        seen.update(orb)
        parts.append(orb)
    first = next(p for p in parts if cycles[0][0] in set(p))
    labels = []
    for p in parts:
        if p is first:
            continue
        lab = new_label() if new_label else max(g.labels()) + 1
        g.set_volume(p, lab)
        labels.append(lab)
    return labels
