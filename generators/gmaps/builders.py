"""Build 3-G-maps of layered terrain volumes from polygons.

:func:`from_polyhedra` turns closed polyhedra (faces as vertex-index polygons) into
a 3-G-map: α0/α1 inside each polygon, α2 between the two faces of a volume that
share an edge, α3 between the faces of two volumes that are the same polygon
(paper §3: "the 3D structured terrain is subdivided into several volumes ... its
boundary representation is a collection of faces").

:class:`Lattice` describes a terrain as boxes on a rectilinear lattice (stacked
prisms/hexahedra per material layer, paper Fig. 2b and Fig. 10): every box
boundary is made of lattice quads, so two boxes touching along a side share their
quads, which are sewn with α3. A side that touches no other box and needs no
subdivision becomes a single polygon (fewer darts: the paper keeps "most parts of
the 3D terrain ... represented roughly", §4.2).
"""

from __future__ import annotations

import numpy as np

from .gmap import GMap, GMapError, VERTEX

SIDES = ("-x", "+x", "-y", "+y", "-z", "+z")


def from_polyhedra(points, volumes) -> GMap:
    """A 3-G-map from closed polyhedra sharing vertices.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Vertex positions.
    volumes : list of (label, faces)
        ``faces`` is a list of polygons (vertex indices); each volume's faces
        must close a 2-manifold surface (every edge in exactly two faces).
        Faces listed by two volumes with the same vertex set are sewn (α3).

    Returns
    -------
    GMap
        Valid (checked) map; vertices that end up as several vertex orbits get
        one position row each.
    """
    points = np.asarray(points, dtype=float)
    n_darts = sum(2 * len(f) for _, faces in volumes for f in faces)
    g = GMap(n_darts)
    for p in points:
        g.add_point(p)
    face_key = {}
    for label, faces in volumes:
        edge_darts = {}            # (u, w) -> [dart at u, ...] within this volume
        for face in faces:
            if len(face) < 3 or len(set(face)) != len(face):
                raise GMapError(f"volume {label}: face {face} must have >= 3 distinct vertices")
            k = len(face)
            ds = g.new_darts(2 * k, volume=label)
            for j in range(k):
                a, b = ds[2 * j], ds[2 * j + 1]
                g.set_vertex((a,), face[j])
                g.set_vertex((b,), face[(j + 1) % k])
                g.link(0, a, b)
                g.link(1, b, ds[(2 * j + 2) % (2 * k)])
                u, w = face[j], face[(j + 1) % k]
                edge_darts.setdefault((min(u, w), max(u, w)), []).append((a, b) if u < w else (b, a))
            key = frozenset(face)
            face_key.setdefault(key, []).append((label, ds[0]))
        for e, pairs in edge_darts.items():
            if len(pairs) != 2:
                raise GMapError(f"volume {label}: edge {e} lies in {len(pairs)} faces (needs 2: closed surface)")
            (a0, b0), (a1, b1) = pairs
            g.link(2, a0, a1)
            g.link(2, b0, b1)
    for key, sides in face_key.items():
        if len(sides) == 1:
            continue
        if len(sides) != 2 or sides[0][0] == sides[1][0]:
            raise GMapError(f"face {sorted(key)} is listed {len(sides)} times")
        d, e = sides[0][1], sides[1][1]
        # The partner of d is the dart of e's face at the same vertex on the same edge.
        u, w = g.vertex(d), g.vertex(g.a(0, d))
        for x in g.face_cycle(e):
            if g.vertex(x) == u and g.vertex(g.a(0, x)) == w:
                g.sew3(d, x)
                break
        else:  # pragma: no cover - same vertex set, different polygon
            raise GMapError(f"faces {sorted(key)} have the same vertices in another order")
    separate_vertex_orbits(g)
    g.check()
    return g


def separate_vertex_orbits(g: GMap) -> None:
    """Give every vertex orbit ⟨α1, α2, α3⟩ its own vertex id (copying the position)."""
    seen = np.zeros(g.capacity, dtype=bool)
    owner = {}
    for d in g.darts():
        if seen[d]:
            continue
        orb = g.orbit(int(d), VERTEX)
        seen[orb] = True
        v = g.vertex(int(d))
        if v in owner:
            g.set_vertex(orb, g.add_point(g.points[v].copy()))
        else:
            owner[v] = True


class Lattice:
    """Boxes of material on a rectilinear lattice ``xs × ys × zs`` (metres, Z up).

    Parameters
    ----------
    xs, ys, zs : sequence of float
        Increasing lattice coordinates.
    """

    def __init__(self, xs, ys, zs):
        self.xs, self.ys, self.zs = (np.asarray(v, dtype=float) for v in (xs, ys, zs))
        for name, v in zip("xyz", (self.xs, self.ys, self.zs)):
            if len(v) < 2 or np.any(np.diff(v) <= 0):
                raise GMapError(f"lattice {name}s must increase (got {list(v)})")
        self.boxes = []

    def add_box(self, label, i, j, k, split=()):
        """Add box ``xs[i0]..xs[i1] × ys[j0]..ys[j1] × zs[k0]..zs[k1]`` of volume ``label``.

        ``split`` names sides (``'-x' ... '+z'``) kept as lattice quads even if they
        touch no other box (where vertices will move).
        """
        for s in split:
            if s not in SIDES:
                raise GMapError(f"unknown side {s!r} (one of {', '.join(SIDES)})")
        self.boxes.append((label, tuple(i), tuple(j), tuple(k), set(split)))
        return self

    def _vid(self, i, j, k):
        key = (i, j, k)
        if key not in self._ids:
            self._ids[key] = len(self._pts)
            self._pts.append((self.xs[i], self.ys[j], self.zs[k]))
        return self._ids[key]

    def _side_quads(self, box, side):
        """Quads of one box side as lattice-index loops, outward orientation."""
        _, (i0, i1), (j0, j1), (k0, k1), _ = box
        axis = "xyz".index(side[1])
        rng = [(i0, i1), (j0, j1), (k0, k1)]
        fixed = rng[axis][1] if side[0] == "+" else rng[axis][0]
        a, b = [x for x in range(3) if x != axis]
        quads = []
        for s in range(rng[a][0], rng[a][1]):
            for t in range(rng[b][0], rng[b][1]):
                corners = []
                for ds, dt in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    idx = [0, 0, 0]
                    idx[axis], idx[a], idx[b] = fixed, s + ds, t + dt
                    corners.append(tuple(idx))
                # (a, b, axis) right-handed: a x b = +axis for axis x, z; reversed for y.
                flip = (side[0] == "-") != (axis == 1)
                quads.append(corners[::-1] if flip else corners)
        return quads

    def _perimeter(self, box, side):
        """The side as one polygon through every lattice point of its border."""
        quads = self._side_quads(box, side)
        edges = {}
        for q in quads:
            for m in range(4):
                e = (q[m], q[(m + 1) % 4])
                if (e[1], e[0]) in edges:
                    del edges[(e[1], e[0])]
                else:
                    edges[e] = True
        succ = {u: w for (u, w) in edges}
        start = min(succ)
        loop, cur = [start], succ[start]
        while cur != start:
            loop.append(cur)
            cur = succ[cur]
        return loop

    def build(self) -> GMap:
        """The 3-G-map of all boxes (shared quads sewn with α3)."""
        self._ids, self._pts = {}, []
        quad_count = {}
        for box in self.boxes:
            for side in SIDES:
                for q in self._side_quads(box, side):
                    key = frozenset(q)
                    quad_count[key] = quad_count.get(key, 0) + 1
        volumes = {}
        for box in self.boxes:
            label, split = box[0], box[4]
            faces = volumes.setdefault(label, [])
            for side in SIDES:
                quads = self._side_quads(box, side)
                shared = any(quad_count[frozenset(q)] > 1 for q in quads)
                if shared or side in split or len(quads) == 1:
                    faces.extend(quads)
                else:
                    faces.append(self._perimeter(box, side))
        # Faces inside one label (two boxes of the same material) would be interior: drop them.
        out = []
        for label, faces in volumes.items():
            keys = {}
            for f in faces:
                keys[frozenset(f)] = keys.get(frozenset(f), 0) + 1
            kept = [[self._vid(*c) for c in f] for f in faces if keys[frozenset(f)] == 1]
            out.append((label, kept))
        return from_polyhedra(np.array(self._pts), out)


def layer_stack(extent, z_levels, cells=(3, 3), top_split=True) -> GMap:
    """Horizontal material layers (paper Fig. 10): volume ``k`` between ``z_levels[k]``
    and ``z_levels[k+1]`` (``k = 0`` at the top), interfaces as sewn ``cells`` grids.

    Parameters
    ----------
    extent : (x0, y0, x1, y1)
    z_levels : sequence of float
        Decreasing heights: top surface first.
    cells : (nx, ny)
        Lattice cells of the interfaces and of the top surface.
    """
    x0, y0, x1, y1 = extent
    zs = np.asarray(z_levels, dtype=float)[::-1]
    lat = Lattice(np.linspace(x0, x1, cells[0] + 1), np.linspace(y0, y1, cells[1] + 1), zs)
    n = len(zs) - 1
    for k in range(n):
        label = n - 1 - k
        lat.add_box(label, (0, cells[0]), (0, cells[1]), (k, k + 1),
                    split=("+z",) if (top_split and label == 0) else ())
    return lat.build()


def star_vertex(g: GMap, face: int, p) -> int:
    """Insert a vertex at ``p`` inside a convex quad face and join it to the corners.

    Cell insertions only: an edge along the diagonal through ``p`` (which must lie
    on the diagonal c0–c2), a vertex on it, then edges to the two other corners.
    Mirrored on the face's α3 side. Returns the new vertex id.
    """
    cyc = g.face_cycle(face)
    if len(cyc) != 8:
        raise GMapError("star_vertex needs a quad face")
    c0, c2 = cyc[0], cyc[4]
    a, b = g.pos(c0), g.pos(c2)
    s = float(np.dot(np.asarray(p) - a, b - a) / np.dot(b - a, b - a))
    if not (0 < s < 1) or np.linalg.norm(a + s * (b - a) - p) > 1e-9 * (1 + np.linalg.norm(b - a)):
        raise GMapError("star_vertex: the point must lie inside the diagonal c0–c2")
    new = g.split_face(c0, c2)            # new dart at c0, in the face of c0
    nd = g.insert_vertex(new, p)          # new dart at the vertex, in the same face
    v = g.vertex(nd)
    for d in (nd, g.a(2, nd)):
        cyc = g.face_cycle(d)
        if len(cyc) > 6:
            g.split_face(cyc[0], cyc[4])
    return v


def find_face(g: GMap, label: int, centre, normal_axis: int) -> int:
    """The face of volume ``label`` whose corners' mean is ``centre`` and that is
    perpendicular to axis ``normal_axis`` (0, 1, 2)."""
    centre = np.asarray(centre, dtype=float)
    for d in g.faces(label):
        p = g.points[g.face_vertices(d)]
        if np.ptp(p[:, normal_axis]) < 1e-9 and np.allclose(p.mean(axis=0), centre, atol=1e-9):
            return d
    raise GMapError(f"no face of volume {label} centred at {centre.tolist()}")


def find_vertex(g: GMap, p, label: int | None = None) -> int:
    """Vertex id at position ``p`` (in volume ``label`` if given)."""
    dist = np.linalg.norm(g.points - np.asarray(p, dtype=float), axis=1)
    for v in np.argsort(dist):
        if dist[v] > 1e-9:
            break
        ds = g.vertex_darts(int(v))
        if len(ds) and (label is None or any(g.volume(int(d)) == label for d in ds)):
            return int(v)
    raise GMapError(f"no vertex at {list(p)}")
