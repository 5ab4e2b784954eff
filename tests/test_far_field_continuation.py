"""The far field continues a DEM without copies of its landforms (issue 34;
generators/terrain/continued_relief.py).

The mirror alone repeats every landform of the tile every two tiles to the horizon
(a volcanic tile's crater thirty times a side). ``ContinuedRelief`` is the mirror near
the tile and, past ``BAND`` tiles, a continuation with the tile's spectrum and height
distribution, its tile-scale trends mirrored and its landforms not.
"""

from __future__ import annotations

import numpy as np

from helpers import variant

variant()

from generators.terrain.continued_relief import BAND, COAST_MARGIN, ContinuedRelief  # noqa: E402
from generators.terrain.mirrored_relief import MirroredRelief  # noqa: E402

W = 2000.0  # the tiles' side (metres)


def _crater_dem(n=129, seed=3):
    """Rolling ground (a few metres of smooth noise) with a crater at the tile's middle:
    a rim 60 m high, 500 m across, around a bowl 40 m deep."""
    rng = np.random.default_rng(seed)
    x = np.linspace(0.0, W, n)
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X - W / 2, Y - W / 2)
    H = 60.0 * np.exp(-0.5 * ((r - 250.0) / 60.0) ** 2) - 40.0 * np.exp(-0.5 * (r / 120.0) ** 2)
    k = np.fft.fftfreq(n)
    K = np.hypot(*np.meshgrid(k, k))
    H += 3.0 * np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal((n, n))) * np.exp(-(K / 0.02) ** 2))) / 0.05
    return H + 100.0, (0.0, 0.0, W, W)


def _patch(relief, cx, cy, sigma=0.0, half=400.0, m=41):
    """Heights on an ``m x m`` grid ``half`` metres around ``(cx, cy)``."""
    u = np.linspace(-half, half, m)
    U, V = np.meshgrid(u, u)
    return relief.heights((cx + U).ravel(), (cy + V).ravel(), sigma).reshape(U.shape)


def _likeness(a, b):
    """Correlation of two patches (1: the same landform up to height and scale)."""
    a, b = a - a.mean(), b - b.mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


def test_the_continuation_is_the_mirror_near_the_tile():
    H, extent = _crater_dem()
    cont, mirror = ContinuedRelief(H, extent), MirroredRelief(H, extent)
    rng = np.random.default_rng(0)
    # Inside the tile and within BAND[0] tiles of it: the mirror's heights, bit for bit.
    p = rng.uniform(-BAND[0] * W, (1.0 + BAND[0]) * W, (2, 4000))
    for sigma in (0.0, 30.0, 300.0):
        assert np.array_equal(cont.heights(p[0], p[1], sigma), mirror.heights(p[0], p[1], sigma))
    # Heights change smoothly through the band: along a line out of the tile, sampled
    # every metre, no step is larger than the mirror's own largest step or the
    # continuation's (each continuous), times 1.5 for the blend's slope.
    x = np.arange(W, W + 0.5 * W, 1.0)
    y = np.full_like(x, 0.3 * W)
    steps = np.abs(np.diff(cont.heights(x, y, 5.0))).max()
    own = max(np.abs(np.diff(mirror.heights(x, y, 5.0))).max(),
              np.abs(np.diff(cont.continued.heights(x, y, 5.0))).max())
    assert steps <= 1.5 * own + 0.1, (steps, own)


def test_the_tiles_landform_does_not_recur_past_the_band():
    H, extent = _crater_dem()
    cont, mirror = ContinuedRelief(H, extent), MirroredRelief(H, extent)
    crater = _patch(mirror, W / 2, W / 2)
    # Where the mirror puts the crater again: every two tiles, and one tile out across
    # each border (at T / 2 outside, past BAND[1]).
    twins = [(W / 2 + a * W, W / 2 + b * W) for a in range(-4, 5) for b in range(-4, 5) if (a, b) != (0, 0)]
    mirror_likeness = [_likeness(crater, _patch(mirror, x, y)) for x, y in twins]
    assert min(mirror_likeness) > 0.99  # the mirror copies it (the test's premise)
    likeness = [_likeness(crater, _patch(cont, x, y)) for x, y in twins]
    assert max(likeness) < 0.5, sorted(likeness)[-3:]


def test_the_continuation_keeps_the_tiles_relief_and_its_heights():
    H, extent = _crater_dem()
    cont = ContinuedRelief(H, extent)
    rng = np.random.default_rng(1)
    a = rng.uniform(0.0, 2.0 * np.pi, 20000)
    s = rng.uniform(1.0, 5.0, 20000) * W
    h = cont.heights(W / 2 + s * np.cos(a), W / 2 + s * np.sin(a), 0.0)
    # Its heights are the tile's (matched to the tile's own distribution): within the tile's
    # range, with a deviation within 30 % of the tile's (the draw of the noise and where
    # the low part's trend falls vary it; measured 0.93 of it here).
    assert H.min() <= h.min() and h.max() <= H.max()
    assert 0.7 * H.std() < h.std() < 1.3 * H.std(), (h.std(), H.std())


def _coast_dem(seed=5, n=129):
    """A coast, sea (below 0 m) on the west half of the tile, land on the east."""
    x = np.linspace(0.0, W, n)
    X, Y = np.meshgrid(x, x)
    rng = np.random.default_rng(seed)
    H = 80.0 * np.tanh((X - W / 2) / 150.0) + 10.0 + 6.0 * np.sin(Y / 90.0) * np.cos(X / 70.0)
    return H + 2.0 * rng.standard_normal(H.shape)


def test_without_a_sea_a_coasts_tile_scale_trends_run_on_as_the_mirror_has_them():
    """Without a sea level the continuation knows no sea: its mirror has the west's sea
    in bands a tile wide (x in (-W/2, W/2), (3W/2, 5W/2), ...) and land between, and the
    continuation keeps those tile-scale trends (its low part); only its detail is new."""
    H = _coast_dem()
    rng = np.random.default_rng(5)
    cont, mirror = ContinuedRelief(H, (0.0, 0.0, W, W)), MirroredRelief(H, (0.0, 0.0, W, W))
    y = rng.uniform(-2.0 * W, 3.0 * W, 5000)
    for lo, hi, sea in ((1.7, 2.3, True), (-1.3, -0.7, False), (2.7, 3.3, False), (-2.3, -1.7, True)):
        x = rng.uniform(lo * W, hi * W, 5000)
        share, share_mirror = (np.mean((r.heights(x, y, 20.0) < 0.0) == sea) for r in (cont, mirror))
        assert share_mirror > 0.95  # the premise: open sea, or land, a tile wide
        # Measured 0.85-0.97: the continuation's detail raises an island or sinks a lake
        # here and there; without its low part (tile-scale trends) the first was 0.65.
        assert share > 0.8, (lo, hi, share)


def test_with_a_sea_a_coast_runs_on_as_sea_and_land():
    """With the sea level, past the tile's sea border lies sea and past its land border
    land, to six tiles out (the mirror put a far shore a tile out to sea, and a sea a
    tile inland); north and south, where the coastline leaves the tile, it runs on:
    its west sea, its east land. Heights far from the sea level keep the continuation's."""
    H = _coast_dem()
    rng = np.random.default_rng(6)
    sea, plain = ContinuedRelief(H, (0.0, 0.0, W, W), sea_level=0.0), ContinuedRelief(H, (0.0, 0.0, W, W))
    y = rng.uniform(-5.0 * W, 6.0 * W, 5000)
    west, east = rng.uniform(-6.0 * W, -BAND[1] * W, 5000), rng.uniform((1.0 + BAND[1]) * W, 7.0 * W, 5000)
    assert np.mean(plain.heights(west, y, 20.0) > 0.0) > 0.3  # the premise: land out to sea
    assert np.all(sea.heights(west, y, 20.0) < 0.0)
    assert np.all(sea.heights(east, y, 20.0) > 0.0)
    # Beyond the north and south borders, well clear of where the coast crosses them.
    for x0, x1, wet in ((0.0, 0.3 * W, True), (0.7 * W, W, False)):
        x = rng.uniform(x0, x1, 4000)
        yy = np.concatenate([rng.uniform(-4.0 * W, -BAND[1] * W, 2000), rng.uniform((1 + BAND[1]) * W, 5.0 * W, 2000)])
        h = sea.heights(x, yy, 20.0)
        assert np.all((h < 0.0) == wet), (x0, x1)
    # Samples on their border's side of the sea, far from it, move by m^2 / (2 |h|) at most
    # (the fold's hyperbola, m the margin), compared on the continuation's grid (the same
    # seed in both). Those that do not are where the coastline leaves the tile, in the
    # fade between sea and land (measured: 0.7 % of them); a sample on the wrong side is
    # folded over (half of them here: the mirror's bands).
    g0, g1 = (np.asarray(r.continued.levels[0]) for r in (plain, sea))
    m = COAST_MARGIN * plain.relief
    kept = (np.abs(g0) > 60.0) & (np.sign(g0) == np.sign(g1))
    assert kept.mean() > 0.3
    assert np.mean(np.abs(g1[kept] - g0[kept]) <= m * m / (2.0 * np.abs(g0[kept])) + 1e-6) > 0.98


def test_the_same_dem_gives_the_same_far_field():
    H, extent = _crater_dem()
    p = np.random.default_rng(2).uniform(-3.0 * W, 4.0 * W, (2, 3000))
    a = ContinuedRelief(H, extent).heights(p[0], p[1], 10.0)
    assert np.array_equal(a, ContinuedRelief(H.copy(), extent).heights(p[0], p[1], 10.0))
    H2 = H.copy()
    H2[3, 5] += 0.5
    assert not np.array_equal(a, ContinuedRelief(H2, extent).heights(p[0], p[1], 10.0))


def test_a_flat_dem_continues_flat():
    H = np.full((33, 33), 42.0)
    cont = ContinuedRelief(H, (0.0, 0.0, W, W))
    p = np.random.default_rng(3).uniform(-3.0 * W, 4.0 * W, (2, 1000))
    assert cont.continued is None
    # atol 1e-9 m: the mirror's bilinear weights in float64 (they sum to 1 up to rounding).
    assert np.allclose(cont.heights(p[0], p[1], 0.0), 42.0, rtol=0.0, atol=1e-9)


def test_the_far_fields_ground_keeps_a_coasts_sea_open():
    """The far field's mesh takes the sea level (as amplify's scenes give it with a sea
    ring): its ground out to sea, one to five tiles west, stays under the sea."""
    from arches_render.field import Heightfield
    from generators.terrain.far_field import far_field_mesh
    H = _coast_dem().astype(np.float32)
    for sea_level, dry in ((None, True), (0.0, False)):
        v = far_field_mesh(Heightfield(H, (0.0, 0.0, W, W)), sea_level=sea_level).vertices
        west = (v[:, 0] < -W) & (v[:, 0] > -5.0 * W) & (np.abs(v[:, 1] - 0.5 * W) < 2.0 * W)
        assert west.sum() > 50
        assert np.any(v[west, 2] > 0.0) == dry  # (without it: the mirror's far shore)
