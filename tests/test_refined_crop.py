"""A coarse DEM refined to a crop at the landforms' scale, in its DEM as the far field (issue 34 item 3)."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from helpers import variant
from robust_helpers import cli_out

CELL = 500.0


def _coast(nx=80, ny=64, cell=CELL):
    """A coarse coast: sea in the west (to -60 m), the shore at x = 12.3 cells, land rising
    east to a plateau of 1.2 km past x = 20 cells, a hill at (30, 6) on it, and
    roughness at every scale (the spectrum the detail continues; the fit needs 64 cells)."""
    x = np.arange(nx) * cell
    y = np.arange(ny) * cell
    X, Y = np.meshgrid(x, y)
    land = 1400.0 / (1.0 + np.exp(-(X / cell - 14.0) / 1.0)) - 210.0
    hill = 300.0 * np.exp(-(((X - 30 * cell) ** 2 + (Y - 6 * cell) ** 2) / (2 * cell) ** 2))
    rough = np.random.default_rng(7).normal(0.0, 12.0, X.shape)
    return np.maximum(land + hill + rough, -60.0)


def _bilinear(H, u, v):
    """``H`` bilinear at fractional column ``u`` and row ``v`` (arrays)."""
    i = np.clip(np.floor(u).astype(int), 0, H.shape[1] - 2)
    j = np.clip(np.floor(v).astype(int), 0, H.shape[0] - 2)
    a, b = u - i, v - j
    return ((1 - a) * (1 - b) * H[j, i] + a * (1 - b) * H[j, i + 1] + (1 - a) * b * H[j + 1, i]
            + a * b * H[j + 1, i + 1])


def test_window_has_the_greatest_relief_and_a_coast_first():
    from arches_render.generators.terrain.refined_crop import COAST_SHARE, crop_window
    # A low coast in the west and a mountain of 2 km far inland.
    X, Y = np.meshgrid(np.arange(80.0), np.arange(64.0))
    H = 10.0 * (X - 12.0) + 2000.0 * np.exp(-((X - 60.0) ** 2 + (Y - 30.0) ** 2) / 6.0 ** 2)
    side = 10
    i0, j0 = crop_window(H, side)  # no sea: the mountain, the greatest relief in a window's middle
    mid = slice(2, 2 + side // 2 + 1)  # the middle 5 cells of 10

    def middle(jj, ii):
        w = H[jj:jj + side + 1, ii:ii + side + 1][mid, mid]
        return w.max() - w.min()
    relief = middle(j0, i0)
    for jj in range(H.shape[0] - side):
        for ii in range(H.shape[1] - side):
            assert middle(jj, ii) <= relief + 1e-9
    assert abs(i0 + side / 2 - 60) < 6 and abs(j0 + side / 2 - 30) < 6, (i0, j0)  # the mountain, in the middle
    # With a sea, the window holds a shore: sea and land in COAST_SHARE.
    i0, j0 = crop_window(H, side, 0.0)
    wet = np.mean(H[j0:j0 + side + 1, i0:i0 + side + 1] < 0.0)
    assert COAST_SHARE[0] <= wet <= COAST_SHARE[1], (i0, j0, wet)


def test_crop_is_finer_meets_its_dem_at_the_border_and_keeps_the_same_bits():
    variant()
    from arches_render.generators.terrain.refined_crop import refine_crop
    H = _coast()
    crop = refine_crop(H, CELL, 0.0, seed=4, cells=64, width=5000.0)
    i0, j0, side = crop.window
    assert side == 10 and crop.cell == pytest.approx(side * CELL / 64)
    Z = crop.heights
    assert Z.shape == (65, 65)
    # The context is the DEM resampled (through its samples) a few times denser ...
    up = (crop.context.shape[1] - 1) // (H.shape[1] - 1)
    assert up > 1 and crop.context.shape == ((H.shape[0] - 1) * up + 1, (H.shape[1] - 1) * up + 1)
    assert np.abs(crop.context[::up, ::up] - H).max() < 1e-6
    # ... and at the border the crop is the context's bilinear surface (what the far field reads).
    k = np.arange(65) * side / 64
    for (u, v, z) in ((i0 + k, np.full(65, j0), Z[0]), (i0 + k, np.full(65, j0 + side), Z[-1]),
                      (np.full(65, i0), j0 + k, Z[:, 0]), (np.full(65, i0 + side), j0 + k, Z[:, -1])):
        assert np.abs(z - _bilinear(crop.context, u * up, v * up)).max() < 1e-6
    # Inside, relief below the DEM's cell: the detail departs from the bilinear surface
    # on land, by metres (the DEM's spectrum continued), not by its relief.
    U, V = np.meshgrid(i0 + k, j0 + k)
    lin = _bilinear(H, U, V)
    inner = np.zeros_like(Z, bool)
    inner[16:-16, 16:-16] = True
    land = inner & (lin > 50.0)
    dev = np.abs(Z - lin)[land]
    assert land.sum() > 100 and 1.0 < np.median(dev) < 0.2 * (H.max() - H.min())
    # No detail at or below the sea level (no islands or pools along the shore): there
    # the seed (which draws only the detail) changes nothing; on land it does.
    other = refine_crop(H, CELL, 0.0, seed=5, cells=64, width=5000.0)
    wet = lin <= 0.0
    assert wet.sum() > 100 and np.array_equal(other.heights[wet], Z[wet])
    assert np.abs(other.heights - Z)[land].min() > 0.0
    # The window's centre is the crop's origin in the context's frame.
    x0, y0, x1, y1 = crop.context_extent
    assert x0 + (i0 + 0.5 * side) * CELL == pytest.approx(0.0, abs=1e-6)
    assert y0 + (j0 + 0.5 * side) * CELL == pytest.approx(0.0, abs=1e-6)
    assert x1 - x0 == pytest.approx((H.shape[1] - 1) * CELL) and y1 - y0 == pytest.approx((H.shape[0] - 1) * CELL)
    again = refine_crop(H, CELL, 0.0, seed=4, cells=64, width=5000.0)
    assert np.array_equal(again.heights, Z)


def test_far_field_reads_the_context_around_the_tile():
    variant()
    from arches_render.field import Heightfield
    from arches_render.generators.terrain.far_field import far_field_mesh
    from arches_render.generators.terrain.refined_crop import refine_crop
    H = _coast()
    crop = refine_crop(H, CELL, None, seed=1, cells=64, width=5000.0)
    half = 0.5 * 64 * crop.cell
    tile = Heightfield(crop.heights.astype(np.float32), (-half, -half, half, half))
    with_context = far_field_mesh(tile, context=(crop.context, crop.context_extent)).vertices
    alone = far_field_mesh(tile).vertices
    x0, y0, x1, y1 = crop.context_extent
    # Ring vertices within the DEM, a few km past the tile: the DEM's heights there
    # (blurred as the rings are: within a tenth of its relief), not the tile's continuation.
    def near_ring(v):
        d = np.maximum(np.abs(v[:, 0]), np.abs(v[:, 1])) - half
        keep = (d > 1500.0) & (d < 4000.0) & (v[:, 0] > x0) & (v[:, 0] < x1) & (v[:, 1] > y0) & (v[:, 1] < y1)
        return v[keep]
    v = near_ring(with_context)
    want = _bilinear(H, (v[:, 0] - x0) / CELL, (v[:, 1] - y0) / CELL)
    relief = H.max() - H.min()
    assert len(v) > 50 and np.median(np.abs(v[:, 2] - want)) < 0.1 * relief
    w = near_ring(alone)
    want_alone = _bilinear(H, (w[:, 0] - x0) / CELL, (w[:, 1] - y0) / CELL)
    assert np.median(np.abs(w[:, 2] - want_alone)) > 2.0 * np.median(np.abs(v[:, 2] - want))


def test_far_field_context_is_checked(tmp_path):
    variant()
    from arches_render.scene import load_scene
    from arches_render.scene.errors import SceneError
    np.save(tmp_path / "t.npy", np.zeros((5, 5), np.float32))
    np.save(tmp_path / "c.npy", np.zeros((9, 9), np.float32))
    base = """
[camera]
origin = [-30.0, -30.0, 20.0]
target = [0.0, 0.0, 0.0]
[[lights]]
type = "sunsky"
elevation = 35.0
[materials.ground]
type = "triplanar"
preset = "terrain"
[field]
root = "terrain"
material = "ground"
[nodes.terrain]
type = "heightfield"
source = "file"
file = "t.npy"
extent = [-10.0, -10.0, 10.0, 10.0]
[[far_field]]
node = "terrain"
material = "ground"
"""
    ok = tmp_path / "ok.toml"
    ok.write_text(base + 'context = { file = "c.npy", extent = [-40.0, -40.0, 40.0, 40.0] }\n')
    far = load_scene(ok).tables["far_field"][0]
    assert far.context[0].shape == (9, 9) and far.context[1] == (-40.0, -40.0, 40.0, 40.0)
    for text, key in (('{ file = "c.npy", extent = [-5.0, -40.0, 40.0, 40.0] }', "far_field[0].context.extent"),
                      ('{ file = "none.npy", extent = [-40.0, -40.0, 40.0, 40.0] }', "far_field[0].context.file"),
                      ('{ file = "c.npy", extent = [-40.0, -40.0, 40.0, 40.0], blur = 2 }', "blur")):
        bad = tmp_path / "bad.toml"
        bad.write_text(base + f"context = {text}\n")
        with pytest.raises(SceneError) as err:
            load_scene(bad)
        assert key in str(err.value), str(err.value)


def test_amplify_refine_carves_a_coarse_coast_in_metres(tmp_path, capsys):
    """``amplify --refine`` on a 500 m coast: a crop of fine cells whose landforms are
    metres wide, its far field the DEM around it; with ``--no-refine`` the header says at
    what scale the whole DEM's landforms are carved."""
    variant()
    from arches_render.scene import load_scene
    np.save(tmp_path / "coast.npy", _coast())
    out = tmp_path / "coast.toml"
    rc, stdout, err = cli_out(capsys, "amplify", tmp_path / "coast.npy", "-o", out, "--cell-size", "500",
                              "--refine", "--refine-cells", "128", "--seed", "2", "-q")
    assert rc == 0, err
    doc = tomllib.loads(out.read_text())
    header = [line for line in out.read_text().splitlines() if line.startswith("#")]
    assert any("refined: a 5 km crop" in line for line in header), header
    x0, y0, x1, y1 = doc["nodes"]["terrain"]["extent"]
    assert x1 - x0 == pytest.approx(5000.0) and y1 - y0 == pytest.approx(5000.0)
    Z = np.load(tmp_path / doc["nodes"]["terrain"]["file"], allow_pickle=False)
    assert Z.shape == (129, 129)
    sizes = next(line for line in header if line.startswith("# Landform sizes"))
    feature = float(sizes.split("feature ")[1].split(",")[0])
    assert feature < 0.05 * CELL, sizes  # metres, not the DEM's cell
    sea = np.load(tmp_path / doc["nodes"]["sea_erosion"]["file"], allow_pickle=False)
    assert np.median(sea["radius"]) < 0.1 * CELL  # the carving primitives too
    context = doc["far_field"][0]["context"]
    C = np.load(tmp_path / context["file"], allow_pickle=False)
    assert C.shape == (63 * 4 + 1, 79 * 4 + 1)
    desc = load_scene(out)
    far = desc.tables["far_field"][0]
    assert far.context is not None and len(far.meshes()[0][1].vertices) > 0
    assert len(desc.cameras) >= 2  # a close shot of what was carved, and the overview

    plain = tmp_path / "plain.toml"
    rc, stdout, err = cli_out(capsys, "amplify", tmp_path / "coast.npy", "-o", plain, "--cell-size", "500",
                              "--seed", "2", "--preset", "sea", "--no-refine", "-q")
    assert rc == 0, err
    assert "landforms are carved at this scale (--no-refine)" in plain.read_text()
    # The same preset on the whole DEM sizes its coastal cliffs by the DEM's cell; the
    # crop's are its benches' risers (a tenth of its relief, here 100 m).
    def cliff(text):
        line = next(x for x in text.splitlines() if x.startswith("# Landform sizes"))
        return float(line.split("coast_cliff ")[1].split(",")[0])
    assert cliff(plain.read_text()) >= CELL and cliff(out.read_text()) <= 0.25 * CELL
    assert "context" not in tomllib.loads(plain.read_text())["far_field"][0]


def test_overview_of_a_refined_crop_stands_over_it():
    """The far field around a refined crop is the coarse DEM: the overview's camera stays
    over the crop (its facets in the foreground read as a seam); a tile's own overview
    may stand past its border."""
    variant()
    from arches_render.generators.terrain.refined_crop import refine_crop
    from arches_render.generators.terrain.overview import TILE_INSET, frame_camera
    crop = refine_crop(_coast(), CELL, 0.0, seed=1, cells=64, width=5000.0)
    half = 0.5 * 64 * crop.cell
    extent = (-half, -half, half, half)
    alone = frame_camera(crop.heights, extent)
    assert max(abs(alone["origin"][0]), abs(alone["origin"][1])) > half
    cam = frame_camera(crop.heights, extent, context=(crop.context, crop.context_extent))
    assert max(abs(cam["origin"][0]), abs(cam["origin"][1])) <= TILE_INSET * half + 1e-6


def test_steep_slopes_become_benches_with_walls(monkeypatch):
    """A 25 degree ramp at 200 m cells hides cliff bands: refined, it has walls (the strata
    preset's rule), and gentle ground is left as the spline made it."""
    variant()
    from arches_render.generators.terrain import refined_crop
    from arches_render.generators.terrain.preset_choice import has_walls, terrain_stats
    X, _ = np.meshgrid(np.arange(40.0), np.arange(40.0))
    ramp = np.clip(X - 14.0, 0.0, 12.0) * 200.0 * np.tan(np.radians(25.0))  # 1.1 km over 2.4 km
    crop = refined_crop.refine_crop(ramp, 200.0, None, seed=3, cells=128, width=5000.0)
    monkeypatch.setattr(refined_crop, "BENCH_SLOPES", (89.0, 90.0))  # no slope that steep: no benches
    smooth = refined_crop.refine_crop(ramp, 200.0, None, seed=3, cells=128, width=5000.0)
    assert has_walls(terrain_stats(crop.heights, crop.cell, -1e4))
    assert not has_walls(terrain_stats(smooth.heights, smooth.cell, -1e4))
    gy, gx = np.gradient(smooth.heights, smooth.cell)
    gentle = np.degrees(np.arctan(np.hypot(gx, gy))) < 5.0
    assert gentle.mean() > 0.2 and np.array_equal(crop.heights[gentle], smooth.heights[gentle])


def test_a_refined_crop_takes_its_regions_snow_line(tmp_path, capsys):
    """The material's layers follow the DEM around the crop: the crop of a steep 2.5 km
    peak beside a broad 4 km massif keeps the region's snow line (the top quarter of the
    region's rise), not its own."""
    variant()
    X, Y = np.meshgrid(np.arange(64.0), np.arange(64.0))
    H = (4000.0 * np.exp(-((X - 16.0) ** 2 + (Y - 32.0) ** 2) / 20.0 ** 2)
         + 2500.0 * np.exp(-((X - 50.0) ** 2 + (Y - 32.0) ** 2) / 2.5 ** 2) + 200.0)
    H += np.random.default_rng(1).normal(0.0, 20.0, H.shape)
    np.save(tmp_path / "m.npy", H)
    out = tmp_path / "m.toml"
    rc, _, err = cli_out(capsys, "amplify", tmp_path / "m.npy", "-o", out, "--cell-size", "200", "--refine",
                         "--refine-cells", "64", "--sea-level", "-1000", "-q")
    assert rc == 0, err
    doc = tomllib.loads(out.read_text())
    crop = np.load(tmp_path / doc["nodes"]["terrain"]["file"], allow_pickle=False)
    snow = doc["materials"]["landscape"]["overrides"]["snow.height_min"]
    C = np.load(tmp_path / doc["far_field"][0]["context"]["file"], allow_pickle=False)
    assert abs(snow - (C.max() - 0.25 * (C.max() - C.min()))) < 1.0
    assert abs(snow - (crop.max() - 0.25 * (crop.max() - crop.min()))) > 50.0


def test_close_shots_of_a_refined_crop_see_the_sky_over_the_dem_around_it(tmp_path, capsys):
    """A crop refined from a caldera lies inside its walls, and the far field (the DEM
    around the crop) rises over the crop's far side. The close shots count only the sky the
    scene shows, far field included, so every one renders sky in its top rows (one of them
    framed the far wall across the crop: 11 % sky there, where the crop alone left 13 %)."""
    variant()
    from landscape_helpers import render_shots, shot_report
    from synthetic_dems import caldera

    from arches_render.scene import load_scene
    np.save(tmp_path / "caldera.npy", caldera())
    out = tmp_path / "caldera.toml"
    rc, stdout, err = cli_out(capsys, "amplify", tmp_path / "caldera.npy", "-o", out, "--cell-size", "150",
                              "--refine", "--seed", "5", "-q")
    assert rc == 0, err
    desc = load_scene(out)
    assert desc.tables["far_field"][0].context is not None
    close = [name for name in desc.cameras if name != "overview"]
    assert len(close) >= 2, list(desc.cameras)
    for name, (rgb, layers) in render_shots(desc, 64, 36, 2).items():
        rep = shot_report(desc, layers, desc.cameras[name], 64, 36)
        if name in close:
            assert rep["top_sky"] > 0.5, (name, rep)


def test_benches_vary_in_thickness():
    """Beds are not equal: on a 30 degree ramp the risers' spacing along the fall line
    varies (median coefficient of variation over 17 profiles above 0.3; equal bands,
    warped alone, gave 0.2, and read from above as regular stripes)."""
    variant()
    from arches_render.generators.terrain.refined_crop import _benches
    n, cell, g = 513, 10.0, np.tan(np.radians(30.0))
    X, _ = np.meshgrid(np.arange(n) * cell, np.arange(n) * cell)
    S, band = _benches(X * g, cell, None, seed=4)
    assert band == 200.0
    cvs = []
    for row in range(0, n, 32):
        steep = np.gradient(S[row], cell) > g  # a riser climbs faster than the ramp
        edges = np.flatnonzero(np.diff(np.r_[0, steep.astype(int), 0]))
        spacing = np.diff(0.5 * (edges[::2] + edges[1::2]))
        cvs.append(spacing.std() / spacing.mean())
    assert np.median(cvs) > 0.3, cvs
    again, _ = _benches(X * g, cell, None, seed=4)
    assert np.array_equal(S, again)


@pytest.mark.parametrize("seed", [1, 3])
def test_a_refined_crops_lakes_are_its_dems(seed):
    """A crop refined from a caldera: its benches and detail dent the terraces with closed
    pits tens of metres deep, which held lakes high on the walls (5-6 on these seeds).
    The lakes are the DEM's: one, on the caldera's floor at the DEM's lake level, far
    below the rim; no water on the terraces."""
    variant()
    from synthetic_dems import caldera

    from arches_render.generators.terrain.refined_crop import refine_crop
    from arches_render.generators.terrain.water import find_water
    H = caldera()
    crop = refine_crop(H, 150.0, 0.0, seed=seed)
    dem = find_water(H, 0.0)
    assert len(dem.lakes) == 1
    water = find_water(crop.heights, 0.0, lake_levels=crop.lake_levels)
    wet = np.isfinite(water.level)
    assert wet.any() and np.all(water.level[wet] == dem.lakes[0][0])
    x = (np.arange(64) - 31.5) * 150.0
    rim = H[(lambda r: (r > 1300) & (r < 1500))(np.hypot(*np.meshgrid(x, x)))].min()
    assert water.level[wet].max() < rim - 200.0
    assert np.all(crop.heights[wet] < dem.lakes[0][0])
