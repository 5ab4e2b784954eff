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
from generators.terrain.far_field import MirroredRelief, far_field_mesh  # noqa: E402


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
    from generators.terrain.far_field import bilinear, gaussian_blur
    rng = np.random.default_rng(8)
    for shape in [(1, 1), (2, 9), (5, 3), (37, 53), (64, 64)]:
        H = rng.normal(size=shape) * 100.0
        assert np.array_equal(gaussian_blur(H), ndimage.gaussian_filter(H, 1.0, mode="mirror"))
        v = np.concatenate([rng.uniform(-2.0, shape[0] + 2.0, 4000), np.arange(shape[0], dtype=float)])
        u = np.concatenate([rng.uniform(-2.0, shape[1] + 2.0, 4000), np.full(shape[0], shape[1] - 1.0)])
        assert np.array_equal(bilinear(H, v, u), ndimage.map_coordinates(H, [v, u], order=1, mode="nearest"))
