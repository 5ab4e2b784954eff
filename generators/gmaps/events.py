"""The event priority queue of the paper (§3.1): vertex displacements until no event.

A displacement moves vertex P of volume ``label`` along the segment P_t P_{t+1}.
Displacements sit in a queue sorted by the time of their first collision with a
face of the volume (P moves into it) or an edge of the face P slides on; those
without a collision come last and are applied as they are. After each event
the collision times of the remaining items are recomputed (the event changed
faces), and the remainder of the processed displacement, from the collision
point, is re-injected (paper: "we also must re-inject displacement P_t P_{t+1}
in the event queue"). The queue is empty at the end of a simulation step.

Events (see :mod:`.operations`):

``split``     P lies in several volumes (§3.2): the volume it erodes gets its copy.
``slide``     P slides on a face and reaches one of its edges (§3.3).
``hole``      P crosses a face not joined to it by an edge (§3.4, Fig. 5c/5d).
``contract``  P reaches a face joined to it by one edge (§3.4, Fig. 7a).
``collapse``  P reaches a face joined to two consecutive corners of it: the
              flattened triangles fold onto the face (Fig. 7b/c).
``pinch``     after a vertex–face event, a vertex around which the faces of one
              volume form several cycles (§3.5).

Contextual constraint (§3.1): a displacement may only remove matter: P must move
into its volume or slide on one of its faces; otherwise :class:`GMapError`.

Symbolic perturbation (§3.1): a segment through an edge or a vertex of the
triangulated faces hits exactly one triangle (:func:`geometry.first_hit`); a
sliding vertex headed exactly at a corner of its face is deflected by a tiny
in-plane offset (§3.3: "slightly modifying the displacement").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import operations as op
from .face_collapse import vertex_face_collapse
from .geometry import face_triangles, first_hit, oriented_faces, project, winding_number
from .gmap import GMap, GMapError

TOL = 1e-9


@dataclass
class Displacement:
    """Move vertex ``vertex`` of volume ``label`` to ``target``.

    ``shared``: the vertex may slide on a face shared by its two volumes, eroding
    both (no split); otherwise only ``label`` is eroded and a shared vertex is
    split first (§3.2).
    """
    vertex: int
    label: int
    target: np.ndarray
    seq: int = 0
    shared: bool = False


class EventQueue:
    """Processes displacements on a map, one event at a time.

    Parameters
    ----------
    gmap : GMap
    seed : int
        Seed of the random order in which a vertex leaves several volumes (§3.2).
    check : bool
        Run :meth:`GMap.check` after every event (the tests do).
    push : float
        How far past a crossed face a drilling vertex is placed before the hole is
        cut, as a fraction of the face's size (the paper moves it to P_{t+1}; a
        short push keeps the hole small and the rest of the move re-injected).
    """

    def __init__(self, gmap: GMap, seed: int = 0, check: bool = True, push: float = 0.25,
                 on_event=None):
        self.g = gmap
        self.rng = np.random.default_rng(seed)
        self.check = check
        self.push = push
        self.on_event = on_event
        self.log: list[tuple] = []
        self.items: list[Displacement] = []
        self._seq = 0
        self.n_events = 0

    # ----------------------------------------------------------------- queue
    def add(self, vertex: int, label: int, target, shared: bool = False) -> None:
        """Queue a displacement (see :class:`Displacement`)."""
        self._seq += 1
        self.items.append(Displacement(int(vertex), int(label), np.asarray(target, float), self._seq, shared))

    def run(self) -> int:
        """Process every displacement (and re-injected remainder); returns events."""
        n = 0
        pops = 0
        while self.items:
            pops += 1
            if pops > 100000:
                raise GMapError("event queue does not empty (an event keeps re-injecting itself)")
            timed = []
            for it in self.items:
                ev = self._next_event(it)
                timed.append((ev[0] if ev else np.inf, it.seq, it, ev))
            timed.sort(key=lambda x: (x[0], x[1]))
            _, _, it, ev = timed[0]
            self.items.remove(it)
            if self._apply(it, ev):
                n += 1
        return n

    # --------------------------------------------------------------- events
    def _alive(self, it) -> bool:
        return len(op.darts_at(self.g, it.vertex, it.label)) > 0

    def _next_event(self, it):
        """(t, kind, data) of the first event of ``it`` or None (free move)."""
        g = self.g
        if not self._alive(it):
            return (0.0, "drop", None)
        p0 = g.points[it.vertex].copy()
        d = it.target - p0
        if np.linalg.norm(d) <= TOL:
            return (0.0, "drop", None)
        labels = {g.volume(x) for x in op.darts_at(g, it.vertex)}
        if labels != {it.label}:
            # Sliding on a face shared by the two volumes of the vertex removes
            # matter from both: no split needed (the split is only there to avoid
            # volume growth, §3.2).
            slide = self._sliding_face(it.vertex, it.label, d) if it.shared else None
            if not (slide is not None and len(labels) == 2 and not g.is_free(3, slide)
                    and labels == {g.volume(slide), g.volume(g.a(3, slide))}):
                return (0.0, "split", None)
            op.prepare_motion(g, it.vertex, d, None)
            return self._slide_event(it, slide, p0, d)
        op.prepare_motion(g, it.vertex, d, it.label)
        slide = self._sliding_face(it.vertex, it.label, d)
        if slide is not None:
            return self._slide_event(it, slide, p0, d)
        faces = oriented_faces(g, it.label)
        tris, owner = [], []
        for _, fs in faces:
            t, o = face_triangles(g, fs)
            tris.append(t)
            owner.append(o)
        tris, owner = np.concatenate(tris), np.concatenate(owner)
        eps = 1e-6 * np.linalg.norm(d)
        if winding_number(g.points, tris, p0 + eps * d / np.linalg.norm(d)) < 0.5:
            raise GMapError(f"displacement of vertex {it.vertex} leaves volume {it.label}: it would add "
                            "matter (contextual constraint, paper §3.1)")
        hit = first_hit(p0, it.target, g.points, tris, skip_vertex=it.vertex)
        if hit is None:
            return None
        t, k, x = hit
        return (t, "face", (int(owner[k]), x))

    def _sliding_face(self, v, label, d):
        """Corner dart of a face at ``v`` whose plane holds ``d`` and that ``d`` enters."""
        g = self.g
        for c in op.faces_at(g, v, label):
            if not op.in_plane(g, c, d, tol=1e-7):
                continue
            o, n = op.face_plane(g, c)
            vids = g.face_vertices(c)
            xy = project(g.points[vids], n)
            q = project(np.atleast_2d(g.points[v] + 1e-6 * d), n)[0]
            if op.point_in_polygon(q, xy):
                return c
        return None

    def _slide_event(self, it, corner, p0, d):
        g = self.g
        cyc = g.face_cycle(corner)
        o, n = op.face_plane(g, corner)
        best = None
        a0 = project(np.atleast_2d(p0), n)[0]
        ids = [g.vertex(x) for x in cyc]
        xy = project(g.points[ids], n)
        for attempt in range(3):
            a1 = project(np.atleast_2d(it.target), n)[0]
            best, corner_hit = None, False
            for k in range(0, len(cyc), 2):
                u, w = ids[k], ids[k + 1]
                if it.vertex in (u, w):
                    continue
                b0, b1 = xy[k], xy[k + 1]
                r, s = a1 - a0, b1 - b0
                den = r[0] * s[1] - r[1] * s[0]
                if abs(den) < 1e-15:
                    continue
                q = b0 - a0
                t = (q[0] * s[1] - q[1] * s[0]) / den
                sp = (q[0] * r[1] - q[1] * r[0]) / den
                if 0 < t <= 1 + 1e-12 and -1e-12 <= sp <= 1 + 1e-12:
                    if sp < 1e-9 or sp > 1 - 1e-9:
                        corner_hit = True
                    if best is None or t < best[0]:
                        best = (t, cyc[k], sp)
            if not corner_hit:
                break
            # vertex–vertex collision: deflect the displacement in the face plane (§3.3)
            perp = np.cross(n, d)
            it.target = it.target + 1e-4 * np.linalg.norm(d) * perp / np.linalg.norm(perp)
        if best is None:
            return None
        t, x0, sp = best
        u, w = g.vertex(x0), g.vertex(g.a(0, x0))
        x = g.points[u] + sp * (g.points[w] - g.points[u])
        return (t, "slide", (corner, x0, x))

    def _apply(self, it, ev) -> bool:
        g = self.g
        if ev is None:
            g.points[it.vertex] = it.target
            if self.check:                  # faces around it may have been triangulated
                g.check()
            return False
        t, kind, data = ev
        if kind == "drop":
            return False
        p0 = g.points[it.vertex].copy()
        d = it.target - p0
        if kind == "split":
            nv = op.vertex_split(g, it.vertex, it.label, d, self.rng)
            self._log("split", it.vertex, nv)
            self.items.append(Displacement(nv, it.label, it.target, it.seq, it.shared))
        elif kind == "slide":
            corner, edge_dart, x = data
            v = op.slide_edge(g, corner, edge_dart, x)
            self._log("slide", v, x)
            self.items.append(Displacement(v, it.label, it.target, it.seq, it.shared))
        elif kind == "face":
            fdart, x = data
            fverts = set(g.face_vertices(fdart))
            joined = set(op.neighbours(g, it.vertex, it.label)) & fverts
            corners = g.face_vertices(fdart)
            tris = {frozenset(g.face_vertices(c)) for c in op.faces_at(g, it.vertex, it.label)}
            consecutive = any(frozenset((it.vertex, corners[k], corners[(k + 1) % len(corners)])) in tris
                              for k in range(len(corners)))
            if consecutive:
                res = vertex_face_collapse(g, it.vertex, it.label, fdart, x, self.new_label)
                self._log("collapse", it.vertex, res["removed"])
                if res["pinch"]:
                    self._log("pinch", it.vertex, it.label, res["pinch"])
            elif joined:
                w = op.contract_to_face(g, it.vertex, it.label, fdart)
                self._log("contract", it.vertex, w)
                self._pinch([w])
            else:
                size = np.ptp(g.points[list(fverts)], axis=0).max()
                dn = np.linalg.norm(d)
                remaining = (1 - t) * dn
                # The paper cuts the hole with P at P_{t+1}; the step past the face is
                # capped (a fraction of the face) so the hole stays inside it, and
                # halved if it still does not fit.
                step = min(self.push * size, remaining) if remaining > TOL else 1e-3 * size
                saved = g.points[it.vertex].copy()
                for _ in range(12):
                    g.points[it.vertex] = x + step * d / dn
                    try:
                        res = op.vertex_face_hole(g, it.vertex, it.label, fdart)
                        break
                    except GMapError:
                        g.points[it.vertex] = saved
                        step *= 0.5
                else:
                    raise GMapError(f"vertex {it.vertex}: no hole fits in the face it crosses")
                self._log("hole", it.vertex, res["behind"], tuple(res["ring"]))
                if res["vertex"] is not None and np.linalg.norm(it.target - g.points[it.vertex]) > TOL \
                        and (it.target - g.points[it.vertex]) @ d > 0:
                    self.items.append(Displacement(it.vertex, res["behind"], it.target, it.seq, it.shared))
                self._pinch(res["ring"])
        if self.check:
            g.check()
        self.n_events += 1
        if self.on_event:
            self.on_event(self)
        return True

    def _pinch(self, vertices):
        g = self.g
        for v in vertices:
            for lab in sorted({g.volume(x) for x in op.darts_at(g, v)}):
                new = op.volume_pinch(g, v, lab, self.new_label)
                if new:
                    self._log("pinch", v, lab, new)

    def new_label(self) -> int:
        """A volume label not in use (for a volume split by pinching)."""
        return max(self.g.labels()) + 1

    def _log(self, kind, *data):
        self.log.append((kind,) + data)

    def counts(self) -> dict:
        out = {}
        for e in self.log:
            out[e[0]] = out.get(e[0], 0) + 1
        return out
