"""The far field continues a DEM's own relief past its tile (issue 34; generators/terrain/far_field.py).

* ``MirroredRelief``: the DEM itself inside the tile at no blur, the mirror image
  outside (continuous across the border), the mean height at a blur wider than the tile.
* The far field's rings: a ridge that runs inside the tile, parallel to its border and
  clear of it, shows again past the border (its mirror image); the rings that held the
  border's own heights smoothed along the loop were flat there. The first ring is the
  border itself (the seam is closed).
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant

variant()

from arches_render.field import Heightfield  # noqa: E402
from generators.terrain.far_field import far_field_mesh  # noqa: E402
from generators.terrain.mirrored_relief import MirroredRelief  # noqa: E402


def _ridge_dem(n=65, width=6400.0):
    """A plain of 100 m with a ridge 400 m high along y at 80 % of the tile's x, clear of
    the border (the border's heights are the plain's, to a part in 1e6)."""
    x = np.linspace(0.0, width, n)
    X, Y = np.meshgrid(x, x)
    return (100.0 + 400.0 * np.exp(-0.5 * ((X - 0.8 * width) / (0.03 * width)) ** 2)
            + 20.0 * np.sin(Y / width * 6.0)).astype(np.float64), (0.0, 0.0, width, width)


def test_mirrored_relief_is_the_dem_inside_its_mirror_outside_and_the_mean_far_away():
    H, extent = _ridge_dem()
    relief = MirroredRelief(H, extent)
    n = H.shape[0]
    d = extent[2] / (n - 1)
    j, i = np.mgrid[0:n, 0:n]
    # atol 1e-9 m on heights of 100-500 m: float64 rounding of the sample coordinates and
    # the bilinear weights only (measured: 0, exact at the samples).
    assert np.allclose(relief.heights(i.ravel() * d, j.ravel() * d, 0.0), H.ravel(), atol=1e-9)
    # Mirrored about the border samples: a point at distance a past the right border
    # has the height of the point a inside it.
    a = np.linspace(0.0, 0.9 * extent[2], 50)
    y = np.full_like(a, 0.37 * extent[3])
    # (the same float64 rounding: the reflected coordinate is computed, not looked up)
    assert np.allclose(relief.heights(extent[2] + a, y, 0.0), relief.heights(extent[2] - a, y, 0.0), atol=1e-9)
    assert np.allclose(relief.heights(-a, y, 0.0), relief.heights(a, y, 0.0), atol=1e-9)
    # A blur wider than the tile: the DEM's mean height everywhere.
    far = relief.heights(np.array([-5e4, 3e3, 9e5]), np.array([2e5, -7e3, 1e3]), 40.0 * extent[2])
    # Exactly the mean past the coarsest level: atol 1e-6 m is float64 rounding of the
    # blend weights (w = 1) and of the mean itself.
    assert np.allclose(far, H.mean(), atol=1e-6)
    # Blurs in between lower the ridge's crest smoothly.
    crest = [float(relief.heights(np.array([0.8 * extent[2]]), np.array([0.5 * extent[3]]), s)[0])
             for s in (0.0, 100.0, 400.0, 1600.0)]
    assert crest[0] > crest[1] > crest[2] > crest[3] > H.mean()


def test_far_field_rings_continue_a_ridge_past_the_border():
    H, extent = _ridge_dem()
    node = Heightfield(H.astype(np.float32), extent)
    mesh = far_field_mesh(node)
    v = mesh.vertices
    w = extent[2]
    # Vertices past the right border, within 0.6 of a tile, near the tile's middle in y.
    out = (v[:, 0] > w + 1.0) & (v[:, 0] < 1.6 * w) & (np.abs(v[:, 1] - 0.5 * w) < 0.3 * w)
    assert out.sum() > 50
    # The ridge's mirror image stands at x = 1.2 w: well above the plain there.
    near_mirror = out & (np.abs(v[:, 0] - 1.2 * w) < 0.05 * w)
    assert near_mirror.any() and v[near_mirror, 2].max() > 100.0 + 0.5 * 400.0, v[near_mirror, 2].max()
    # ... and the plain beside it stays low (the relief, not a raised skirt).
    plain = out & (np.abs(v[:, 0] - 1.45 * w) < 0.05 * w)
    assert v[plain, 2].max() < 100.0 + 0.25 * 400.0, v[plain, 2].max()
    # The first ring is the border itself: every border sample is a vertex of the mesh.
    Hn = np.asarray(node.heights_np, np.float64)  # the heights as the node stores them
    n = Hn.shape[0]
    d = w / (n - 1)
    border = np.array([(i * d, 0.0, Hn[0, i]) for i in range(n)] + [(w, j * d, Hn[j, -1]) for j in range(n)])
    gaps = np.min(np.linalg.norm(v[None, :, :] - border[:, None, :], axis=2), axis=1)
    assert gaps.max() < 1e-6


def test_blur_and_interpolation_are_scipys_bit_for_bit():
    """The relief's pyramid and lookups are written in numpy (no scipy.ndimage import in a
    render process); they must be scipy's filters exactly."""
    ndimage = pytest.importorskip("scipy.ndimage")
    from generators.terrain.mirrored_relief import bilinear, gaussian_blur
    rng = np.random.default_rng(8)
    for shape in [(1, 1), (2, 9), (5, 3), (37, 53), (64, 64)]:
        H = rng.normal(size=shape) * 100.0
        assert np.array_equal(gaussian_blur(H), ndimage.gaussian_filter(H, 1.0, mode="mirror"))
        v = np.concatenate([rng.uniform(-2.0, shape[0] + 2.0, 4000), np.arange(shape[0], dtype=float)])
        u = np.concatenate([rng.uniform(-2.0, shape[1] + 2.0, 4000), np.full(shape[0], shape[1] - 1.0)])
        assert np.array_equal(bilinear(H, v, u), ndimage.map_coordinates(H, [v, u], order=1, mode="nearest"))


def _ridges_dem(n=97, width=9600.0):
    """Mountains: crossing ridges 3.2 km apart, 600 m from trough to crest."""
    x = np.linspace(0.0, width, n)
    X, Y = np.meshgrid(x, x)
    return (1500.0 + 300.0 * np.sin(2 * np.pi * X / 3200.0) * np.cos(2 * np.pi * Y / 4200.0)), (0.0, 0.0, width, width)


def test_far_rings_keep_mountains_past_the_tile_and_in_its_corners_then_fade():
    """Past a tile or two the rings' blur stops at the width that keeps most of the relief
    (blur_schedule): the ridges run on, beside the sides and in the corner quadrants
    alike (the blur that grew with distance alone made a flat plain there, and the
    corner quadrants were a few long triangles); far past the distance where they
    would subtend RELIEF_ANGLE, the ground is the mean height; and the mesh stays
    within MAX_RING points a ring."""
    from generators.terrain import far_field
    H, extent = _ridges_dem()
    w = extent[2]
    mesh = far_field_mesh(Heightfield(H.astype(np.float32), extent))
    v = mesh.vertices
    gap = np.maximum(np.maximum(extent[0] - v[:, 0], v[:, 0] - extent[2]),
                     np.maximum(extent[1] - v[:, 1], v[:, 1] - extent[3]))  # distance past the tile
    band = (gap > 2.0 * w) & (gap < 5.0 * w)
    corner = band & (v[:, 0] > extent[2]) & (v[:, 1] > extent[3]) & (np.abs(v[:, 0] - v[:, 1]) < 0.5 * gap)
    side = band & (v[:, 0] > extent[2]) & (np.abs(v[:, 1] - 0.5 * w) < 0.5 * w)
    for part in (side, corner):
        assert part.sum() > 100
        # (the DEM's deviation is 150 m; 0.7 of it is kept, sampled at random phases)
        assert v[part, 2].std() > 0.4 * H.std(), v[part, 2].std()
    far = gap > 20.0 * 2.0 * H.std() / far_field.RELIEF_ANGLE
    # Exactly the mean of the stored (float32) heights past the pyramid's coarsest level:
    # atol 1e-6 m is float64 rounding of the blend weight (w = 1) and of the mean, as in
    # the MirroredRelief test above (measured: 0).
    mean = float(np.asarray(H, np.float32).astype(np.float64).mean())
    assert far.sum() > 10 and np.allclose(v[far, 2], mean, atol=1e-6)
    rings = len(far_field.ring_distances(w / 96, far_field.default_reach(extent), 1.0 + 0.7 / far_field.DETAIL))
    assert len(v) < rings * far_field.MAX_RING + H.size


def test_blur_schedule_grows_continuously_from_a_cell_and_a_flat_dem_stays_small():
    from generators.terrain.far_field import DETAIL, KEEP_RELIEF, blur_schedule
    H, extent = _ridges_dem()
    cell = extent[2] / (H.shape[0] - 1)
    relief = MirroredRelief(H, extent)
    sigma = blur_schedule(relief, cell)
    s = np.geomspace(1.0, 1e8, 2000)
    b = np.array([sigma(x) for x in s])
    assert np.all(np.diff(b) >= 0) and np.all(b[1:] / b[:-1] < 1.05)  # no jumps between nearby s
    # Near the tile: detail fades with distance; a few tiles out: the ridges' own scale
    # (a blur of 3.2 km ridges that keeps 0.7 of them is a few hundred metres).
    keep = relief.blur_keeping(KEEP_RELIEF)
    assert b[0] == s[0] / (2 * DETAIL) and b[np.searchsorted(s, 5 * extent[2])] == max(keep, cell) < 800.0
    # A flat DEM: no relief to keep, the rings coarsen with distance (no million-point rings).
    flat = np.full((33, 33), 7.0)
    mesh = far_field_mesh(Heightfield(flat.astype(np.float32), (0.0, 0.0, 3200.0, 3200.0)))
    assert len(mesh.vertices) < 20000 and np.allclose(mesh.vertices[:, 2], 7.0)


@pytest.mark.parametrize("shape, extent", [((2, 2), (0.0, 0.0, 10.0, 10.0)), ((7, 40), (0.0, 0.0, 3900.0, 600.0)),
                                           ((64, 64), (-1e5, -1e5, 1e5, 1e5))])
def test_rings_cover_the_ground_around_the_tile_once(shape, extent):
    """The stitched rings tile the plane from the border to the reach: their triangles'
    projected areas sum to the annulus's exactly (a hole or an overlap would not), all face
    up and none is degenerate, for tiny, narrow and wide tiles."""
    H = (np.random.default_rng(0).normal(size=shape) * 10.0).astype(np.float32)
    mesh = far_field_mesh(Heightfield(H, extent))
    v, f = mesh.vertices, mesh.faces
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    up = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]  # twice the signed projected area
    x0, y0, x1, y1 = extent
    reach = v[:, 0].max() - x1
    annulus = (x1 - x0 + 2 * reach) * (y1 - y0 + 2 * reach) - (x1 - x0) * (y1 - y0)
    assert np.all(up > 0)
    # (float64 sums of ~1e5 areas up to ~1e14 m2: a part in 1e9)
    assert abs(0.5 * up.sum() / annulus - 1.0) < 1e-9


def test_the_first_rings_of_a_large_dem_are_as_fine_as_its_border():
    """Next to the tile the rings keep a point a cell, as the border loop does, however
    large the DEM (MAX_RING caps only rings past a quarter tile): a 1200^2 DEM's ring one
    cell out is sampled about a cell apart along its side."""
    from generators.terrain import far_field
    n, cell = 1200, 10.0
    H = np.random.default_rng(3).normal(size=(n, n)).astype(np.float32)
    w = (n - 1) * cell
    mesh = far_field_mesh(Heightfield(H, (0.0, 0.0, w, w)))
    v = mesh.vertices
    ring = v[np.isclose(v[:, 1], -cell) & (v[:, 0] >= 0.0) & (v[:, 0] <= w)]  # the first ring's south side
    assert 4 * n > far_field.MAX_RING
    # (the ring's side is two cells longer than the border's, cut into as many pieces)
    assert len(ring) >= n - 2 and np.diff(np.sort(ring[:, 0])).max() <= cell * (1 + 3.0 / n)


def test_a_dem_two_samples_wide_is_itself_unblurred():
    """A DEM two samples wide has no pyramid level past its own: unblurred, its heights are
    its own (they were its mean); blurred by a sample or more, its mean."""
    H = np.array([[0.0, 10.0, 20.0, 30.0], [5.0, 15.0, 25.0, 35.0]])
    relief = MirroredRelief(H, (0.0, 0.0, 300.0, 100.0))
    x, y = np.array([0.0, 100.0, 250.0, 300.0]), np.array([0.0, 100.0, 50.0, 100.0])
    # atol 1e-9 m: float64 bilinear weights (exact at samples, 2.5 m + 25 m at the middle point).
    assert np.allclose(relief.heights(x, y, 0.0), [0.0, 15.0, 27.5, 35.0], atol=1e-9)
    assert np.allclose(relief.heights(x, y, 100.0), H.mean(), atol=1e-9)


@pytest.mark.parametrize("sea", [False, True])
def test_rays_just_below_the_horizon_of_a_high_camera_meet_the_far_field(sea):
    """No void at the horizon: from 100 km above a 6.4 km tile, rays 3e-5 rad below the
    horizontal (a fifth of a pixel of a 4K frame at 50 degrees) meet the far ground (or
    its sea ring) in every azimuth, where the old 1e7 m reach let them pass its edge
    into the sky's black lower hemisphere (a row of dark specks along an overview's horizon)."""
    import drjit as dr
    import mitsuba as mi
    from generators.terrain.far_field import default_reach, sea_ring_mesh
    H, extent = _ridge_dem()
    reach = default_reach(extent)
    meshes = [far_field_mesh(Heightfield(H, extent))]
    if sea:
        meshes.append(sea_ring_mesh(extent, 150.0, reach))
    shapes = {}
    for k, m in enumerate(meshes):
        shape = mi.Mesh(f"far{k}", len(m.vertices), len(m.faces))
        params = mi.traverse(shape)
        params["vertex_positions"] = mi.Float(np.asarray(m.vertices, np.float32).ravel())
        params["faces"] = mi.UInt32(np.asarray(m.faces, np.uint32).ravel())
        params.update()
        shapes[f"far{k}"] = shape
    scene = mi.load_dict({"type": "scene", **shapes})
    n = 720
    azimuth = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    dip = 3e-5
    d = np.column_stack([np.cos(azimuth) * np.cos(dip), np.sin(azimuth) * np.cos(dip), np.full(n, -np.sin(dip))])
    o = np.tile([3200.0, 3200.0, 1e5], (n, 1))
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(o[:, i].astype(np.float32)) for i in range(3))),
                   mi.Vector3f(*(mi.Float(d[:, i].astype(np.float32)) for i in range(3))))
    hit = scene.ray_intersect_preliminary(ray).is_valid()
    dr.eval(hit)
    assert hit.numpy().all(), np.flatnonzero(~hit.numpy())[:10]
