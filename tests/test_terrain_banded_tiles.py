"""Banded polygonization in column-tile windows (issue 37 item 2): the tiled banded
mesh equals the dense one bit for bit in its faces, tiles stitch into the mesh of one
marching cubes over the whole grid, and the work is O(band), not O(grid)."""

from __future__ import annotations

import numpy as np
from helpers import variant

variant()

from skimage.measure import marching_cubes  # noqa: E402

from arches_render.field import evaluate  # noqa: E402
from arches_render.generators.terrain import tiled_mc  # noqa: E402
from arches_render.mesh import lewiner  # noqa: E402
from arches_render.generators.terrain.banded import BandStats, _Grid, polygonize_banded, polygonize_dense  # noqa: E402
from arches_render.generators.terrain.benchmarks import sea_tree  # noqa: E402


def _sparse_tree(size=480.0, n_prims=30):
    """A coast (relief of ~+-60 m: a tall grid) with primitives on the coastline, so
    the band crosses many tile borders (tiles of 32 x 1.5 m)."""
    root, _, sets = sea_tree(n_prims=n_prims, size=size, res=64, seed=2)
    return root, sets


def test_tiled_banded_equals_dense_and_is_o_band():
    root, sets = _sparse_tree()
    voxel = 1.5
    stats = BandStats()
    mb = polygonize_banded(root, voxel, stats=stats)
    md = polygonize_dense(root, voxel)
    assert len(mb.vertices) > 5000 and mb.vertices.shape == md.vertices.shape
    np.testing.assert_array_equal(mb.faces, md.faces)
    # Vertices differ by the float32 rounding of the direct extraction (3.3e-4 m here,
    # as the whole-grid code before the tiles gave on such trees), the benchmark's bound:
    assert np.abs(mb.vertices - md.vertices).max() < 1e-3 * voxel
    # Normals are central differences of the field at those vertices, so they differ as
    # the vertices do: measured 1.8e-4 here (main's code before the tiles: 4.8e-4 on a
    # 160 m coast). 2e-3 leaves that a margin and stays far below what a wrong vertex or
    # face would give (a unit normal moved by ~1).
    np.testing.assert_allclose(mb.normals, md.normals, atol=2e-3)
    # Several tiles in each direction, and primitives on tile borders.
    grid = _Grid(root, voxel)
    assert grid.shape[0] > 8 * tiled_mc.TILE and grid.shape[1] > 8 * tiled_mc.TILE
    lo = np.concatenate([s.primitive_boxes()[0] for s in sets])
    hi = np.concatenate([s.primitive_boxes()[1] for s in sets])
    t0 = np.floor((lo[:, :2] - grid.lo[:2]) / voxel / tiled_mc.TILE)
    t1 = np.floor((hi[:, :2] - grid.lo[:2]) / voxel / tiled_mc.TILE)
    assert np.any(t0 != t1)
    # O(band): the windows (allocated, filled, scanned) are a small multiple of the
    # band and a small part of the grid; whole-grid passes would allocate it all.
    # (Here 4.6M of 9.2M voxels for a band of 1.8M: the tiles' relief.)
    assert stats.band <= stats.allocated < 0.6 * stats.voxels
    assert stats.allocated < 3 * stats.band
    assert 0 < stats.meshed <= stats.allocated
    # Stitched: the solid's surface is closed across every tile border.
    import trimesh
    assert trimesh.Trimesh(mb.vertices, mb.faces, process=False).is_watertight


def test_tiles_stitch_into_one_marching_cubes_of_the_grid():
    """The dense reference (tiles, runs, stitching) has the triangles of one
    scikit-image marching cubes over the whole grid: same vertices, same faces as
    sets (tile order differs), so no vertex is left unmerged on a tile border."""
    root, _ = _sparse_tree(160.0, 40)  # 96^3 voxels, 3 x 3 tiles
    voxel = 1.5
    md = polygonize_dense(root, voxel, normals=False)
    grid = _Grid(root, voxel)
    nx, ny, nz = (int(n) for n in grid.shape)
    idx = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), -1).reshape(-1, 3)
    vol = evaluate(root, grid.lo + idx * voxel).reshape(nx, ny, nz)
    v, f, _, _ = marching_cubes(vol, 0.0, spacing=(voxel,) * 3)
    v = (v + grid.lo).astype(np.float32)
    assert len(v) == len(md.vertices) and len(f) == len(md.faces)

    def triangles(verts, faces):
        """Triangles by corner positions, each rotated to start at its smallest corner
        (keeps the winding), sorted."""
        t = np.round(verts[faces].astype(np.float64) / voxel, 3)  # (F, 3 corners, 3)
        keys = [tuple(map(tuple, tri)) for tri in t]
        return sorted(min(k[i:] + k[:i] for i in range(3)) for k in keys)

    assert triangles(md.vertices, md.faces.astype(np.int64)) == triangles(v, f)


def test_marching_cubes_in_threads_equals_one_call():
    """Runs cut into chunks meshed in threads give the single call's vertices, keys,
    faces and declined runs bit for bit (faces and declined indices offset)."""
    from arches_render.generators.terrain import banded_kernels
    rng = np.random.default_rng(1)
    x = np.linspace(-6, 6, 81)
    X, Y, Z = np.meshgrid(x, x, np.linspace(-2, 2, 30), indexing="ij")
    # Smooth relief (plain cases) with a few noisy patches (runs declined to scikit-image).
    noisy = (np.abs(X - 2) < 0.6) & (np.abs(Y + 3) < 0.6)
    vol = (np.sin(X) + np.cos(1.3 * Y) - 1.5 * Z + 0.8 * noisy * rng.normal(size=X.shape)).astype(np.float32)
    nx, ny, nz = vol.shape
    i0, j0, sx, sy, c0, c1 = banded_kernels.tile_crossing_runs(vol, 8).T
    runs = np.stack([(i0 * ny + j0) * nz + c0, np.full_like(i0, ny * nz), np.full_like(i0, nz), sx, sy,
                     c1 - c0 + 2, i0, j0, c0, i0, i0 + sx - 1, j0, j0 + sy - 1], axis=1)
    flat = vol.reshape(-1)
    args = (ny, nz, tiled_mc.DELTA, 0.0, 1, False, *lewiner.lewiner_luts())
    one = lewiner.plain_runs(flat, runs, *args)
    declined = one[5]
    assert len(runs) >= 90 and 0 < len(declined) < len(runs) // 4 and len(one[3]) > 10000
    for workers in (2, 3):
        parts = lewiner.plain_runs_chunked(flat, runs, *args, workers=workers, min_cubes=0)
        assert len(parts) == 8 * workers
        nv = np.cumsum([0] + [len(p[0]) for _, p in parts])
        for field in (0, 1, 2, 4):
            np.testing.assert_array_equal(one[field], np.concatenate([p[field] for _, p in parts]))
        np.testing.assert_array_equal(one[3], np.concatenate([p[3] + v for (_, p), v in zip(parts, nv)]))
        np.testing.assert_array_equal(one[5], np.concatenate([p[5] + first for first, p in parts]))


def test_run_keys_recompute_scikit_image_positions_bit_for_bit():
    """Edge vertices' positions are recomputed from the grid values as scikit-image
    computes them (``float32(k + v0 / (v0 - v1))``): equal bit for bit at origin 0,
    and keyed by their edge; exact zeros and tiny values resolve to grid points."""
    rng = np.random.default_rng(0)
    x = np.linspace(-3, 3, 40)
    X, Y, Z = np.meshgrid(x, x, np.linspace(-2, 2, 30), indexing="ij")
    # (positive on the bottom layer, negative on the top one)
    vol = (np.sin(X) + np.cos(1.3 * Y) - 1.5 * Z + 0.1 * rng.normal(size=X.shape)).astype(np.float32)
    v, _, _, _ = marching_cubes(vol, 0.0, allow_degenerate=True)
    g, keys, _ = tiled_mc._run_keys(v, vol, np.zeros(3, np.int64), np.array([0, 39, 0, 39]), 40, 30, tiled_mc.DELTA)
    edge = (keys >= 0) & (keys % 4 < 3)
    assert edge.mean() > 0.99
    np.testing.assert_array_equal(g[edge], v[edge])
    # The same vertices from a run whose origin is 7 levels lower (positive layers
    # below: no crossing there): same keys, same positions.
    shift = np.concatenate([np.ones((40, 40, 7), np.float32), vol], axis=2)
    v2, _, _, _ = marching_cubes(shift, 0.0, allow_degenerate=True)
    g2, keys2, _ = tiled_mc._run_keys(v2, shift, np.array([0, 0, -7]), np.array([0, 39, 0, 39]), 40, 30,
                                      tiled_mc.DELTA)
    np.testing.assert_array_equal(keys2, keys)
    np.testing.assert_array_equal(g2[edge], g[edge])


def test_plain_cases_emit_scikit_image_triangles():
    """The numba path for Lewiner's plain cases (1, 2, 5, 8, 9, 11, 14) emits, for
    every cube configuration, the triangles scikit-image emits (positions, winding),
    and declines the cases with face or interior tests."""
    T = lewiner.lewiner_tables()
    rng = np.random.default_rng(0)

    def triangles(g, f):
        t = np.round(g[f].astype(np.float64), 5)
        keys = [tuple(map(tuple, x)) for x in t]
        return sorted(min(k[i:] + k[:i] for i in range(3)) for k in keys)

    plain = declined = 0
    for idx in range(1, 255):
        for trial in range(3):
            mags = rng.uniform(0.05, 1.0, 8)
            vol = np.empty((2, 2, 2), np.float32)
            for c, (di, dj, dk) in enumerate(T["corner"]):
                vol[di, dj, dk] = mags[c] if (idx >> c) & 1 else -mags[c]
            if trial == 2:
                vol[0, 0, 0] = 0.0  # a corner on the surface
            ok, g, _, _, f, _ = lewiner.plain_volume(vol, exact=False, box=(0, 1, 0, 1), delta=tiled_mc.DELTA)
            actual = sum(1 << c for c, (di, dj, dk) in enumerate(T["corner"]) if vol[di, dj, dk] > 0)
            case = T["cases"][actual, 0]
            assert ok == (case == 0 or case in lewiner.PLAIN)
            if not ok:
                declined += 1
                continue
            try:
                v, ff, _, _ = marching_cubes(vol, 0.0, allow_degenerate=True)
            except RuntimeError:
                v, ff = np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int64)
            assert triangles(g, f) == triangles(v, ff), (idx, trial)
            plain += 1
    assert plain > 300 and declined > 300


def test_stitch_in_parts_equals_the_serial_merge_of_the_concatenation():
    """The parallel stitch (parts never concatenated, blocks of 2^16 prefix-summed) gives
    the serial definition's vertices and faces: shareable vertices of equal key merged
    into the first in order, kept ones renumbered in order, faces repeating a vertex
    dropped. Parts of unequal sizes, several blocks each, many merges and drops."""
    rng = np.random.default_rng(4)
    parts = []
    for n in (150_000, 7, 90_000, 0, 70_000):
        g = rng.random((n, 3)).astype(np.float32) * 100
        keys = rng.integers(0, 60_000, n)        # ~1 in 3 of the shareable ones merge
        share = rng.random(n) < 0.5
        faces = rng.integers(0, max(n, 1), (2 * n, 3)).astype(np.int32)
        parts.append((g, keys, share, faces))
    lo = np.array([1.0, -2.0, 3.0])
    v, f = tiled_mc._stitch(parts, 1.5, lo)
    # The serial definition, on the concatenation.
    first = np.cumsum([0] + [len(p[0]) for p in parts])
    g = np.concatenate([p[0] for p in parts])
    keys = np.concatenate([p[1] for p in parts])
    share = np.concatenate([p[2] for p in parts])
    faces = np.concatenate([p[3] + o for p, o in zip(parts, first[:-1])]).astype(np.int64)
    rep = np.arange(len(g))
    lead = {}
    for q in np.flatnonzero(share):
        rep[q] = lead.setdefault(int(keys[q]), q)
    kept = rep == np.arange(len(g))
    new = np.cumsum(kept) - 1
    mapped = new[rep[faces]]
    ok = (mapped[:, 0] != mapped[:, 1]) & (mapped[:, 1] != mapped[:, 2]) & (mapped[:, 0] != mapped[:, 2])
    assert 0 < kept.sum() < len(g) and 0 < ok.sum() < len(ok)
    np.testing.assert_array_equal(v, (g[kept].astype(np.float64) * 1.5 + lo).astype(np.float32))
    np.testing.assert_array_equal(f, mapped[ok].astype(np.uint32))
    assert f.dtype == np.uint32 and v.dtype == np.float32


def test_neighbour_range_is_scipys_3x3_minimum_and_maximum():
    """The band's column ranges use a one-pass parallel 3 x 3 minimum and maximum: scipy's
    ``minimum_filter`` / ``maximum_filter`` (``size=3, mode="nearest"``) exactly, thin
    grids and infinities included."""
    from scipy.ndimage import maximum_filter, minimum_filter

    from arches_render.generators.terrain.banded_kernels import neighbour_range
    rng = np.random.default_rng(3)
    for shape in ((1, 1), (1, 6), (5, 1), (2, 3), (40, 57)):
        h = rng.normal(size=shape) * 100
        h[rng.random(shape) < 0.05] = np.inf
        h[rng.random(shape) < 0.05] = -np.inf
        lo, hi = neighbour_range(h)
        np.testing.assert_array_equal(lo, minimum_filter(h, size=3, mode="nearest"), err_msg=str(shape))
        np.testing.assert_array_equal(hi, maximum_filter(h, size=3, mode="nearest"), err_msg=str(shape))
