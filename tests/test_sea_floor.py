"""Seas stored as a flat sheet at the sea level (SRTM: the ocean is 0 m) get a sea floor
before amplification (issue 34): the water covers them and the coast is measured."""
from __future__ import annotations

import numpy as np

from helpers import REPO, variant

variant()

from arches_render.generators.terrain.amplify import amplify  # noqa: E402
from arches_render.generators.terrain.preset_choice import landform_scales  # noqa: E402
from arches_render.generators.terrain.sea_floor import (  # noqa: E402
    DEPTH_AT_SHORE, SLOPE, flat_sea, lay_sea_floor)

CELL = 8.0


def _srtm_coast(n=384, cliff=80.0):
    """Whole metres, the west 40 % of the tile a flat 0 m sheet; cliffs ``cliff`` m tall
    rise within two cells of a wavy shore, hills behind; a 0 m lagoon inland."""
    x = np.arange(n) * CELL
    X, Y = np.meshgrid(x, x)
    shore = 0.4 * n * CELL + 60.0 * np.sin(Y / 300.0)
    d = X - shore
    land = cliff * np.clip(d / (2 * CELL), 0, 1) + 0.05 * np.clip(d, 0, None) + 20 * np.sin(Y / 170.0) ** 2
    H = np.where(d > 0, np.maximum(np.rint(land), 1.0), 0.0)
    H[240:250, 300:310] = 0.0                   # a lagoon at 0 m, not the sea
    return H.astype(np.float32)


def test_flat_sheet_found_and_floored_land_and_lagoon_left_alone():
    H = _srtm_coast()
    sheet = flat_sea(H, 0.0)
    assert sheet is not None and 0.35 < sheet.mean() < 0.45
    assert not sheet[240:250, 300:310].any()    # the lagoon is not connected to the border
    out, deepest = lay_sea_floor(H, sheet, CELL, 0.0)
    assert np.array_equal(out[~sheet], H[~sheet].astype(np.float64))
    assert np.all(out[sheet] <= -DEPTH_AT_SHORE - SLOPE * CELL + 1e-9)   # a cell out: deeper than at the shore
    # Deeper away from the shore, up to the cap (a fifth of the land's relief).
    row = out[40, :100]
    assert np.all(np.diff(row[::-1]) <= 1e-9) and deepest <= 0.2 * float(H.max()) + 1e-9
    # No sheet: a DEM with bathymetry, a sheet under 1 % of the tile, no sea level.
    coast = np.load(REPO / "scenes" / "data" / "eroded_coast.npy", allow_pickle=False)
    assert flat_sea(coast, 0.0) is None
    small = H.copy()
    small[:, :] = np.maximum(small, 1.0)
    small[:5, :5] = 0.0
    assert flat_sea(small, 0.0) is None and flat_sea(H, None) is None


def test_srtm_coast_keeps_its_sea_and_cliffs_and_says_so(tmp_path):
    H = _srtm_coast()
    # On the sheet, the analysis grid (256 samples across: this DEM is smoothed) smears
    # the land into the flat sea, and the coast reads low.
    sheet = flat_sea(H, 0.0)
    floored, _ = lay_sea_floor(H, sheet, CELL, 0.0)
    before = landform_scales(H, CELL, "sea", 0.0)["coast_cliff_m"]
    after = landform_scales(floored, CELL, "sea", 0.0)["coast_cliff_m"]
    assert after > max(2 * before, 40.0), (before, after)
    res = amplify(H, CELL, "sea", 2, tmp_path)
    assert res.scales["coast_cliff_m"] > 40.0 and res.stats["primitives"] > 100
    assert any(n.startswith("the sea is a flat sheet at 0 m on ") for n in res.stats["notes"])
    assert np.all(res.heights[sheet] < -DEPTH_AT_SHORE + 1e-6)          # every sheet cell under water
    assert np.all(np.abs(res.heights[~sheet] - H[~sheet]) <= 0.5 + 1e-6)  # land: dequantized only
