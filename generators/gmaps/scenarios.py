"""The three evolution scenarios of the paper (§4.2) as seeded, reproducible runs.

==========  ======================================================================
scenario    what happens (atomic operations in brackets)
==========  ======================================================================
arch        A sandstone fin on a limestone ground (two volumes, Fig. 1). The
            vertex at the middle of the fin's front base, shared by both volumes,
            is split [split] and slides along the base towards the back until it
            reaches the back edge [slide: vertex insertion + Fig. 9 face split],
            undercutting the fin. Then a vertex of the front face erodes through
            the fin and crosses its back face [hole, Fig. 5c]: the fin gets a
            window (genus one), which successive slides of the hole's corners
            along the back face enlarge.
drilling    Four horizontal layers (Fig. 10). The centre vertex of the top
            surface descends at the erosion rate of the layer it is in; at each
            interface it cuts a hole and goes on as a dip of the next layer
            [hole, Fig. 5d]; the holes' corners then slide outward along the
            interfaces, widening the shaft.
cavern      Hard limestone over soft sandstone over basalt (Fig. 11). A vertex
            drills through the hard top and through the soft layer into the
            basalt [hole, Fig. 5d]; then vertices inserted half-way up the soft
            layer's shaft walls move outward at the soft rate: a cavern opens in
            the soft layer only (differential erosion).
==========  ======================================================================

Every rate is in metres per step; the seed jitters rates and directions by a few
per cent (the same seed gives the same map, bit for bit). ``steps`` cuts a run
short; each scenario has a default length.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import operations as op
from .builders import Lattice, find_face, find_vertex, layer_stack, star_vertex
from .events import EventQueue
from .gmap import GMap

SCENARIOS = ("arch", "drilling", "cavern")
RATES = {"sandstone": 0.16, "limestone": 0.10, "basalt": 0.05}   # m / step


@dataclass
class Result:
    """A finished (or cut short) run."""
    name: str
    gmap: GMap
    materials: dict                      # volume label -> material preset
    steps: int
    log: list = field(default_factory=list)
    events: int = 0

    def counts(self) -> dict:
        out = {}
        for e in self.log:
            out[e[0]] = out.get(e[0], 0) + 1
        return out


def default_steps(name: str) -> int:
    return {"arch": 14, "drilling": 16, "cavern": 14}[name]


def run(name: str, seed: int = 0, steps: int | None = None, on_step=None, check: bool = True) -> Result:
    """Run scenario ``name``.

    Parameters
    ----------
    name : {'arch', 'drilling', 'cavern'}
    seed : int
    steps : int, optional
        Number of simulation steps (default :func:`default_steps`).
    on_step : callable, optional
        ``on_step(step, result)`` after every step (e.g. to export meshes).
    check : bool
        Check the map's validity after every event.

    Returns
    -------
    Result
    """
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r} (one of {', '.join(SCENARIOS)})")
    n = default_steps(name) if steps is None else int(steps)
    rng = np.random.default_rng(seed)
    return {"arch": _arch, "drilling": _drilling, "cavern": _cavern}[name](rng, seed, n, on_step, check)


def _rates(rng):
    return {k: v * (1 + 0.08 * rng.uniform(-1, 1)) for k, v in RATES.items()}


def _label_of(g, v):
    labs = {g.volume(d) for d in op.darts_at(g, v)}
    return min(labs) if labs else None


def _finish(res: Result, q: EventQueue):
    res.log = q.log
    res.events = q.n_events
    for e in q.log:
        if e[0] == "pinch":                         # ("pinch", vertex, label, new labels)
            for lab in e[3]:
                res.materials.setdefault(lab, res.materials.get(e[2], "default"))
    return res


# ------------------------------------------------------------------ drilling
def _drill_setup(rng, z_levels, materials):
    g = layer_stack((-1.5, -1.5, 1.5, 1.5), z_levels, cells=(3, 3))
    top = find_face(g, 0, (0.0, 0.0, z_levels[0]), 2)
    v = star_vertex(g, top, (0.0, 0.0, z_levels[0]))
    g.check()
    tilt = rng.normal(0.0, 0.03, 2)
    direction = np.array([tilt[0], tilt[1], -1.0])
    return g, v, direction / np.linalg.norm(direction)


def _widen(g, q, rings, amount, max_radius):
    """Queue outward slides of hole corners along their interface (plane z = const)."""
    for ring, centre in rings:
        for h in ring:
            if not len(g.vertex_darts(h)):
                continue
            r = g.points[h] - centre
            r[2] = 0.0
            rad = np.linalg.norm(r)
            if rad <= 0 or rad + amount > max_radius:
                continue
            lab = _label_of(g, h)
            q.add(h, lab, g.points[h] + amount * r / rad, shared=True)


def _drilling(rng, seed, n, on_step, check):
    mats = {0: "sandstone", 1: "limestone", 2: "basalt", 3: "sandstone"}
    rates = _rates(rng)
    g, v, direction = _drill_setup(rng, [1.6, 1.2, 0.8, 0.4, 0.0], mats)
    q = EventQueue(g, seed=seed, check=check)
    res = Result("drilling", g, mats, 0)
    rings = []
    for step in range(n):
        seen = len(q.log)
        if len(g.vertex_darts(v)):
            lab = _label_of(g, v)
            q.add(v, lab, g.points[v] + rates[mats[lab]] * direction)
        _widen(g, q, rings, 0.5 * rates["limestone"], 0.45)
        q.run()
        for e in q.log[seen:]:
            if e[0] == "hole":                      # ("hole", vertex, behind, ring)
                ring = list(e[3])
                rings.append((ring, g.points[ring].mean(axis=0)))
        res.steps = step + 1
        if on_step:
            on_step(step, _finish(res, q))
    return _finish(res, q)


# -------------------------------------------------------------------- cavern
def _cavern(rng, seed, n, on_step, check):
    mats = {0: "limestone", 1: "sandstone", 2: "basalt"}
    rates = _rates(rng)
    rates["sandstone"] *= 1.6                      # the soft layer
    g, v, direction = _drill_setup(rng, [1.6, 1.2, 0.5, 0.0], mats)
    q = EventQueue(g, seed=seed, check=check)
    res = Result("cavern", g, mats, 0)
    rings, mids = [], []
    lateral = 0.45 * rates["sandstone"] * (1 + 0.1 * rng.uniform(-1, 1, 64))
    for step in range(n):
        seen = len(q.log)
        if len(g.vertex_darts(v)):
            lab = _label_of(g, v)
            if lab == 2 and len(rings) >= 2 and not mids:
                mids = _insert_wall_vertices(g, rings[0][0], rings[1][0], label=1)
            if lab != 2 or step % 3 == 0:
                q.add(v, lab, g.points[v] + rates[mats[lab]] * direction)
        centre = rings[0][1] if rings else None
        if mids:
            _widen(g, q, rings[:1], 0.3 * rates["limestone"], 0.3)
        for k, m in enumerate(mids):
            r = g.points[m] - centre
            r[2] = 0.0
            rad = np.linalg.norm(r)
            if rad + lateral[k] <= 1.05:
                q.add(m, 1, g.points[m] + lateral[k] * r / rad)
        q.run()
        for e in q.log[seen:]:
            if e[0] == "hole":
                ring = list(e[3])
                rings.append((ring, g.points[ring].mean(axis=0)))
        res.steps = step + 1
        if on_step:
            on_step(step, _finish(res, q))
    return _finish(res, q)


def _insert_wall_vertices(g, upper, lower, label):
    """A vertex half-way up each shaft-wall edge joining ring ``upper`` to ``lower``,
    and an edge between consecutive ones across each wall (cell insertions), so the
    wall is a band of quads that can bulge outward."""
    out = []
    lower = set(lower)
    for h in upper:
        for d in op.darts_at(g, h, label):
            w = g.vertex(g.a(0, d))
            if w in lower:
                p = 0.5 * (g.points[h] + g.points[w])
                out.append(g.vertex(g.insert_vertex(d, p)))
                lower.discard(w)
                break
    mids = set(out)
    for m in out:
        for c in op.faces_at(g, m, label):
            cyc = g.face_cycle(c)
            others = [k for k in range(4, len(cyc) - 2, 2) if g.vertex(cyc[k]) in mids]
            if len(cyc) > 8 and others:
                g.split_face(c, cyc[others[0]])
    g.check()
    return out


# ---------------------------------------------------------------------- arch
def arch_lattice() -> Lattice:
    """Ground (label 1) and fin (label 0); the fin's front face is a quad grid."""
    lat = Lattice([-2.4, -1.2, -0.6, 0.0, 0.6, 1.2, 2.4], [-1.6, -0.4, 0.4, 1.6],
                  [-0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 2.5])
    lat.add_box(1, (0, 6), (0, 3), (0, 1))
    lat.add_box(0, (1, 5), (1, 2), (1, 6), split=("-y",))
    return lat


def _arch(rng, seed, n, on_step, check):
    mats = {0: "sandstone", 1: "limestone"}
    g = arch_lattice().build()
    q = EventQueue(g, seed=seed, check=check)
    res = Result("arch", g, mats, 0)
    base = find_vertex(g, (0.0, -0.4, 0.0))
    slide_to = np.array([0.3 + 0.05 * rng.uniform(-1, 1), 0.4, 0.0])
    drill = find_vertex(g, (0.0, -0.4, 1.5))
    tilt = rng.normal(0.0, 0.02, 2)
    dir_drill = np.array([tilt[0], 1.0, tilt[1]])
    dir_drill /= np.linalg.norm(dir_drill)
    n_slide, n_drill = 3, 4
    drill_step = 1.0 / n_drill
    window = None
    widen = 0.08 * (1 + 0.1 * rng.uniform(-1, 1))
    slide_from, slider = g.points[base].copy(), base
    for step in range(n):
        seen = len(q.log)
        if step < n_slide:
            # the base vertex (shared with the ground) slides towards the back edge
            q.add(slider, 0, slide_from + (step + 1) / n_slide * (slide_to - slide_from))
        elif len(g.vertex_darts(drill)) and step < n_slide + n_drill + 2:
            q.add(drill, 0, g.points[drill] + drill_step * dir_drill)
        elif window is not None:
            ring, centre = window
            for h in ring:
                r = g.points[h] - centre
                r[1] = 0.0
                rad = np.linalg.norm(r)
                if rad + widen <= 0.62:
                    q.add(h, 0, g.points[h] + widen * r / rad)
        q.run()
        for e in q.log[seen:]:
            if e[0] == "split":                     # ("split", old vertex, the fin's copy)
                slider = e[2]
            if e[0] == "hole":
                ring = list(e[3])
                window = (ring, g.points[ring].mean(axis=0))
        res.steps = step + 1
        if on_step:
            on_step(step, _finish(res, q))
    return _finish(res, q)
