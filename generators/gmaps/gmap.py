"""A 3-generalized map (3-G-map) kernel stored as compact int32 arrays.

A 3-G-map is a set of *darts* with four involutions α0, α1, α2, α3 (paper §4.1,
[Lie94]). A dart is a (vertex, edge, face, volume) flag; α_i swaps the i-cell of
the flag while keeping the others. A cell is an *orbit*:

========  =================  ==========================================
cell      orbit              meaning
========  =================  ==========================================
vertex    ⟨α1, α2, α3⟩       all flags around a vertex, in every volume
edge      ⟨α0, α2, α3⟩
face      ⟨α0, α1, α3⟩       both sides of a face shared by two volumes
volume    ⟨α0, α1, α2⟩       the closed boundary surface of one volume
========  =================  ==========================================

A free α3 (``α3(d) = d``) marks a face on the terrain's outer boundary. The
map is valid when every α_i is an involution, α0, α1, α2 have no fixed point
(closed faces and closed volume boundaries) and α_i∘α_j is an involution for
|i − j| ≥ 2 (α0α2, α0α3, α1α3), see :meth:`GMap.check`.

Storage (paper §4.1 reports 20 bytes a dart): ``alpha`` is a ``(4, capacity)``
int32 array and ``attr`` one int32 a dart packing the vertex-attribute index
(low 24 bits) and the volume label (high 7 bits): 4×4 + 4 = 20 bytes a dart.
Geometry lives per vertex orbit in ``points`` (float64, one row per vertex),
never per dart. An unused dart slot has ``alpha[0] = -1`` and is reused.

Kernel operations (cell insertion, removal and contraction, [VD] Moka): sewing
(:meth:`sew3`), vertex insertion on an edge (:meth:`insert_vertex`), edge
insertion in a face (:meth:`split_face`), the corner relinking of Fig. 9
(:meth:`relink_corners`), edge contraction (:meth:`contract_edge`) and digon
removal (:meth:`remove_digon`). Every face operation is mirrored on the α3
partner face, so faces shared by two volumes stay sewn.

References
----------
Bezin et al., *Topological Operations for Geomorphological Evolution*, §4.1 and
Fig. 9; Lienhardt, *N-dimensional generalized combinatorial maps and cellular
quasi-manifolds*, IJCGA 4(3), 1994.
"""

from __future__ import annotations

from collections import deque

import numpy as np

VERTEX_BITS = 24
VERTEX_MASK = (1 << VERTEX_BITS) - 1
MAX_VOLUMES = 127          # the label takes the 7 bits above the vertex index
MAX_VERTICES = 1 << VERTEX_BITS

VERTEX, EDGE, FACE, VOLUME = (1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2)
FACE2 = (0, 1)             # one side of a face (inside one volume)
CORNER = (1, 2)            # the vertex inside one volume


class GMapError(ValueError):
    """An invalid map or an operation that does not apply."""


class GMap:
    """A 3-G-map with vertex positions and volume labels.

    Parameters
    ----------
    capacity : int
        Initial number of dart slots (grows by doubling).

    Attributes
    ----------
    alpha : ndarray, shape (4, capacity), int32
        ``alpha[i, d]`` is α_i(d); ``alpha[0, d] == -1`` marks an unused slot.
    attr : ndarray, shape (capacity,), int32
        Vertex index (low 24 bits) and volume label (high bits) of each dart.
    points : ndarray, shape (n_points, 3), float64
        One position per vertex orbit.
    """

    def __init__(self, capacity: int = 64):
        capacity = max(int(capacity), 4)
        self.alpha = np.full((4, capacity), -1, dtype=np.int32)
        self.attr = np.zeros(capacity, dtype=np.int32)
        self._points = np.zeros((16, 3))
        self.n_points = 0
        self._top = 0              # slots [0, _top) have been handed out once
        self._free: list[int] = []

    # ------------------------------------------------------------------ storage
    @property
    def capacity(self) -> int:
        return self.alpha.shape[1]

    @property
    def points(self) -> np.ndarray:
        return self._points[:self.n_points]

    def darts(self) -> np.ndarray:
        """Ids of the used darts, ascending."""
        return np.flatnonzero(self.alpha[0, :self._top] >= 0)

    @property
    def n_darts(self) -> int:
        return int(np.count_nonzero(self.alpha[0, :self._top] >= 0))

    def nbytes(self) -> int:
        """Bytes of the dart arrays (capacity slots) plus the vertex positions."""
        return self.alpha.nbytes + self.attr.nbytes + self.points.nbytes

    def dart_bytes(self) -> float:
        """Bytes a dart slot: ``(alpha.nbytes + attr.nbytes) / capacity`` (20)."""
        return (self.alpha.nbytes + self.attr.nbytes) / self.capacity

    def new_darts(self, n: int, vertex: int = 0, volume: int = 0) -> list[int]:
        """``n`` fresh darts, every α_i a fixed point."""
        out = []
        while self._free and len(out) < n:
            out.append(self._free.pop())
        need = n - len(out)
        if self._top + need > self.capacity:
            cap = max(2 * self.capacity, self._top + need)
            alpha = np.full((4, cap), -1, dtype=np.int32)
            alpha[:, :self.capacity] = self.alpha
            attr = np.zeros(cap, dtype=np.int32)
            attr[:self.capacity] = self.attr
            self.alpha, self.attr = alpha, attr
        out.extend(range(self._top, self._top + need))
        self._top += need
        for d in out:
            self.alpha[:, d] = d
            self.attr[d] = (volume << VERTEX_BITS) | vertex
        return out

    def delete(self, darts) -> None:
        """Free dart slots (the caller has unlinked them from the rest)."""
        for d in darts:
            self.alpha[:, d] = -1
            self.attr[d] = 0
            self._free.append(int(d))

    def add_point(self, p) -> int:
        if self.n_points >= MAX_VERTICES:
            raise GMapError(f"more than {MAX_VERTICES} vertices")
        if self.n_points == len(self._points):
            grown = np.zeros((2 * len(self._points), 3))
            grown[:self.n_points] = self._points[:self.n_points]
            self._points = grown
        self._points[self.n_points] = p
        self.n_points += 1
        return self.n_points - 1

    def compact(self) -> None:
        """Renumber used darts to 0..n-1 and drop unused slots and vertices."""
        used = self.darts()
        remap = np.full(self.capacity, -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        self.alpha = remap[self.alpha[:, used]].astype(np.int32)
        verts = self.attr[used] & VERTEX_MASK
        vols = self.attr[used] >> VERTEX_BITS
        vused, vinv = np.unique(verts, return_inverse=True)
        self._points = self._points[vused].copy()
        self.n_points = len(vused)
        self.attr = ((vols << VERTEX_BITS) | vinv).astype(np.int32)
        self._top = len(used)
        self._free = []

    def copy(self) -> "GMap":
        g = GMap.__new__(GMap)
        g.alpha, g.attr, g._points = self.alpha.copy(), self.attr.copy(), self._points.copy()
        g.n_points, g._top, g._free = self.n_points, self._top, list(self._free)
        return g

    # --------------------------------------------------------------- attributes
    def a(self, i: int, d: int) -> int:
        return int(self.alpha[i, d])

    def vertex(self, d: int) -> int:
        return int(self.attr[d]) & VERTEX_MASK

    def volume(self, d: int) -> int:
        return int(self.attr[d]) >> VERTEX_BITS

    def set_vertex(self, darts, v: int) -> None:
        for d in darts:
            self.attr[d] = (int(self.attr[d]) & ~VERTEX_MASK) | v

    def set_volume(self, darts, label: int) -> None:
        if not 0 <= label <= MAX_VOLUMES:
            raise GMapError(f"volume label must be in [0, {MAX_VOLUMES}] (got {label})")
        for d in darts:
            self.attr[d] = (label << VERTEX_BITS) | (int(self.attr[d]) & VERTEX_MASK)

    def pos(self, d: int) -> np.ndarray:
        return self._points[self.vertex(d)]

    def vertex_ids(self) -> np.ndarray:
        return self.attr[:self._top] & VERTEX_MASK

    def volume_ids(self) -> np.ndarray:
        return self.attr[:self._top] >> VERTEX_BITS

    # -------------------------------------------------------------- involutions
    def link(self, i: int, d: int, e: int) -> None:
        self.alpha[i, d] = e
        self.alpha[i, e] = d

    def unlink(self, i: int, d: int) -> None:
        e = self.a(i, d)
        self.alpha[i, d] = d
        self.alpha[i, e] = e

    def is_free(self, i: int, d: int) -> bool:
        return self.a(i, d) == d

    def orbit(self, d: int, indices) -> list[int]:
        """Darts reachable from ``d`` through the involutions ``indices`` (BFS order)."""
        seen = {d}
        out = [d]
        queue = deque([d])
        alpha = self.alpha
        while queue:
            x = queue.popleft()
            for i in indices:
                y = int(alpha[i, x])
                if y not in seen:
                    seen.add(y)
                    out.append(y)
                    queue.append(y)
        return out

    def face_cycle(self, d: int) -> list[int]:
        """Darts of one side of a face, alternately α0 then α1 from ``d``.

        Positions ``2k, 2k+1`` hold the two darts of the k-th edge; the vertex
        of position ``2k`` is the k-th corner of the polygon.
        """
        a0, a1 = self.alpha[0], self.alpha[1]
        out = [d]
        x = d
        limit = 4 * self.capacity
        while True:
            x = int(a0[x])
            out.append(x)
            x = int(a1[x])
            if x == d:
                return out
            out.append(x)
            if len(out) > limit:
                raise GMapError(f"face cycle of dart {d} does not close")

    def face_vertices(self, d: int) -> list[int]:
        """Vertex ids of the face side of ``d``, in cycle order."""
        return [self.vertex(x) for x in self.face_cycle(d)[0::2]]

    def faces(self, label: int | None = None) -> list[int]:
        """One dart of each face side (⟨α0, α1⟩ orbit), optionally of one volume."""
        out, seen = [], np.zeros(self._top, dtype=bool)
        for d in self.darts():
            if seen[d] or (label is not None and self.volume(int(d)) != label):
                continue
            cyc = self.face_cycle(int(d))
            seen[cyc] = True
            out.append(int(d))
        return out

    def labels(self) -> list[int]:
        return sorted(set(int(v) for v in self.volume_ids()[self.darts()]))

    def vertex_darts(self, v: int) -> np.ndarray:
        """All darts carrying vertex id ``v``."""
        ids = self.vertex_ids()
        return np.flatnonzero((ids == v) & (self.alpha[0, :self._top] >= 0))

    # ------------------------------------------------------------------ sewing
    def sew3(self, d: int, e: int) -> None:
        """α3-sew the face side of ``d`` to that of ``e`` (``d`` meets ``e``)."""
        cd, ce = self.face_cycle(d), self.face_cycle(e)
        if len(cd) != len(ce):
            raise GMapError(f"cannot sew faces of {len(cd) // 2} and {len(ce) // 2} edges")
        # face_cycle(e) starts with α0 as face_cycle(d) does, so positions match.
        for x, y in zip(cd, ce):
            if not (self.is_free(3, x) and self.is_free(3, y)):
                raise GMapError("sew3 on a face that is already sewn")
            self.link(3, x, y)

    def unsew3(self, d: int) -> None:
        for x in self.face_cycle(d):
            if not self.is_free(3, x):
                self.unlink(3, x)

    # -------------------------------------------------------- cell insertion
    def insert_vertex(self, d: int, p) -> int:
        """Insert a vertex at ``p`` on the edge of ``d`` (in every face and volume).

        Each dart x of the edge orbit ⟨α0, α2, α3⟩ gets a new dart n(x) with
        α0(x) = n(x), α1(n(x)) = n(α0_old(x)), α2/α3 mirrored.

        Returns
        -------
        int
            The new dart next to ``d`` (it carries the new vertex).
        """
        edge = self.orbit(d, EDGE)
        v = self.add_point(p)
        new = dict(zip(edge, self.new_darts(len(edge), vertex=v)))
        old0 = {x: self.a(0, x) for x in edge}
        for x in edge:
            n = new[x]
            self.attr[n] = (self.volume(x) << VERTEX_BITS) | v
            self.alpha[0, x], self.alpha[0, n] = n, x
            self.alpha[1, n] = new[old0[x]]
            self.alpha[2, n] = new[self.a(2, x)]
            self.alpha[3, n] = new[self.a(3, x)]
        return new[d]

    def split_face(self, c1: int, c2: int) -> int:
        """Insert an edge between two corners of a face (mirrored on its α3 side).

        ``c1`` and ``c2`` are *corner darts* of the same face side: darts at even
        positions of a :meth:`face_cycle` (``α1`` leads back to the previous
        edge). The face splits into the part from ``c1`` to the dart before
        ``c2`` and the rest.

        Returns
        -------
        int
            The new dart at the vertex of ``c1`` that lies in the face of ``c1``.
        """
        out = self._split_face_side(c1, c2)
        if not self.is_free(3, c1):
            other = self._split_face_side(self.a(3, c1), self.a(3, c2))
            for x, y in zip(out, other):
                self.link(3, x, y)
        return out[0]

    def _split_face_side(self, c1: int, c2: int):
        cyc = self.face_cycle(c1)
        try:
            j = cyc.index(c2)
        except ValueError:
            raise GMapError("split_face: corners are not in the same face") from None
        if j % 2 or j in (0, 2, len(cyc) - 2):
            raise GMapError("split_face: corners must be distinct, non-adjacent corner darts")
        p1, p2 = self.a(1, c1), self.a(1, c2)      # previous-edge darts at c1, c2
        vol = self.volume(c1)
        u, w = self.vertex(c1), self.vertex(c2)
        # Face A keeps c1 .. (dart before c2); face B keeps c2 .. p1.
        a_u, a_w, b_u, b_w = self.new_darts(4, volume=vol)
        self.set_vertex((a_u, b_u), u)
        self.set_vertex((a_w, b_w), w)
        self.link(1, c1, a_u)
        self.link(0, a_u, a_w)
        self.link(1, a_w, p2)
        self.link(1, c2, b_w)
        self.link(0, b_w, b_u)
        self.link(1, b_u, p1)
        self.link(2, a_u, b_u)
        self.link(2, a_w, b_w)
        return a_u, a_w, b_u, b_w

    def relink_corners(self, c1: int, c2: int) -> None:
        """Fig. 9: swap the α1 links at two corners of one face side (and its α3 side).

        With α1(a) = b at ``c1 = a`` and α1(c) = d at ``c2 = c``, the links become
        α1(a) = d and α1(b) = c: the face splits in two and the two vertices
        become one vertex orbit (the caller merges their positions/ids).
        """
        pairs = [(c1, c2)]
        if not self.is_free(3, c1):
            pairs.append((self.a(3, c1), self.a(3, c2)))
        for a, c in pairs:
            b, dd = self.a(1, a), self.a(1, c)
            self.link(1, a, dd)
            self.link(1, b, c)

    # ------------------------------------------------ removal and contraction
    def contract_edge(self, d: int, p=None) -> int:
        """Contract the edge of ``d``: its two vertices become one at ``p``.

        For every dart x of the edge orbit, its α1 neighbours at both ends are
        linked to each other and the edge's darts are deleted (the faces around
        the edge lose one edge; a triangle becomes a digon, see
        :meth:`remove_digon`). Returns a surviving dart of the merged vertex.
        """
        edge = self.orbit(d, EDGE)
        keep_v = self.vertex(d)
        survivor = None
        eset = set(edge)
        for x in edge:  # check every face first: contraction must not start half-done
            bx, by = self.a(1, x), self.a(1, self.a(0, x))
            if bx in eset or by in eset or self.a(0, bx) == by:
                raise GMapError("contract_edge: a face of the edge has fewer than three edges")
        for x in edge:
            y = self.a(0, x)
            if x > y:
                continue
            bx, by = self.a(1, x), self.a(1, y)
            if bx in eset or by in eset or self.a(0, bx) == by:
                raise GMapError("contract_edge: a face of the edge has fewer than three edges")
            self.link(1, bx, by)
            survivor = bx
        self.delete(edge)
        merged = self.orbit(survivor, VERTEX)
        self.set_vertex(merged, keep_v)
        if p is not None:
            self._points[keep_v] = p
        return survivor

    def remove_digon(self, d: int) -> None:
        """Remove a face of two edges, α2-sewing its neighbours across it.

        The digon's two edges become one edge: for each dart x of the digon side,
        the faces beyond its two edges (α2 of x and of its parallel dart) are
        linked with α2. Applied to both α3 sides of the digon.
        """
        cyc = self.face_cycle(d)
        if len(cyc) != 4:
            raise GMapError(f"remove_digon: the face has {len(cyc) // 2} edges")
        sides = [cyc]
        if not self.is_free(3, d):
            sides.append([self.a(3, x) for x in cyc])
        for c in sides:
            # c = [x0 (u), x1 (w), x2 (w), x3 (u)]: edge (x0, x1) is parallel to (x3, x2).
            for x, y in ((c[0], c[3]), (c[1], c[2])):
                ex, ey = self.a(2, x), self.a(2, y)
                if ex in c or ey in c:
                    raise GMapError("remove_digon: the digon is sewn to itself")
                self.link(2, ex, ey)
        for c in sides:
            self.delete(c)

    # ---------------------------------------------------------------- checks
    def check(self) -> None:
        """Raise :class:`GMapError` unless the map is a valid closed 3-G-map.

        Checks: α_i(d) is a used dart; α_i is an involution (i = 0..3); α0, α1,
        α2 have no fixed point; α0α2, α0α3 and α1α3 are involutions; all darts
        of a vertex orbit carry one vertex id and those of a volume one label.
        """
        ds = self.darts()
        alpha = self.alpha.astype(np.int64)
        for i in range(4):
            img = alpha[i, ds]
            if np.any((img < 0) | (img >= self._top)) or np.any(alpha[0, img] < 0):
                raise GMapError(f"α{i} leads to an unused dart")
            bad = ds[alpha[i, img] != ds]
            if len(bad):
                raise GMapError(f"α{i} is not an involution at dart {bad[0]}")
            if i < 3 and np.any(img == ds):
                raise GMapError(f"α{i} has a fixed point at dart {ds[img == ds][0]} (open cell)")
        for i, j in ((0, 2), (0, 3), (1, 3)):
            ij = alpha[i, alpha[j, ds]]
            bad = ds[alpha[i, alpha[j, ij]] != ds]
            if len(bad):
                raise GMapError(f"α{i}α{j} is not an involution at dart {bad[0]}")
        vid, vol = self.vertex_ids(), self.volume_ids()
        for i in (1, 2, 3):
            if np.any(vid[alpha[i, ds]] != vid[ds]):
                raise GMapError(f"vertex ids differ across α{i} (vertex orbit)")
        for i in (0, 1, 2):
            if np.any(vol[alpha[i, ds]] != vol[ds]):
                raise GMapError(f"volume labels differ across α{i} (volume orbit)")
        if np.any(vid[ds] >= self.n_points):
            raise GMapError("a dart has no vertex position")

    # ---------------------------------------------------------- orbit counts
    def _components(self, darts, maps) -> np.ndarray:
        """Component index (per dart of ``darts``) of the graph joined by ``maps``."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components
        idx = np.full(self._top, -1, dtype=np.int64)
        idx[darts] = np.arange(len(darts))
        rows, cols = [], []
        for m in maps:
            rows.append(np.arange(len(darts)))
            cols.append(idx[m])
        r, c = np.concatenate(rows), np.concatenate(cols)
        g = coo_matrix((np.ones(len(r)), (r, c)), shape=(len(darts), len(darts)))
        return connected_components(g, directed=False)[1]

    def cell_counts(self, darts=None, a2=None) -> tuple[int, int, int]:
        """(V, E, F) of the 2-map ⟨α0, α1, α2'⟩ restricted to ``darts``.

        ``a2`` replaces α2 (used for the outer surface); default α2.
        """
        ds = self.darts() if darts is None else np.asarray(darts)
        a0, a1 = self.alpha[0, ds], self.alpha[1, ds]
        a2 = self.alpha[2, ds] if a2 is None else a2
        v = len(np.unique(self._components(ds, (a1, a2))))
        e = len(np.unique(self._components(ds, (a0, a2))))
        f = len(np.unique(self._components(ds, (a0, a1))))
        return v, e, f

    def volume_topology(self) -> list[dict]:
        """Per connected volume (⟨α0, α1, α2⟩ orbit): label, χ = V − E + F, genus.

        Each volume boundary is a closed orientable surface, so genus = (2 − χ)/2.
        """
        ds = self.darts()
        comp = self._components(ds, (self.alpha[0, ds], self.alpha[1, ds], self.alpha[2, ds]))
        out = []
        for c in np.unique(comp):
            sub = ds[comp == c]
            v, e, f = self.cell_counts(sub)
            chi = v - e + f
            out.append(dict(label=self.volume(int(sub[0])), darts=len(sub), V=v, E=e, F=f,
                            euler=chi, genus=(2 - chi) / 2))
        return out

    def boundary_alpha2(self) -> tuple[np.ndarray, np.ndarray]:
        """Darts of the outer surface (α3 free) and its α2': α2, then α3α2 until free."""
        ds = self.darts()
        bd = ds[self.alpha[3, ds] == ds]
        out = np.empty(len(bd), dtype=np.int64)
        for k, d in enumerate(bd):
            e = self.a(2, int(d))
            guard = 0
            while not self.is_free(3, e):
                e = self.a(2, self.a(3, e))
                guard += 1
                if guard > self._top:
                    raise GMapError("outer surface walk does not end")
            out[k] = e
        return bd, out

    def surface_topology(self) -> list[dict]:
        """χ and genus of each component of the terrain's outer surface (α3-free faces)."""
        bd, a2 = self.boundary_alpha2()
        if len(bd) == 0:
            return []
        comp = self._components(bd, (self.alpha[0, bd], self.alpha[1, bd], a2))
        out = []
        for c in np.unique(comp):
            m = comp == c
            v, e, f = self.cell_counts(bd[m], a2[m])
            chi = v - e + f
            out.append(dict(V=v, E=e, F=f, euler=chi, genus=(2 - chi) / 2))
        return out
