"""Georeferenced DEMs (issue 22, item 1): GeoTIFF geotransform and CRS, ``.asc``, ``.npz``, ``--cell-size DX,DY``.

The GeoTIFFs are written here with tifffile and GeoKey tags (the OGC GeoTIFF
standard's ModelPixelScale, ModelTiepoint, ModelTransformation and GeoKeyDirectory),
in geographic (EPSG:4326, 1 arc-second cells at latitude 45) and projected (UTM 33N,
New York State Plane in US feet) CRSs, with no-data and heights in feet. The true
metres per cell come from the ellipsoid's radii of curvature (closed form, no pyproj),
and must match within 1 %.
"""

from __future__ import annotations

import math
import numpy as np
import pytest
import tifffile

# GeoKey ids (OGC 19-008r4, annex): model type, raster type, geographic / projected CRS, units.
MODEL, RASTER, GEOGRAPHIC, PROJECTED, LINEAR, VERTICAL = 1024, 1025, 2048, 3072, 3076, 4099
ARCSEC = 1.0 / 3600.0


def _geokeys(**keys):
    ids = {"model": MODEL, "raster": RASTER, "geographic": GEOGRAPHIC, "projected": PROJECTED, "linear": LINEAR,
           "vertical": VERTICAL}
    entries = sorted((ids[k], v) for k, v in keys.items())
    out = [1, 1, 0, len(entries)]
    for key, value in entries:
        out += [key, 0, 1, value]
    return (34735, "H", len(out), out)


def write_geotiff(path, heights, pixel, corner, nodata=None, transform=False, **keys):
    """A GeoTIFF with the pixel size and upper-left corner in CRS units, and GeoKeys."""
    sx, sy = pixel
    x0, y0 = corner
    tags = [_geokeys(**keys)]
    if transform:
        tags.append((34264, "d", 16, (sx, 0, 0, x0, 0, -sy, 0, y0, 0, 0, 0, 0, 0, 0, 0, 1)))
    else:
        tags += [(33550, "d", 3, (sx, sy, 0.0)), (33922, "d", 6, (0, 0, 0, x0, y0, 0))]
    if nodata is not None:
        tags.append((42113, "s", 0, str(nodata)))
    tifffile.imwrite(path, np.asarray(heights), extratags=tags)
    return path


def wgs84_metres(lat_deg, dlon_deg, dlat_deg):
    """Metres of ``dlon`` along the parallel and ``dlat`` along the meridian at ``lat`` (WGS 84)."""
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    s2 = math.sin(math.radians(lat_deg)) ** 2
    N = a / math.sqrt(1 - e2 * s2)  # prime vertical radius
    M = a * (1 - e2) / (1 - e2 * s2) ** 1.5  # meridian radius
    return N * math.cos(math.radians(lat_deg)) * math.radians(dlon_deg), M * math.radians(dlat_deg)


def _relief(ny, nx, seed=0):
    y, x = np.mgrid[0:ny, 0:nx]
    return (400.0 + 120.0 * np.sin(x / 9.0) * np.cos(y / 7.0) + 2.0 * y).astype(np.float32)


# -- reading ----------------------------------------------------------------------------------
def test_geographic_geotiff_cells_in_metres_within_one_percent(tmp_path):
    from arches_render.field.heightmaps import read_dem
    H = _relief(60, 80)
    H[3:6, 4:9] = -9999.0
    lat_top = 45.0 + 30 * ARCSEC  # the tile's centre at latitude 45
    path = write_geotiff(tmp_path / "geo.tif", H, (ARCSEC, ARCSEC), (7.25, lat_top), nodata=-9999,
                         model=2, raster=1, geographic=4326)
    dem = read_dem(path)
    true_dx, true_dy = wgs84_metres(45.0, ARCSEC, ARCSEC)
    assert abs(dem.cell[0] / true_dx - 1) < 0.01 and abs(dem.cell[1] / true_dy - 1) < 0.01, (dem.cell, true_dx, true_dy)
    assert 21.5 < dem.cell[0] < 22.3 and 30.6 < dem.cell[1] < 31.2  # about 21.9 and 30.9 m
    assert dem.georef.crs == "EPSG:4326" and dem.georef.geographic
    cx, cy = dem.georef.centre()
    assert abs(cx - (7.25 + 40 * ARCSEC)) < 1e-9 and abs(cy - 45.0) < 1e-9
    # Rows flipped: the file's last (southern) row is row 0, +y north.
    assert dem.heights[0, 20] == pytest.approx(float(H[-1, 20])) and dem.heights[-1, 20] == pytest.approx(float(H[0, 20]))
    assert dem.filled == 15 and np.all(dem.heights > 0)  # no-data filled, never -9999


def test_projected_utm_geotiff_with_heights_in_feet(tmp_path):
    from arches_render.field.heightmaps import read_dem
    H = _relief(40, 50)
    path = write_geotiff(tmp_path / "utm.tif", H, (10.0, 10.0), (500000.0, 5000400.0), model=1, raster=1,
                         projected=32633, vertical=9002)
    dem = read_dem(path)
    assert dem.cell == pytest.approx((10.0, 10.0))
    assert dem.georef.crs == "EPSG:32633" and "UTM zone 33N" in dem.georef.crs_name and not dem.georef.geographic
    # rel=1e-6: the converted heights are stored as float32 (7 significant digits).
    assert dem.heights[-1] == pytest.approx(0.3048 * H[0].astype(np.float64), rel=1e-6)
    assert any("feet converted to metres" in n for n in dem.notes), dem.notes
    assert dem.georef.centre() == pytest.approx((500250.0, 5000200.0))


def test_state_plane_in_us_feet_and_pixel_is_point_transformation(tmp_path):
    from arches_render.field.heightmaps import read_dem
    H = _relief(30, 30)
    # EPSG:2263 (NAD83 / New York Long Island, US survey feet); 10 ft cells; the tie is a pixel's centre.
    path = write_geotiff(tmp_path / "ny.tif", H, (10.0, 10.0), (980000.0, 200000.0), transform=True, model=1,
                         raster=2, projected=2263, vertical=9003)
    dem = read_dem(path)
    # 10 US survey feet = 3.0480061 m; rel=1e-5 is the 7 digits written here.
    assert dem.cell == pytest.approx((3.048006, 3.048006), rel=1e-5)
    assert dem.georef.corner == pytest.approx((979995.0, 200005.0))
    assert dem.heights[0, 0] == pytest.approx(float(H[-1, 0]) * 1200 / 3937, rel=1e-6)  # float32 heights


def test_esri_ascii_grid_with_no_data(tmp_path):
    from arches_render.field.heightmaps import read_dem
    H = _relief(12, 15).astype(np.float64)
    H[2, 3] = -9999
    head = "ncols 15\nnrows 12\nxllcorner 300000\nyllcorner 4000000\ncellsize 25\nNODATA_value -9999\n"
    (tmp_path / "g.asc").write_text(head + "\n".join(" ".join(f"{v:.3f}" for v in row) for row in H) + "\n")
    dem = read_dem(tmp_path / "g.asc")
    assert dem.cell == (25.0, 25.0) and dem.filled == 1
    assert dem.heights[-1, 0] == pytest.approx(H[0, 0], abs=1e-3)  # first row is the north
    assert dem.georef.corner == (300000.0, 4000000.0 + 12 * 25.0)


def test_npz_with_cell_size(tmp_path):
    from arches_render.field.heightmaps import read_dem
    np.savez(tmp_path / "d.npz", heights=_relief(20, 30), cell_size=np.array([5.0, 7.5]))
    dem = read_dem(tmp_path / "d.npz")
    assert dem.cell == (5.0, 7.5) and dem.georef is None and dem.heights.shape == (20, 30)


def test_square_cells_keep_the_extent_and_heights():
    from arches_render.field.dem_readers import square_cells
    y, x = np.mgrid[0:31, 0:21]
    H = 2.0 * x * 30.0 + 0.5 * y * 20.0  # a plane in metres: z = 2 X + 0.5 Y
    S, cell = square_cells(H, 30.0, 20.0)
    assert cell == 20.0 and S.shape == (31, 31)
    Y, X = np.mgrid[0:31, 0:31] * cell
    assert np.allclose(S, 2.0 * X + 0.5 * Y)


# -- amplify ----------------------------------------------------------------------------------
def _amplify(capsys, *args):
    from arches_render.cli import main
    capsys.readouterr()
    rc = main(["amplify", *map(str, args), "-q"])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def _header(path):
    return [line[2:] for line in path.read_text().splitlines() if line.startswith("# ")]


def test_amplify_geographic_geotiff_without_cell_size(tmp_path, capsys):
    H = _relief(40, 40)
    path = write_geotiff(tmp_path / "geo.tif", H, (ARCSEC, ARCSEC), (7.0, 45.0 + 20 * ARCSEC), nodata=-9999,
                         model=2, geographic=4326, vertical=9002)
    out = tmp_path / "geo.toml"
    rc, stdout, err = _amplify(capsys, path, "-o", out)
    assert rc == 0, err
    assert "resampled 40x40 cells of 21.9 x 30.87 m to 40x56 square cells of 21.9 m" in stdout, stdout
    head = _header(out)
    assert any(line.startswith("DEM: resampled 40x40 cells") for line in head), head
    geo = [line for line in head if line.startswith("Georeference: CRS EPSG:4326")]
    assert geo and "lat 45.0000000" in geo[0] and "lon 7.0055556" in geo[0], head
    assert np.load(tmp_path / "geo.heights.npy", allow_pickle=False).shape == (56, 40)
    import tomllib
    ext = tomllib.loads(out.read_text())["nodes"]["terrain"]["extent"]
    true_dx, true_dy = wgs84_metres(45.0, ARCSEC, ARCSEC)
    cell = (ext[2] - ext[0]) / 39
    assert abs(cell / true_dx - 1) < 0.01  # the square cell is the east-west one, in true metres
    assert abs((ext[3] - ext[1]) - 39 * true_dy) <= 0.5 * cell  # the north-south extent within half a cell
    # The override wins: square cells given, nothing resampled.
    rc, stdout, err = _amplify(capsys, path, "-o", tmp_path / "over.toml", "--cell-size", "30,30")
    assert rc == 0 and "resampled" not in stdout, stdout
    assert np.load(tmp_path / "over.heights.npy", allow_pickle=False).shape == (40, 40)


def test_amplify_reads_npz_cell_size_and_asc(tmp_path, capsys):
    np.savez(tmp_path / "d.npz", heights=_relief(30, 30), cell_size=np.array(12.0))
    rc, stdout, err = _amplify(capsys, tmp_path / "d.npz", "-o", tmp_path / "d.toml")
    assert rc == 0, err
    assert "heights 30x30 at 12 m" in stdout, stdout
    head = "ncols 30\nnrows 30\nxllcenter 0\nyllcenter 0\ncellsize 15\nNODATA_value -1\n"
    (tmp_path / "g.asc").write_text(head + "\n".join(" ".join(f"{v:.2f}" for v in row) for row in _relief(30, 30)))
    rc, stdout, err = _amplify(capsys, tmp_path / "g.asc", "-o", tmp_path / "g.toml", "--cell-size", "10,20")
    assert rc == 0, err
    assert "resampled 30x30 cells of 10 x 20 m to 30x59 square cells of 10 m" in stdout, stdout


@pytest.mark.parametrize("name, write, words", [
    ("rot.tif", lambda p: tifffile.imwrite(p, _relief(8, 8), extratags=[
        (34264, "d", 16, (1, 0.5, 0, 0, 0.5, -1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1)), _geokeys(model=1)]),
     ["rot.tif", "ModelTransformation", "north-up"]),
    ("zero.tif", lambda p: write_geotiff(p, _relief(8, 8), (0.0, 1.0), (0, 0), model=1),
     ["zero.tif", "ModelPixelScale", "> 0"]),
    ("bad.asc", lambda p: p.write_text("ncols 4\nnrows 4\nxllcorner 0\nyllcorner 0\n1 2 3 4\n"),
     ["bad.asc", "cellsize"]),
    ("short.asc", lambda p: p.write_text("ncols 4\nnrows 4\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3 4\n"),
     ["short.asc", "nrows 4"]),
    ("cell.npz", lambda p: np.savez(p, heights=_relief(8, 8), cell_size=np.array([-1.0])),
     ["cell.npz", "cell_size", "> 0"]),
])
def test_bad_georeferenced_inputs_exit_2_with_one_line(tmp_path, capsys, name, write, words):
    from robust_helpers import assert_one_line_error
    write(tmp_path / name)
    rc, _, err = _amplify(capsys, tmp_path / name, "-o", tmp_path / "x.toml")
    assert_one_line_error(rc, err, *words)
    assert not (tmp_path / "x.toml").exists()


@pytest.mark.parametrize("value", ["0", "1,2,3", "x,1", "nan", "-5,5"])
def test_bad_cell_size_exits_2_naming_the_option(tmp_path, capsys, value):
    from arches_render.cli import main
    np.save(tmp_path / "d.npy", _relief(8, 8))
    with pytest.raises(SystemExit) as stop:  # argparse's own exit
        main(["amplify", str(tmp_path / "d.npy"), "-o", str(tmp_path / "x.toml"), f"--cell-size={value}"])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and "--cell-size must be D or DX,DY" in err and "Traceback" not in err


# -- web elevation tiles ------------------------------------------------------------------------
def _encode(H, encoding):
    if encoding == "terrain-rgb":
        v = np.round((H + 10000.0) * 10.0).astype(np.int64)
        return np.stack([v // 65536, (v // 256) % 256, v % 256], axis=-1).astype(np.uint8)
    v = H + 32768.0
    r = np.floor(v / 256.0)
    g = np.floor(v - 256.0 * r)
    b = np.round((v - 256.0 * r - g) * 256.0)
    return np.stack([r, g, np.minimum(b, 255)], axis=-1).astype(np.uint8)


@pytest.mark.parametrize("encoding, tol", [("terrain-rgb", 0.051), ("terrarium", 1.0 / 256)])
def test_web_elevation_tiles_decode_to_metres(tmp_path, capsys, encoding, tol):
    import imageio.v3 as iio
    from arches_render.field.heightmaps import read_dem
    H = _relief(32, 32).astype(np.float64) - 450.0  # below and above sea level
    iio.imwrite(tmp_path / "tile.png", _encode(H, encoding))
    dem = read_dem(tmp_path / "tile.png", encoding=encoding)
    assert not dem.normalised and np.abs(dem.heights - H).max() <= tol
    # amplify needs the cell size of a tile, and reads it with it.
    from robust_helpers import assert_one_line_error
    rc, _, err = _amplify(capsys, tmp_path / "tile.png", "-o", tmp_path / "t.toml", "--encoding", encoding)
    assert_one_line_error(rc, err, "tile.png", "--encoding", "--cell-size")
    rc, stdout, err = _amplify(capsys, tmp_path / "tile.png", "-o", tmp_path / "t.toml", "--encoding", encoding,
                               "--cell-size", 20, "--preset", "river")
    assert rc == 0 and "heights 32x32 at 20 m" in stdout, err + stdout
    assert float(np.load(tmp_path / "t.heights.npy", allow_pickle=False).min()) == pytest.approx(float(H.min()), abs=0.06)


def test_a_dem_without_a_cell_size_and_needle_slopes_says_so(tmp_path, capsys):
    # A .npy says nothing of its cell: 1 m is assumed. Hills 100 m high and 600 m apart
    # at 20 m cells read so have slopes of 80 deg and more (a 2.4 km DEM read so rendered
    # as needles): the user hears, with the option to give.
    x = np.arange(32.0)
    X, Y = np.meshgrid(x, x)
    np.save(tmp_path / "v.npy", (300.0 + 50.0 * np.sin(X / 5.0) * np.cos(Y / 4.0)).astype(np.float32))
    for cell, noted in ((None, True), ("20", False)):
        out = tmp_path / f"v{cell}.toml"
        rc, stdout, err = _amplify(capsys, tmp_path / "v.npy", "-o", out, "--preset", "strata", "--no-refine",
                                   *(("--cell-size", cell) if cell else ()))
        assert rc == 0, err
        said = [line for line in stdout.splitlines() if "gives no cell size" in line]
        assert len(said) == noted and (not noted or "--cell-size" in said[0]), stdout
