"""The boundary of a voxel set as faces (arches_render.mesh.cover_faces)."""

from __future__ import annotations

import numpy as np
import pytest

from arches_render.mesh.cover_faces import boundary_quads, quads_to_triangles


def _random_set(seed):
    rng = np.random.default_rng(seed)
    m = rng.random((7, 9, 11)) < 0.35
    m[2:5, 3:8, 1:10] = True  # a block, so that merging has flat stretches to merge
    return m


def _inside(mask, lo, h, p):
    """Whether points ``p`` (x, y, z) lie in a voxel of ``mask``."""
    idx = np.floor((p - lo) / h).astype(int)[:, ::-1]
    ok = np.all((idx >= 0) & (idx < mask.shape), axis=1)
    out = np.zeros(len(p), dtype=bool)
    out[ok] = mask[tuple(idx[ok].T)]
    return out


@pytest.mark.parametrize("merge", [False, True])
def test_faces_bound_the_set_and_face_outwards(merge):
    """Along random axis-parallel lines, the faces met alternate between entering and
    leaving exactly where the set's membership changes; merged rectangles cover the
    same faces as unmerged ones (same area per orientation), with fewer quads."""
    mask, lo, h = _random_set(3), np.array([1.0, -2.0, 0.5]), 0.5
    corners, outward = boundary_quads(mask, lo, h, merge=merge)
    rng = np.random.default_rng(4)
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        for _ in range(60):
            # A line along `axis` through random cell centres of the other two axes.
            p = lo + (rng.integers(0, 12, 3) + 0.5) * h
            sel = (outward >> 1) == axis
            q = corners[sel]
            lo_q, hi_q = q.min(axis=1), q.max(axis=1)
            on = np.all((lo_q[:, others] < p[others]) & (p[others] < hi_q[:, others]), axis=1)
            cross = q[on, 0, axis]
            signs = (outward[sel][on] & 1).astype(int)
            order = np.argsort(cross)
            cross, signs = cross[order], signs[order]
            # Membership just after each crossing: entering (outward -axis) -> inside.
            probe = np.repeat(p[None], len(cross), axis=0)
            probe[:, axis] = cross + 0.25 * h
            assert np.array_equal(_inside(mask, lo, h, probe), signs == 0)
            probe[:, axis] = cross - 0.25 * h
            assert np.array_equal(_inside(mask, lo, h, probe), signs == 1)
            assert not np.any(np.diff(cross) == 0)  # one face per crossing
    area = {k: 0.0 for k in range(6)}
    for q, k in zip(corners, outward):
        ext = q.max(axis=0) - q.min(axis=0)
        area[int(k)] += np.prod(ext[ext > 0])
    unmerged = boundary_quads(mask, lo, h, merge=False)
    expected = {k: h * h * np.count_nonzero(unmerged[1] == k) for k in range(6)}
    assert all(np.isclose(area[k], expected[k]) for k in range(6))
    if merge:
        assert len(corners) < 0.8 * len(unmerged[0])


def test_grown_faces_overlap_their_neighbours_and_triangles_index_their_quads():
    mask = np.ones((1, 1, 2), dtype=bool)
    corners, outward = boundary_quads(mask, (0.0, 0.0, 0.0), 1.0, merge=False, grow=0.01)
    top = corners[outward == 5]
    assert len(top) == 2 and np.isclose(top[0, :, 0].max() - top[0, :, 0].min(), 1.02)
    vertices, faces = quads_to_triangles(corners)
    assert vertices.shape == (4 * len(corners), 3) and faces.shape == (2 * len(corners), 3)
    assert np.all(faces[0::2] // 4 == np.arange(len(corners))[:, None])
    assert np.all(faces[1::2] // 4 == np.arange(len(corners))[:, None])
    assert boundary_quads(np.zeros((2, 2, 2), bool), (0, 0, 0), 1.0)[0].shape == (0, 4, 3)
