"""3-G-map kernel and the atomic operations on the paper's small configurations (Figs. 3–9).

Bezin et al., *Topological Operations for Geomorphological Evolution*: every test
states the dart relations or cell counts that the figure describes, checks the
map's validity (α_i involutions, α_iα_j involutions for |i − j| ≥ 2), and, where
geometry is involved, compares volumes with their analytic values.
"""

from __future__ import annotations

import numpy as np
import pytest

from arches_render.generators.gmaps import operations as op
from arches_render.generators.gmaps.builders import (Lattice, find_face, find_vertex, from_polyhedra,
                                                     layer_stack, star_vertex)
from arches_render.generators.gmaps.events import EventQueue
from arches_render.generators.gmaps.export import volume_meshes
from arches_render.generators.gmaps.geometry import triangulate_polygon
from arches_render.generators.gmaps.gmap import GMap, GMapError, VERTEX

from arches_render.generators.gmaps.checks import self_intersections, volumes_by_label


def cube_map():
    pts = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return from_polyhedra(pts, [(0, faces)])


# ------------------------------------------------------------------- kernel
def test_cube_counts_storage_and_validity():
    g = cube_map()
    g.check()
    assert g.n_darts == 48                       # 6 faces x 4 edges x 2 darts
    assert g.dart_bytes() == 20.0                # 4 x int32 involutions + 1 x int32 attribute
    (t,) = g.volume_topology()
    assert (t["V"], t["E"], t["F"], t["euler"], t["genus"]) == (8, 12, 6, 2, 0)
    d = 0
    assert len(g.orbit(d, VERTEX)) == 6          # 3 faces x 2 darts around a cube corner
    assert len(g.orbit(d, (0, 2, 3))) == 4       # an edge: 2 faces x 2 darts
    assert len(g.orbit(d, (0, 1, 3))) == 8       # a quad face
    assert len(g.orbit(d, (0, 1, 2))) == 48      # the volume


def test_check_rejects_broken_involutions():
    g = cube_map()
    d = 0
    e = g.a(2, d)
    g.alpha[2, d] = g.a(1, d)                    # α2 no longer an involution
    with pytest.raises(GMapError, match="α2"):
        g.check()
    g.alpha[2, d] = e
    g.check()
    # α0α2 must be an involution: swap the α2 links of the two darts of an edge side
    x, y = d, g.a(0, d)
    ex, ey = g.a(2, x), g.a(2, y)
    g.link(2, x, ey)
    g.link(2, y, ex)
    with pytest.raises(GMapError):
        g.check()


def test_layer_stack_sews_interfaces():
    g = layer_stack((-1, -1, 1, 1), [1.0, 0.5, 0.0], cells=(2, 2))
    g.check()
    sewn = [d for d in g.darts() if not g.is_free(3, int(d))]
    assert len(sewn) == 2 * 4 * 8                # 4 interface quads, 8 darts a side
    assert {t["genus"] for t in g.volume_topology()} == {0}
    (s,) = g.surface_topology()
    assert s["euler"] == 2                       # the union is one ball


def test_insert_vertex_split_face_contract_inverse():
    g = cube_map()
    v0 = g.volume_topology()[0]
    d = g.faces()[0]
    nd = g.insert_vertex(d, 0.5 * (g.pos(d) + g.pos(g.a(0, d))))
    g.check()
    t = g.volume_topology()[0]
    assert (t["V"], t["E"], t["F"]) == (v0["V"] + 1, v0["E"] + 1, v0["F"])
    cyc = g.face_cycle(nd)
    g.split_face(cyc[0], cyc[4])                 # edge from the new vertex across the face
    g.check()
    t = g.volume_topology()[0]
    assert (t["V"], t["E"], t["F"], t["euler"]) == (v0["V"] + 1, v0["E"] + 2, v0["F"] + 1, 2)
    # contracting the inserted edge's neighbour edge brings the vertex back onto a corner
    g.contract_edge(g.a(0, nd))
    g.check()
    assert g.volume_topology()[0]["euler"] == 2


def test_triangulate_polygon_weakly_simple_hole():
    # square with a square hole joined by a bridge (Fig. 6): 4 + 1 + 4 + 1 corners
    outer = [(0, 0), (4, 0), (4, 4), (0, 4)]
    hole = [(1, 1), (1, 3), (3, 3), (3, 1)]      # clockwise
    pts2 = outer + [(0, 0)] + hole + [(1, 1)]
    ids = [0, 1, 2, 3, 0, 4, 5, 6, 7, 4]
    pts = np.c_[np.asarray(pts2, float), np.zeros(len(pts2))]
    tris = triangulate_polygon(pts, ids)
    assert len(tris) == len(pts) - 2
    area = sum(0.5 * np.cross(pts[b] - pts[a], pts[c] - pts[a])[2] for a, b, c in tris)
    assert area == pytest.approx(16 - 4)
    assert all(0.5 * np.cross(pts[b] - pts[a], pts[c] - pts[a])[2] > 0 for a, b, c in tris)


# ----------------------------------------------------- Fig. 9: face split
def test_fig9_relink_corners_merges_vertex_orbits():
    g = cube_map()
    top = find_face(g, 0, (0.5, 0.5, 1.0), 2)
    cyc = g.face_cycle(top)
    a = cyc[0]
    b = g.a(1, a)
    # a vertex X inserted on the edge opposite to a's vertex
    far = cyc[4]
    g.insert_vertex(far, 0.5 * (g.pos(far) + g.pos(g.a(0, far))))
    cyc = g.face_cycle(a)
    j = 6
    c = cyc[j]
    d = g.a(1, c)
    assert g.vertex(a) != g.vertex(c) and c not in g.orbit(a, VERTEX)   # two vertex orbits
    g.relink_corners(a, c)
    assert (g.a(1, a), g.a(1, b), g.a(1, c), g.a(1, d)) == (d, c, b, a)
    assert c in g.orbit(a, VERTEX)               # one vertex orbit now
    assert len(g.face_cycle(a)) + len(g.face_cycle(c)) == len(cyc)     # the face split in two
    g.set_vertex(g.orbit(a, VERTEX), g.vertex(a))
    g.check()
    # the paper's path from a to b: α1, α2, α1, α2, α1 (through the neighbouring faces)
    assert b in g.orbit(a, (1, 2))


# ----------------------------------------------- Fig. 3: vertex in two volumes
def test_fig3_vertex_split_keeps_the_resistant_volume():
    g = layer_stack((0, 0, 2, 2), [2.0, 1.0, 0.0], cells=(2, 2))
    p = find_vertex(g, (1.0, 1.0, 1.0))          # centre of the interface, in both volumes
    upper, lower = 0, 1
    assert {g.volume(d) for d in op.darts_at(g, p)} == {upper, lower}
    before = volumes_by_label(g)
    q = EventQueue(g, seed=0)
    q.add(p, lower, g.points[p] + np.array([0.1, 0.05, -0.4]))   # towards the lower volume's centre
    q.run()
    assert [e[0] for e in q.log] == ["split"]
    new = q.log[0][2]
    assert new != p
    assert {g.volume(d) for d in op.darts_at(g, p)} == {upper}
    assert {g.volume(d) for d in op.darts_at(g, new)} == {lower}
    assert all(g.is_free(3, d) for d in op.faces_at(g, new))        # faces around the copy are exposed
    assert np.allclose(g.points[p], (1, 1, 1))                       # the upper volume's vertex stays
    after = volumes_by_label(g)
    assert after[upper] == pytest.approx(before[upper], abs=1e-12)   # no growth of the upper volume
    assert after[lower] < before[lower] - 1e-3
    g.check()
    for _, _, _, m in volume_meshes(g):
        assert m.is_watertight


# ------------------------------------------- Fig. 4: sliding onto an edge
def test_fig4_slide_inserts_vertex_on_the_hit_edge():
    lat = Lattice([0, 1, 2], [0, 1, 2], [0, 1])
    lat.add_box(0, (0, 2), (0, 2), (0, 1), split=("+z",))
    g = lat.build()
    p = find_vertex(g, (1.0, 0.0, 1.0))          # middle of the top's front edge
    edges_before = g.volume_topology()[0]["E"]
    q = EventQueue(g, seed=0)
    target = np.array([1.3, 1.0, 1.0])           # slides on the top, reaches the edge y = 1
    q.add(p, 0, target)
    q.run()
    assert [e[0] for e in q.log] == ["slide"]
    assert np.allclose(g.points[p], target)
    # P now lies on the edge (1,1)-(2,1): it joins both of its ends
    a, b = find_vertex(g, (1.0, 1.0, 1.0)), find_vertex(g, (2.0, 1.0, 1.0))
    assert {a, b} <= set(op.neighbours(g, p))
    # the quad P slid across became the triangle (P, (2,0), (2,1)); the digon (P, a) was removed
    tri = [d for d in op.faces_at(g, p) if set(g.face_vertices(d)) == {p, find_vertex(g, (2.0, 0.0, 1.0)), b}]
    assert len(tri) == 1 and len(g.face_cycle(tri[0])) == 6
    g.check()
    t = g.volume_topology()[0]
    assert t["euler"] == 2
    # + the split edge, + 3 diagonals of the front hexagon (the one face around P that
    # P leaves the plane of), - 1 for the digon whose two edges became one
    assert t["E"] == edges_before + 1 + 3 - 1
    (_, _, _, m), = volume_meshes(g)
    assert m.is_watertight and not self_intersections(m)


# --------------------------------- Fig. 5c / 6: drilling through an outer face
def _slab_with_centre_vertex(z_levels):
    g = layer_stack((-1, -1, 1, 1), z_levels, cells=(1, 1))
    top = find_face(g, 0, (0, 0, z_levels[0]), 2)
    v = star_vertex(g, top, (0.0, 0.0, z_levels[0]))
    return g, v


def test_fig5c_hole_removes_the_cap_and_makes_a_tunnel():
    g, v = _slab_with_centre_vertex([1.0, 0.0])
    q = EventQueue(g, seed=0, push=0.1)
    q.add(v, 0, (0.0, 0.0, -0.5))
    q.run()
    assert [e[0] for e in q.log] == ["hole"]
    kind, _, behind, ring = q.log[0]
    assert behind is None and len(ring) == 4     # one hole corner per edge of the vertex
    assert not op.darts_at(g, v)                 # the vertex went with the cap
    g.check()
    (t,) = g.volume_topology()
    assert t["genus"] == 1
    # the bottom face: 4 border corners, the bridge's corner twice, 4 hole corners
    bottom = [d for d in g.faces(0) if len(g.face_cycle(d)) == 2 * 10]
    assert len(bottom) == 1
    cyc = g.face_cycle(bottom[0])
    bridge = [x for x in cyc if g.a(2, x) in cyc]
    assert len(bridge) == 4                      # Fig. 6: the bridge edge lies twice in the face
    # volume: slab minus the pyramid from the top (apex at the pushed vertex) plus the cap below
    z = -0.1 * 2.0                               # pushed past z = 0 by push x face size
    h_ring = 2.0 * (0 - z) / (1.0 - z)           # hole side (homothety of the top square)
    expected = 4.0 - (4.0 * (1.0 - z) - h_ring ** 2 * (0 - z)) / 3.0
    (_, _, _, m), = volume_meshes(g)
    assert m.is_watertight and m.volume == pytest.approx(expected, rel=1e-9)
    assert not self_intersections(m)


def test_fig5d_hole_in_a_shared_face_gives_a_dip_below():
    g, v = _slab_with_centre_vertex([2.0, 1.0, 0.0])
    q = EventQueue(g, seed=0)
    q.add(v, 0, (0.0, 0.0, 0.6))
    q.run()
    assert [e[0] for e in q.log] == ["hole"]
    _, _, behind, ring = q.log[0]
    assert behind == 1
    assert {g.volume(d) for d in op.darts_at(g, v)} == {1}           # the vertex drills on below
    assert np.allclose(g.points[v], (0, 0, 0.6))                     # remainder re-injected and applied
    for h in ring:                                                    # hole corners shared by both
        assert {g.volume(d) for d in op.darts_at(g, h)} == {0, 1}
    g.check()
    topo = {t["label"]: t["genus"] for t in g.volume_topology()}
    assert topo == {0: 1, 1: 0}
    (s,) = g.surface_topology()
    assert s["genus"] == 0                       # the terrain as a whole has a dip, no hole
    vols = volumes_by_label(g)
    assert vols[0] + vols[1] == pytest.approx(8.0 - 4.0 * 1.4 / 3.0, rel=1e-9)   # minus one pyramid
    for _, _, _, m in volume_meshes(g):
        assert m.is_watertight and not self_intersections(m)


# --------------------------------------------- Fig. 7a: one connecting edge
def test_fig7a_single_edge_is_contracted():
    # A triangular prism whose sides next to the vertical edge P–Q are split by
    # diagonals from Q: P is joined to the bottom face by that one edge only.
    Q, A, B, P, A2, B2 = range(6)
    pts = [(0, 0, 0), (2, 0, 0), (0, 2, 0), (0, 0, 1), (2, 0, 1), (0, 2, 1)]
    faces = [[Q, A, B], [P, A2, B2], [Q, A, A2], [Q, A2, P], [A, B, B2, A2], [Q, B, B2], [Q, B2, P]]
    g = from_polyhedra(pts, [(0, faces)])
    p, qv = find_vertex(g, (0, 0, 1)), find_vertex(g, (0, 0, 0))
    assert set(op.neighbours(g, p)) & {qv, find_vertex(g, (2, 0, 0)), find_vertex(g, (0, 2, 0))} == {qv}
    q = EventQueue(g, seed=0)
    q.add(p, 0, (0.4, 0.4, -0.2))                # down into the prism, hits the bottom inside
    q.run()
    assert [e[0] for e in q.log] == ["contract"]
    assert q.log[0][2] == qv
    assert not op.darts_at(g, p)                 # P merged into Q, which stays on the face
    g.check()
    t = g.volume_topology()[0]
    # P's 3 edges: P-Q contracted, P-A2 and P-B2 now join Q; the two triangles on P-Q became
    # digons and were removed (their two edges merged into one each)
    assert (t["V"], t["E"], t["F"], t["euler"]) == (5, 9 + 2 - 1 - 2, 7 - 2, 2)
    (_, _, _, m), = volume_meshes(g)
    # the prism (volume 2) minus the tetrahedron (Q, A2, B2, P): 2 - 4/6
    assert m.is_watertight and m.volume == pytest.approx(2.0 - 4.0 / 6.0, rel=1e-12)
    assert not self_intersections(m)


# ------------------------------- Fig. 7c + Fig. 8: collapse and pinching
def test_fig8_ridge_vertex_pinches_a_prism_in_two():
    # A prism of triangular section lying along x; its ridge vertex P goes straight
    # down. P is joined (after the fan of the two slopes) to the bottom's four
    # corners: the two triangles (P, FL, FR) and (P, BR, BL) fold onto the bottom
    # (Fig. 7c); the faces around P then form two cycles: P is a pinching point,
    # and the volume is split into two subvolumes (Fig. 8c).
    FL, FR, BR, BL, RL, P, RR = range(7)
    pts = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0), (-1, 0, 1), (0, 0, 1), (1, 0, 1)]
    faces = [[FL, FR, BR, BL], [FL, FR, RR, P, RL], [BR, BL, RL, P, RR], [FL, RL, BL], [FR, BR, RR]]
    g = from_polyhedra(pts, [(0, faces)])
    p = find_vertex(g, (0, 0, 1))
    q = EventQueue(g, seed=0)
    q.add(p, 0, (0.0, 0.0, -0.5))
    q.run()
    kinds = [e[0] for e in q.log]
    assert kinds == ["collapse", "pinch"]
    assert q.log[0][2] == 2                      # two flattened triangles folded onto the bottom
    g.check()
    topo = g.volume_topology()
    assert sorted(t["label"] for t in topo) == [0, 1] and all(t["genus"] == 0 for t in topo)
    # each half is the tetrahedron (P on the floor; the end triangle of area 1 at distance 1): 1/3
    vols = volumes_by_label(g)
    assert vols[0] == pytest.approx(1 / 3, rel=1e-12) and vols[1] == pytest.approx(1 / 3, rel=1e-12)
    for _, _, _, m in volume_meshes(g):
        assert m.is_watertight and not self_intersections(m)
    # P became one vertex per subvolume, at the same place
    at_p = [v for v in range(g.n_points) if len(g.vertex_darts(v)) and np.allclose(g.points[v], 0)]
    assert len(at_p) == 2


def test_vertex_face_hole_refuses_connected_faces():
    g = cube_map()
    p = find_vertex(g, (1.0, 1.0, 1.0))
    bottom = find_face(g, 0, (0.5, 0.5, 0.0), 2)
    with pytest.raises(GMapError, match="Fig. 7"):
        op.vertex_face_hole(g, p, 0, bottom)
    g.check()                                    # refused before any change


# ------------------------------------------------------- Fig. 8: pinching
def test_fig8_pinched_volume_is_split_in_two():
    # Two tetrahedra touching at P, first as two volumes, then relabelled as one
    # volume whose two cycles around P share one vertex: P is a pinching point.
    pts = [(0, 0, 0), (1, 0, -1), (0, 1, -1), (-1, -1, -1), (1, 0, 1), (0, 1, 1), (-1, -1, 1)]
    t1 = [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]
    t2 = [[0, 4, 5], [0, 5, 6], [0, 6, 4], [4, 5, 6]]
    g = from_polyhedra(pts, [(0, t1), (1, t2)])
    g.set_volume(g.darts(), 0)
    p0 = [v for v in range(g.n_points) if np.allclose(g.points[v], 0) and len(g.vertex_darts(v))]
    for v in p0[1:]:
        g.set_vertex(g.vertex_darts(v), p0[0])
    p = p0[0]
    g.check()
    cycles = op.pinch_cycles(g, p, 0)
    assert len(cycles) == 2                      # more than one cycle goes back to P (§3.5)
    new = op.volume_pinch(g, p, 0, new_label=lambda: 5)
    assert new == [5]
    g.check()
    assert len(op.pinch_cycles(g, p, 0)) == 1
    labels = sorted(t["label"] for t in g.volume_topology())
    assert labels == [0, 5]
    assert op.volume_pinch(g, p, 0) == []        # nothing left to pinch


def test_contextual_constraint_rejects_growth():
    g = cube_map()
    p = find_vertex(g, (1.0, 1.0, 1.0))
    q = EventQueue(g, seed=0)
    q.add(p, 0, (1.3, 1.3, 1.3))                 # outward: would add matter
    with pytest.raises(GMapError, match="contextual constraint"):
        q.run()


def test_symbolic_perturbation_one_hit_on_a_shared_edge():
    from arches_render.generators.gmaps.geometry import first_hit
    pts = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)], float)
    tris = np.array([[0, 1, 2], [1, 3, 2]])      # share the diagonal 1-2
    hits = [first_hit(np.array([0.5, 0.5, 1.0]), np.array([0.5, 0.5, -1.0]), pts, tris[k:k + 1])
            for k in range(2)]
    assert sum(h is not None for h in hits) == 1  # exactly one triangle claims the edge point
    # a segment through a vertex shared by a fan of four triangles: one of them claims it
    pts = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0.5, 0.5, 0)], float)
    fan = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    centre = [first_hit(np.array([0.5, 0.5, 1.0]), np.array([0.5, 0.5, -1.0]), pts, fan[k:k + 1])
              for k in range(4)]
    assert sum(h is not None for h in centre) == 1


def test_gmap_grows_and_compacts():
    g = GMap(4)
    ds = g.new_darts(100)
    assert g.capacity >= 100 and len(set(ds)) == 100
    g.delete(ds[:50])
    assert g.n_darts == 50
    g.new_darts(10)
    assert g.n_darts == 60
    h = cube_map()
    h.delete([])
    n = h.n_darts
    h.compact()
    assert h.n_darts == n == h.capacity
    h.check()


def test_self_intersection_check_finds_crossings():
    import trimesh
    a = trimesh.creation.box((1, 1, 1))
    assert self_intersections(a) == []
    b = trimesh.creation.box((1, 1, 1))
    b.apply_translation((0.5, 0.3, 0.2))
    both = trimesh.util.concatenate([a, b])
    assert self_intersections(both)              # two interpenetrating boxes


def test_star_face_cell_counts():
    g = cube_map()
    t0 = g.volume_topology()[0]
    top = find_face(g, 0, (0.5, 0.5, 1.0), 2)
    from arches_render.generators.gmaps.face_collapse import star_face
    star_face(g, top, (0.5, 0.5, 1.0))
    g.check()
    t = g.volume_topology()[0]
    assert (t["V"], t["E"], t["F"], t["euler"]) == (t0["V"] + 1, t0["E"] + 4, t0["F"] + 3, 2)


def test_queue_processes_the_earliest_collision_first_and_reinjects():
    g = layer_stack((-1.5, -0.5, 1.5, 0.5), [2.0, 1.0, 0.0], cells=(3, 1))
    left = star_vertex(g, find_face(g, 0, (-1.0, 0.0, 2.0), 2), (-1.0, 0.0, 2.0))
    right = star_vertex(g, find_face(g, 0, (1.0, 0.0, 2.0), 2), (1.0, 0.0, 2.0))
    q = EventQueue(g, seed=0)
    q.add(left, 0, (-1.0, 0.0, 0.85))            # crosses z = 1 at t = 0.87
    q.add(right, 0, (1.0, 0.0, 0.2))             # crosses z = 1 at t = 0.56: first event
    q.run()
    holes = [e for e in q.log if e[0] == "hole"]
    assert [e[1] for e in holes] == [right, left]
    # both remainders were re-injected into the lower volume and completed
    assert np.allclose(g.points[left], (-1.0, 0.0, 0.85)) and np.allclose(g.points[right], (1.0, 0.0, 0.2))
    assert {g.volume(d) for d in op.darts_at(g, left)} == {1}
    g.check()
    assert {t["label"]: t["genus"] for t in g.volume_topology()} == {0: 2, 1: 0}


def test_vertex_vertex_collision_is_deflected():
    # P slides diagonally across the top exactly through the lattice vertex (1, 1):
    # the displacement is deflected in the face plane (§3.3) and becomes two edge
    # collisions next to that vertex.
    lat = Lattice([0, 1, 2], [0, 1, 2], [0, 1])
    lat.add_box(0, (0, 2), (0, 2), (0, 1), split=("+z",))
    g = lat.build()
    p = find_vertex(g, (0.0, 0.0, 1.0))
    q = EventQueue(g, seed=0)
    q.add(p, 0, (1.5, 1.5, 1.0))
    q.run()
    assert [e[0] for e in q.log] == ["slide", "slide"]
    for e in q.log:                                   # both next to (1, 1), neither on it
        assert 0 < np.linalg.norm(e[2] - (1.0, 1.0, 1.0)) < 1e-3
    assert np.linalg.norm(g.points[p] - (1.5, 1.5, 1.0)) < 1e-3
    g.check()
    (_, _, _, m), = volume_meshes(g)
    assert m.is_watertight and not self_intersections(m) and m.volume < 4.0
