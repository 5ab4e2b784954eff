"""Plain-array triangle operations (:mod:`arches_render.mesh.triangles`) against trimesh's."""

from __future__ import annotations

import numpy as np
import pytest

from arches_render.mesh.triangles import face_areas, face_normals, merged_vertices, vertex_normals

trimesh = pytest.importorskip("trimesh")


def _grid(n=9, seed=2):
    """A bumpy height grid, its quads split in two, every vertex written once per face."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 10, n), np.linspace(0, 7, n))
    z = rng.normal(scale=0.8, size=x.shape)
    P = np.stack([x, y, z], -1)
    tris = []
    for j in range(n - 1):
        for i in range(n - 1):
            a, b, c, d = P[j, i], P[j, i + 1], P[j + 1, i], P[j + 1, i + 1]
            tris += [(a, b, d), (a, d, c)]
    V = np.array(tris).reshape(-1, 3)
    return V, np.arange(len(V)).reshape(-1, 3)


def test_merged_vertices_join_equal_positions_and_drop_unreferenced():
    V, F = _grid()
    V = np.vstack([V, [[99.0, 99.0, 99.0]]])  # referenced by no face
    v, f = merged_vertices(V, F)
    assert len(v) == 81 and len(np.unique(v, axis=0)) == 81
    assert np.array_equal(v[f], V[F])  # every face keeps its corners, in its order


def test_normals_and_areas_are_trimeshs():
    V, F = merged_vertices(*_grid())
    ref = trimesh.Trimesh(V, F, process=False)
    # The same formulas in another summation order (trimesh sums vertex normals through a
    # sparse product): measured 2.8e-16 (face normals), 3.2e-16 relative (areas) and
    # 4.3e-16 (vertex normals) apart, a few float64 ulps; 1e-12 leaves room for other
    # BLAS builds and still fails any change of weighting (unweighted normals: 0.44 off).
    assert np.allclose(face_normals(V, F), ref.face_normals, atol=1e-12)
    assert np.allclose(face_areas(V, F), ref.area_faces, rtol=1e-12)
    assert np.allclose(vertex_normals(V, F), ref.vertex_normals, atol=1e-12)
    # A degenerate face adds nothing and has a zero normal.
    Fd = np.vstack([F, [[0, 0, 1]]])
    assert np.array_equal(face_normals(V, Fd)[-1], [0.0, 0.0, 0.0])
    # Its zero normal adds exactly nothing (measured: equal bits).
    assert np.array_equal(vertex_normals(V, Fd), vertex_normals(V, F))
