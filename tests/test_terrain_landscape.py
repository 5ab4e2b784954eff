"""Landscapes from DEMs (issue 14): ``auto`` preset and water, DEM reduction notes, far field, shots.

Small synthetic DEMs (a few thousand cells), ``amplify`` run in this process, and
renders of 64x36 pixels at 2 spp (one scene per landscape, its camera moved between
shots) keep these cheap; each check can fail (a flooded inland valley, a black coastal
render, a pixel below the horizon that sees the sky's lower hemisphere, a hit on the
wall of the field's prism, a camera in rock).
"""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from helpers import REPO, variant
from robust_helpers import cli_out


def _amplify(capsys, *args):
    """``arches-render amplify ARGS -q`` in this process: ``(status, stdout, stderr)``."""
    return cli_out(capsys, "amplify", *args, "-q")


def _header(path):
    return [line[2:] for line in path.read_text().splitlines() if line.startswith("# ")]


def _valley(n=48, base=600.0):
    """An inland canyon (walls of about 50 deg at 30 m cells) draining to one edge, far above sea level."""
    x = np.linspace(-1, 1, n)
    X, Y = np.meshgrid(x, x)
    return (base + 200.0 * np.clip((np.abs(X - 0.25 * np.sin(2.5 * Y)) - 0.1) / 0.15, 0, 1) ** 1.5
            + 40.0 * (Y + 1)).astype(np.float32)


def _coast(n=40):
    """Land rising from a sea floor that reaches the southern edge."""
    x = np.linspace(-1, 1, n)
    X, Y = np.meshgrid(x, x)
    return (-400.0 + 1400.0 * np.clip((Y + 0.4) / 1.2, 0, 1) + 150.0 * np.sin(3 * X) * (Y > -0.2)).astype(np.float32)


def test_auto_inland_dem_no_sea_no_void_no_walls(tmp_path, capsys):
    variant()
    from arches_render.scene import load_scene
    np.save(tmp_path / "inland.npy", _valley())
    out = tmp_path / "inland.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "inland.npy", "-o", out, "--cell-size", "30")
    assert rc == 0, err
    assert "preset " in stdout and "preset sea" not in stdout, stdout
    head = _header(out)
    assert any(line.startswith("Preset ") and not line.startswith("Preset sea") for line in head), head
    assert any(line.startswith("Landform sizes (m):") for line in head), head
    text = out.read_text()
    assert "sea_level" not in text  # no sea ring, no sea in the material
    desc = load_scene(out)
    assert len(desc.cameras) >= 2 and "overview" in desc.cameras
    # The valley floor is dry: no water mesh at all (no lake in a valley that drains).
    assert not (tmp_path / "inland.water.ply").exists()
    # Every shot: sky above, ground (the far field past the tile) to the horizon, no prism wall.
    _check_shots(desc, _render_all_cameras(desc))


def test_auto_coast_gets_sea_reaching_the_horizon(tmp_path, capsys):
    variant()
    from arches_render.scene import load_scene
    np.save(tmp_path / "coast.npy", _coast())
    out = tmp_path / "coast.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "coast.npy", "-o", out, "--cell-size", "50")
    assert rc == 0, err
    assert "preset sea" in stdout, stdout
    head = "\n".join(_header(out))
    assert "Preset sea:" in head and "reaching the border" in head, head
    text = out.read_text()
    assert "[[far_field]]" in text and "sea_level = 0.0" in text
    # The sea cliffs' rock texture follows the cliffs the header measured (a fifth, 6-30 m).
    import re
    import tomllib
    cliff = float(re.search(r"cliff_height ([\d.e+]+)", head).group(1))
    rock = tomllib.loads(text)["materials"]["landscape"]["overrides"]["rock.scale"]
    # rel 1e-2: the header prints the cliff height to three significant digits (a rounding
    # of at most 0.5 %); the scene's value comes from the unrounded height.
    assert rock == pytest.approx(min(max(0.2 * cliff, 6.0), 30.0), rel=1e-2), (rock, cliff)
    # The sea mirrors the sky (a dielectric coat, not a diffuse paint lit pale by the sun),
    # and the preview rolls the sky's highlights off (ACES's view, not a clip).
    doc = tomllib.loads(text)
    water = doc["materials"][doc["far_field"][0]["water_material"]]
    assert water["type"] == "glossy" and water["ior"] == pytest.approx(1.333), water
    assert doc["render"]["view"] == "aces"
    # Rendered: no pixel below the horizon sees past the sea, no prism wall (the close shots face
    # the cliffs from the water: their top rows may be rock).
    desc = load_scene(out)
    _check_shots(desc, _render_all_cameras(desc), sky_above=False)
    # --sea-level overrides: far below the floor there is no sea, and auto picks another preset.
    out2 = tmp_path / "dry.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "coast.npy", "-o", out2, "--cell-size", "50", "--sea-level", "-1000")
    assert rc == 0 and "preset sea" not in stdout, stdout


def test_dem_reduction_is_printed_and_written_in_the_header(tmp_path, capsys):
    np.save(tmp_path / "big.npy", _valley(64))
    out = tmp_path / "big.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "big.npy", "-o", out, "--max-cells", "1024", "--preset", "strata")
    assert rc == 0, err
    lines = [line for line in stdout.splitlines() if "reduced 64x64" in line]
    assert len(lines) == 1 and "--max-cells" in lines[0], stdout
    assert any("reduced 64x64 samples to 32x32" in line for line in _header(out))


def test_default_keeps_8192_squared(tmp_path):
    from arches_render.generators.terrain.command import MAX_CELLS
    from arches_render.field.heightmaps import read_dem
    assert MAX_CELLS >= 8192 ** 2
    # The reader itself reduces only beyond the limit it is given (a memory map: no full read).
    np.save(tmp_path / "d.npy", np.zeros((40, 30), np.float32))
    assert read_dem(tmp_path / "d.npy", max_samples=1200).step == 1
    assert read_dem(tmp_path / "d.npy", max_samples=1199).step == 2


@pytest.mark.parametrize("content,message", [
    ("inf", "no valid height"), ("strip", "at most 64 times"), ("huge", "heights reach"),
    ("text", "not real numbers")])
def test_amplify_more_bad_dems_exit_2_with_one_line(tmp_path, capsys, content, message):
    path = tmp_path / "dem.npy"
    if content == "inf":
        np.save(path, np.full((8, 8), np.inf))
    elif content == "strip":
        np.save(path, np.zeros((3, 5000), np.float32))
    elif content == "huge":
        np.save(path, np.full((8, 8), 1e30))
    elif content == "text":
        np.save(path, np.array([["a", "b"], ["c", "d"]]))
    rc, _, err = _amplify(capsys, path, "-o", tmp_path / "s.toml")
    assert rc == 2 and message in err, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "s.toml").exists()


def _check_shots(desc, shots, sky_above=True):
    """Lit, no prism wall, no void below the horizon, cameras in air; sky above the close shots.

    A void is a pixel whose whole footprint looks down (``shot_report``'s
    below-horizon pixels) with a sample that hit nothing: it sees the sky's lower
    hemisphere, past the far field's edge or through a thin slab the tracer missed.
    The overview, which looks down on the whole tile, must have pixels below the
    horizon, so the void check is never empty.
    """
    from arches_render.field import evaluate
    assert shots["overview"][1]["below_horizon_pixels"] > 0, shots["overview"][1]
    for name, (rgb, rep) in shots.items():
        assert np.isfinite(rgb).all(), name
        assert rgb.mean() > 0.02, (name, float(rgb.mean()))
        assert rep["below_horizon_misses"] == 0.0, (name, "void below the horizon", rep)
        assert rep["wall_hits"] == 0.0, (name, rep)
        assert rep["unresolved_camera_rays"] == 0, (name, "camera rays used up both step budgets", rep)
        # The overview too: a photographer's, with the horizon in the frame and the tile,
        # not the far field around it, as most of the ground it shows (issue 34).
        if sky_above or name == "overview":
            assert rep["top_sky"] > 0.5, (name, rep)
        if name == "overview":
            assert rep["tile_share"] > 0.5, (name, rep)
        origin = np.asarray(desc.cameras[name].origin, float)[None]
        assert float(evaluate(desc.field, origin)[0]) < 0.0, f"{name}: camera inside matter"


def _render_all_cameras(desc, width=64, height=36, spp=2):
    """``{camera: (beauty, shot_report)}`` of every camera of ``desc``; the report also
    counts the camera rays that used up both of the tracer's step budgets (issue 21)."""
    from landscape_helpers import render_shots, shot_report
    out = {}
    for name, (rgb, layers) in render_shots(desc, width, height, spp).items():
        rep = shot_report(desc, layers, desc.cameras[name], width, height)
        arr, letters = layers["unresolved"]
        rep["unresolved_camera_rays"] = int(round(float(arr[..., letters.index("primary")].sum()) * spp))
        out[name] = (rgb, rep)
    return out


def test_coastal_dem_of_hundreds_of_km_renders_a_landscape(tmp_path, capsys):
    """The Salish Sea DEM (290 x 219 km, here at 4870 m cells): not black, sky above, no void below the horizon
    (in the close shots too: the tracer once missed thin carved slabs there), no camera ray unresolved."""
    variant()
    from arches_render.scene import load_scene
    out = tmp_path / "salish.toml"
    # The whole DEM (--no-refine; refined by default, it is a crop: tests/test_refined_crop.py).
    rc, stdout, err = _amplify(capsys, REPO / "scenes" / "data" / "real_salish_sea_2435m.npy", "-o", out,
                               "--cell-size", "2435", "--max-cells", "3000", "--no-refine")
    assert rc == 0, err
    assert "preset sea" in stdout
    desc = load_scene(out)
    # The air thinned to the tile's scale (the default air's ~20 km range was a fog bank
    # over the overview): its meteorological range is HAZE_WIDTHS tile widths (the
    # overview looks across the whole tile, low).
    import tomllib
    from arches_render.generators.terrain.scene_writer import HAZE_RANGE_M, HAZE_WIDTHS
    x0, y0, x1, y1 = tomllib.loads(out.read_text())["nodes"]["terrain"]["extent"]
    width = max(x1 - x0, y1 - y0)
    range_m = HAZE_WIDTHS * width
    assert width > 200e3 and abs(desc.atmosphere.density * range_m - HAZE_RANGE_M) < 0.01 * HAZE_RANGE_M
    _check_shots(desc, _render_all_cameras(desc))


def test_lakes_stand_where_their_catchment_fills_them_and_no_flooded_canyon_floor():
    from arches_render.generators.terrain.hydrology import fill_depressions
    from arches_render.generators.terrain.water import LAKE_CATCHMENT_SHARE, descent_sinks, find_water
    x = np.linspace(-1, 1, 64)
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X, Y)
    # A closed crater with a rim on a gently tilted plain drains little more than its
    # own bowl: its lake covers at most LAKE_CATCHMENT_SHARE of the cells draining into
    # it, on the crater's floor, far below the rim's lowest point (it used to fill to
    # that point: a caldera drowned to its brim).
    H = 100.0 + 10.0 * X + 40.0 * np.exp(-((r - 0.3) / 0.08) ** 2) - 30.0 * (r < 0.25)
    w = find_water(H, 0.0)
    assert w.sea_level is None and len(w.lakes) == 1, w.lakes
    level, cells = w.lakes[0]
    wet = np.isfinite(w.level)
    assert cells == wet.sum() and np.all(w.level[wet] == level) and np.all(H[wet] < level)
    drains_in = np.isin(descent_sinks(H), np.flatnonzero(wet)).sum()
    assert drains_in > 1.5 * cells and cells <= LAKE_CATCHMENT_SHARE * drains_in, (cells, drains_in)
    floor = r < 0.25
    assert wet[floor].mean() > 0.3 and not wet[~floor].any()
    ring = (r > 0.28) & (r < 0.32)
    assert level < H[ring].min() - 20.0
    # A valley dammed across its lower end drains the whole valley into the lake behind
    # the dam, far more than the lake: it fills to the dam's lowest point and spills.
    V = 50.0 * np.abs(X) + 30.0 * Y + 25.0 * np.exp(-((Y + 0.6) / 0.05) ** 2)
    w = find_water(V, None)
    assert len(w.lakes) == 1, w.lakes
    wet = np.isfinite(w.level)
    assert w.lakes[0][0] == fill_depressions(V)[wet].max() and np.all(Y[wet] > -0.6)
    # The flat floor of the real canyon has resampling pits of 1-4 m: no lake there.
    canyon = np.load(REPO / "scenes" / "data" / "real_nm_canyon_10m.npy", allow_pickle=False)
    assert find_water(canyon, 0.0).lakes == []


def test_descent_sinks_follow_the_steepest_drop_to_its_pit():
    from arches_render.generators.terrain.water import descent_sinks
    # Two bowls side by side: every cell ends in the pit of its own bowl; a flat cell
    # (no lower neighbour) is its own end.
    H = np.array([[5.0, 4.0, 5.0, 6.0, 4.0, 4.0],
                  [4.0, 1.0, 4.0, 6.0, 3.0, 2.0],
                  [5.0, 4.0, 5.0, 6.0, 4.0, 4.0]])
    sinks = descent_sinks(H)
    left, right = np.ravel_multi_index((1, 1), H.shape), np.ravel_multi_index((1, 5), H.shape)
    assert np.all(sinks[:, :3] == left) and np.all(sinks[:, 4:] == right), sinks
    # The ridge column drains down its steeper side, into the right bowl.
    assert np.all(sinks[:, 3] == right), sinks
    flat = np.full((4, 4), 3.0)
    assert np.array_equal(descent_sinks(flat), np.arange(16).reshape(4, 4))


def test_water_quads_cover_each_wet_cell_once_at_its_level_in_maximal_runs():
    from arches_render.generators.terrain.water import WaterBodies, water_mesh
    rng = np.random.default_rng(3)
    ny, nx = 40, 57
    level = np.where(rng.random((ny, nx)) < 0.5, rng.choice([2.0, 5.0], (ny, nx)), np.nan)
    level[7] = np.nan  # a dry row of samples
    w = WaterBodies(level, np.zeros((ny, nx), bool), None, [(5.0, 1)])
    dx, dy = 1.5, 2.0
    m = water_mesh(w, (10.0, -4.0, 10.0 + dx * (nx - 1), -4.0 + dy * (ny - 1)))
    # Expected cell levels: a cell is water at its highest wet corner, after the lakes'
    # one-cell growth (water_mesh's own rule, restated on the samples).
    lev = np.where(np.isfinite(level), level, -np.inf)
    from scipy import ndimage
    grown = np.where(np.isfinite(level), lev, ndimage.grey_dilation(lev, size=(3, 3)))
    corners = np.stack([grown[:-1, :-1], grown[:-1, 1:], grown[1:, :-1], grown[1:, 1:]]).max(axis=0)
    got = np.full(corners.shape, -np.inf)
    V, F = m.vertices, m.faces.reshape(-1, 2, 3)
    assert np.all(F[:, 1] - F[:, 0] == [0, 1, 1])  # two triangles a quad
    for quad in F[:, 0]:
        (xa, ya, z), (xb, _, _), (_, yb, _) = V[quad]
        k0, k1 = int(round((xa - 10.0) / dx)), int(round((xb - 10.0) / dx))
        j = int(round((ya + 4.0) / dy))
        assert round((yb + 4.0) / dy) == j + 1 and k1 > k0
        assert np.all(np.isneginf(got[j, k0:k1])), "a cell covered twice"
        got[j, k0:k1] = z
        # Maximal: the cells on either side are dry or at another level.
        for k in (k0 - 1, k1):
            if 0 <= k < nx - 1:
                assert corners[j, k] != z
    np.testing.assert_array_equal(got, corners)


def _escarpment(n=64):
    """A plateau 900 m above its lowland behind a winding escarpment (200 m cells: coarse)."""
    x = np.linspace(-1, 1, n)
    X, Y = np.meshgrid(x, x)
    return (300 + 900 / (1 + np.exp(-(Y - 0.2 * np.sin(3 * X)) * 12))
            + 30 * np.sin(5 * X) * np.cos(4 * Y)).astype(np.float32)


def _assert_legible_close_shots(out, at_least=3):
    """The header's legibility of every close shot (sky share, background share, one-sheet
    share, the landform's contrast) within shots.LEGIBLE, at least ``at_least`` of them,
    and the overview last."""
    import re
    from arches_render.generators.terrain.shots import LEGIBLE
    cams = next(line for line in _header(out) if line.startswith("Cameras: "))
    found = re.findall(r"legible: sky (\d+) %, background (\d+) %, one sheet (\d+) %, contrast (\d+) %", cams)
    assert len(found) >= at_least and cams.rstrip().endswith("overview"), cams
    for sky, background, sheet, contrast in found:
        # (the header rounds to a percent)
        assert float(sky) >= 100 * LEGIBLE["sky"] - 0.5, cams
        assert float(background) >= 100 * LEGIBLE["background"] - 0.5, cams
        assert float(sheet) <= 100 * LEGIBLE["one_surface"] + 0.5, cams
        assert float(contrast) >= 100 * LEGIBLE["contrast"] - 0.5, cams


def test_escarpment_at_coarse_cells_gets_legible_close_shots(tmp_path, capsys):
    """An escarpment plateau at 200 m cells: four cameras, and the header's legibility of
    every close shot (sky share, background share, one-sheet share) within shots.LEGIBLE."""
    np.save(tmp_path / "esc.npy", _escarpment())
    out = tmp_path / "esc.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "esc.npy", "-o", out, "--cell-size", "200", "--seed", "3")
    assert rc == 0, err
    _assert_legible_close_shots(out)


def test_caldera_gets_cliffs_in_its_walls_and_a_lake_on_its_floor(tmp_path, capsys):
    """A caldera (issue 34's kinds of DEM): its walls are a small share of the tile, but
    ``auto`` carves layered cliffs in them (the river default found no valley there and
    made a few blobs), its lake lies on the floor far below the rim (it filled the
    caldera to the brim: a flat disc), and its cameras are legible, lit and void-free."""
    variant()
    import trimesh
    from arches_render.scene import load_scene
    from synthetic_dems import caldera
    H = caldera()
    np.save(tmp_path / "caldera.npy", H)
    out = tmp_path / "caldera.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "caldera.npy", "-o", out, "--cell-size", "150", "--seed", "5")
    assert rc == 0, err
    assert "preset strata (strata: walls without flat tops" in stdout, stdout
    _assert_legible_close_shots(out)
    x = (np.arange(64) - 31.5) * 150.0
    r = np.hypot(*np.meshgrid(x, x))
    water = trimesh.load(next(tmp_path.glob("caldera*.water.ply")), process=False)
    assert water.vertices[:, 2].max() < H[(r > 1300) & (r < 1500)].min() - 200.0
    desc = load_scene(out)
    # The far field reads no node of the tile's fallen blocks: their bare-rock masks read
    # bare rock all over it (the tile's edge showed as a ring of banded relief).
    doc = tomllib.loads(out.read_text())
    tile, far = doc["materials"]["landscape"], doc["materials"][doc["far_field"][0]["material"]]
    assert "masks" in tile and "node" in tile["cavity"]
    assert "masks" not in far and "cavity" not in far and "blocks" not in far["strata"]
    assert far["overrides"] == tile["overrides"] and far["strata"]["levels"] == tile["strata"]["levels"]
    # Cameras below the walls do not look up at them past PITCH half fields, so the floor
    # stays in the frame (the first looked up 33 degrees, over two half fields, before);
    # 1e-6 rad: the camera's numbers as the TOML writes and reads them.
    from arches_render.generators.terrain.shots import PITCH
    for name, cam in desc.cameras.items():
        if name == "overview":
            continue
        d = np.asarray(cam.target, float) - np.asarray(cam.origin, float)
        vfov2 = math.atan(math.tan(math.radians(cam.fov) / 2) * 9 / 16)
        assert abs(math.atan2(d[2], math.hypot(d[0], d[1]))) <= PITCH * vfov2 + 1e-6, name
    _check_shots(desc, _render_all_cameras(desc))


@pytest.mark.parametrize("dem, cell, extra", [
    ("real_aletsch_200m", "200", []), ("real_maunga_whau_10m", "10", []),
    # (halved, block-averaged as --max-cells does for any large DEM: 35 s -> 24 s)
    ("real_devils_slide_25m", "25", ["--max-cells", str(256 ** 2)])])
def test_mountains_and_a_volcanic_cone_amplify_into_landscapes(tmp_path, capsys, dem, cell, extra):
    """Issue 34's further real DEMs (scenes/data/DEMS.md): high mountains at 200 m cells, a
    volcanic cone with its crater at 10 m, and a cliffed coast whose sea is SRTM's flat
    0 m. Exit 0 with ``auto``; four cameras or more; every close shot shows landforms
    (header: at least 1 % of the frame) under sky; lit, no void, no prism wall, no camera
    ray unresolved, no camera in rock."""
    import re
    variant()
    from arches_render.scene import load_scene
    out = tmp_path / f"{dem}.toml"
    rc, stdout, err = _amplify(capsys, REPO / "scenes" / "data" / f"{dem}.npy", "-o", out, "--cell-size", cell,
                               *extra)
    assert rc == 0, err
    desc = load_scene(out)
    assert len(desc.cameras) >= 4 and list(desc.cameras)[-1] == "overview", list(desc.cameras)
    cams = next(line for line in _header(out) if line.startswith("Cameras: "))
    covers = [float(c) for c in re.findall(r"covers (\d+) % of the frame", cams)]
    assert len(covers) >= 3 and min(covers) >= 1.0, cams
    if dem == "real_aletsch_200m":  # high mountains: grey rock, snow on the top quarter of the relief
        import tomllib
        doc = tomllib.loads(out.read_text())
        look = doc["materials"]["landscape"]
        # Refined (the default at 200 m), the layers follow the region around the crop:
        # the DEM as its far field reads it (the spline's context, which overshoots the
        # DEM's samples by metres), else the DEM.
        context = doc["far_field"][0].get("context")
        H = np.load(tmp_path / context["file"] if context else REPO / "scenes" / "data" / f"{dem}.npy",
                    allow_pickle=False)
        relief = float(H.max() - H.min())
        assert look["strata"]["palette"] == "limestone", look["strata"]
        assert abs(look["overrides"]["snow.height_min"] - (float(H.max()) - 0.25 * relief)) < 1.0, look["overrides"]
    if dem == "real_maunga_whau_10m":  # whole metres: the terraces are smoothed away, within half a metre
        assert any("heights on a 1 m lattice" in line for line in _header(out)), _header(out)
        H = np.load(REPO / "scenes" / "data" / f"{dem}.npy", allow_pickle=False).astype(np.float64)
        Z = np.load(next(tmp_path.rglob("*heights.npy")), allow_pickle=False).astype(np.float64)
        assert np.abs(Z - H).max() <= 0.5 + 1e-4
        assert np.mean(np.diff(H, axis=1) == 0) > 0.2 and np.mean(np.abs(np.diff(Z, axis=1)) < 1e-3) < 0.1
    if dem == "real_devils_slide_25m":  # the sea keeps its cliffs: a floor is laid under the 0 m sheet
        header = _header(out)
        assert any(line.startswith("Preset sea:") for line in header), header
        assert any("the sea is a flat sheet at 0 m" in line for line in header), header
        Z = np.load(next(tmp_path.rglob("*heights.npy")), allow_pickle=False)
        assert 0.3 < np.mean(Z < -1.9) < 0.5       # the Pacific, all under water
    _check_shots(desc, _render_all_cameras(desc))


def test_snow_and_rock_follow_the_lands_rise_not_the_sea_floor():
    from arches_render.generators.terrain.scene_writer import ALPINE_RELIEF, SNOW_RELIEF, landscape_material
    snow = lambda *a: landscape_material(*a)["overrides"]["snow.height_min"]  # noqa: E731
    assert snow(-2000.0, 300.0, 0.0) > 300.0           # a 300 m island over a deep sea: no snow
    assert snow(-100.0, 450.0, 0.0) > 450.0            # a coastal range: none either
    assert snow(1198.0, 1529.0) > 1529.0               # nor desert mesas 330 m high (white caprock)
    assert snow(-100.0, 1200.0, 0.0) == 1200.0 - 0.05 * 1200.0  # a mountain range: its top 5 %
    assert snow(502.0, 4216.0) == 4216.0 - 0.25 * 3714.0     # high mountains: the top quarter
    assert snow(-1437.0, 2205.0, 0.0) == 2205.0 - 0.25 * 2205.0  # mountains behind a deep sea
    assert ALPINE_RELIEF == 1500.0 and SNOW_RELIEF == 1000.0



def test_grass_covers_flat_tops_and_leaves_rims_and_peaks_bare():
    """Flat-topped relief without snow (mesas, canyon plateaus) gets grass to its top: bare,
    its caprock crossed its beds in camouflage blotches; a cone's rim, ridges and snowy
    mountains keep bare rock above three quarters of their relief."""
    from arches_render.generators.terrain.scene_writer import flat_topped, landscape_material
    grass = lambda *a, **k: landscape_material(*a, **k)["overrides"]["grass.height_max"]  # noqa: E731
    assert grass(1198.0, 1529.0, flat_top=True) > 1529.0
    assert grass(1198.0, 1529.0) == 1198.0 + 0.75 * 331.0
    assert grass(-100.0, 1200.0, 0.0, flat_top=True) == -100.0 + 0.75 * 1300.0  # snow caps it
    x = np.arange(0.0, 3000.0, 20.0)
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X - 1500.0, Y - 1500.0)
    mesa = 1200.0 + 300.0 * np.clip((900.0 - r) / 60.0, 0.0, 1.0)   # flat top, steep sides
    cone = 1200.0 + 300.0 * np.clip(1.0 - r / 900.0, 0.0, 1.0)      # 18 degree flanks
    assert flat_topped(mesa, 20.0) and not flat_topped(cone, 20.0)


def test_rock_texture_of_sea_cliffs_grows_with_them():
    """On the sea preset the rock texture's tile is a fifth of the DEM's cliff height,
    within 6-30 m: sea cliffs 98 m high get 19.6 m (the preset's 6 m drew a dry-stone wall
    of cobbles on them), low and very high ones are held to the range, no cliff keeps the
    preset's tile, and so do the other presets (shot from farther, where it averages out)."""
    from arches_render.generators.terrain.scene_writer import landscape_material

    def tile(h, preset="sea"):
        return landscape_material(0.0, 500.0, 0.0, preset=preset, cliff_height=h)["overrides"].get("rock.scale")

    assert tile(98.0) == pytest.approx(19.6) and tile(80.0) == pytest.approx(16.0)
    assert tile(23.4) == 6.0 and tile(608.0) == 30.0
    assert tile(None) is None and tile(0.0) is None
    assert all(tile(98.0, p) is None for p in ("river", "karst", "hoodoos", "strata"))


def test_scree_covers_gentle_ground_above_the_grass_in_the_rocks_mean_colour():
    """Above the grass, gentle ground is scree of the rock's own beds mixed (the sand layer
    to the snow line, in the strata palette's mean colour): a volcano's bare upper flanks
    showed its horizontal beds as a bullseye of rings. Flat-topped relief (grass to the
    top) and high mountains (snow from the grass line up) have no bare band to cover."""
    variant()
    from arches_render.generators.terrain import geology as G
    from arches_render.generators.terrain.scene_writer import landscape_material
    from arches_render.materials.masks import PALETTES
    from arches_render.materials.presets import preset_layers
    rock = G.Blend(G.Strata(20.0, 5.0, 0.6), G.Turbulence(60.0, 0.2))

    def look(zlo, zhi, sea=None, **kw):
        box = (np.array([0.0, 0.0, zlo]), np.array([3000.0, 3000.0, zhi]))
        return landscape_material(zlo, zhi, sea, rock, box, preset="strata", **kw)["overrides"]

    cone, snowy = look(1200.0, 1500.0), look(-100.0, 1200.0, 0.0)
    mean = np.mean(PALETTES["sandstone"], axis=0)
    for over in (cone, snowy):
        assert over["sand.height_max"] == over["snow.height_min"] > over["grass.height_max"]
        # (the writer rounds the tint to 4 decimals for the TOML: within 5e-5 of the mean)
        assert np.allclose(over["sand.tint"], mean, atol=1e-4)
    assert cone["snow.height_min"] > 1500.0 and snowy["snow.height_min"] == 1200.0 - 0.05 * 1200.0
    for over in (look(1198.0, 1529.0, flat_top=True), look(502.0, 4216.0)):
        assert "sand.tint" not in over and over["sand.height_max"] < over["grass.height_max"]
    # Gentle ground only: the beds still show where the rock stands steep.
    layers = {layer.name: layer for layer in preset_layers("terrain", cone)[0]}
    assert layers["sand"].slope_max + layers["sand"].slope_soft <= 30.0


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int32])
def test_label_extrema_are_scipys(dtype):
    """``hydrology.label_extrema``: per label the same minima and maxima as
    ``scipy.ndimage.minimum`` / ``maximum`` (the same numbers and dtype), labels from
    ``ndimage.label`` and from a dilation of them (as ``_cliff_height`` uses)."""
    from scipy import ndimage

    from arches_render.generators.terrain.hydrology import label_extrema
    rng = np.random.default_rng(3)
    values = (rng.normal(0, 100, (300, 200)) * (1 if dtype != np.int32 else 1)).astype(dtype)
    lab, n = ndimage.label(rng.random((300, 200)) < 0.3)
    for labels in (lab, ndimage.grey_dilation(lab, size=(1, 3))):
        lo, hi = label_extrema(values, labels, n)
        idx = np.arange(1, n + 1)
        want_lo = np.asarray(ndimage.minimum(values, labels, idx))
        want_hi = np.asarray(ndimage.maximum(values, labels, idx))
        assert lo.dtype == (np.float64 if dtype == np.int32 else dtype)
        np.testing.assert_array_equal(lo, want_lo.astype(lo.dtype))
        np.testing.assert_array_equal(hi, want_hi.astype(hi.dtype))

