"""Georeferenced DEMs: cell sizes in metres, vertical units and the map position, from the file.

Real elevation data say where they are and how large their cells are; a user should
not have to know it (issue 22). :func:`~.heightmaps.read_dem` calls the readers here
for what the plain array readers cannot tell:

GeoTIFF (``.tif``)
    Read with tifffile, whose ``geotiff_tags`` decodes the GeoKey directory:
    ``ModelPixelScale`` + ``ModelTiepoint`` (or a ``ModelTransformation`` without
    rotation) give the upper-left corner and the pixel size in CRS units;
    ``ProjectedCSTypeGeoKey`` / ``GeographicTypeGeoKey`` the CRS (an EPSG code);
    ``VerticalUnitsGeoKey`` the unit of the heights (feet are converted to metres).
    Chosen over rasterio: tifffile is already a dependency and is pure Python,
    rasterio brings GDAL (a large binary) for reading a handful of tags.
ESRI ASCII grid (``.asc``)
    The header ``ncols, nrows, xllcorner|xllcenter, yllcorner|yllcenter, cellsize``
    (or ``dx, dy``), ``NODATA_value``, then the rows, north first. Cells are in the
    units of the grid's CRS, which an ``.asc`` does not name: metres are assumed,
    unless a ``.prj`` beside it holds a CRS pyproj reads.
Web elevation tiles (``.png``, ``--encoding``)
    RGB tiles with metres packed in the channels (:func:`decode_rgb`): Mapbox
    Terrain-RGB ``h = -10000 + 0.1 (65536 R + 256 G + B)`` and Terrarium
    ``h = 256 R + G + B / 256 - 32768``. A tile does not say where it is: the
    cell size must be given (``156543.03 cos(lat) / 2^z`` m for a 256-pixel tile of
    zoom ``z``).
``.npz``
    A ``heights`` array (or the archive's only 2-D array) and ``cell_size``: one
    number or ``[dx, dy]`` in metres.

Metres per pixel
    Projected CRS: the pixel size times the unit of the CRS's axes (pyproj).
    Geographic CRS (degrees): the geodesic length on the CRS's ellipsoid
    (``pyproj.Geod``) of one pixel along the parallel and along the meridian through
    the tile's centre; a 1 arc-second cell at latitude 45 is 21.9 m east-west and
    30.9 m north-south. Across a tile of one degree the east-west size varies by
    about 1.8 %; the centre's value is used for the whole tile.
Square cells
    The implicit heightfield has square cells: a grid with ``dx != dy``
    (geographic grids, or ``--cell-size DX,DY``) is resampled (bilinear) to square
    cells of the smaller size, or larger where the sample count would exceed the
    limit (:func:`square_cells`); the caller prints it and writes it in the header.
Orientation
    Georeferenced rows run north to south in the file; :func:`~.heightmaps.read_dem`
    flips them so that row ``j`` is ``y = y0 + j dy`` with ``+y`` north and ``+x``
    east, as the scene's axes.

References
----------
OGC GeoTIFF Standard 1.1 (19-008r4), 2019: sections 7.1 (raster space, PixelIsArea
and PixelIsPoint) and 7.4 (model transformation tags).
ESRI ASCII raster format (ArcGIS documentation, "Esri ASCII raster format").
Karney, C. F. F. (2013). Algorithms for geodesics. J. Geodesy 87, 43-55 (pyproj.Geod).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Georef", "LINEAR_UNITS", "ENCODINGS", "decode_rgb", "geotiff_georef", "read_asc", "read_npz", "metres_per_pixel",
           "square_cells", "parse_cell_size"]

#: EPSG linear unit codes -> metres (GeoTIFF's ``VerticalUnitsGeoKey``, ``ProjLinearUnitsGeoKey``).
LINEAR_UNITS = {9001: ("metres", 1.0), 9002: ("feet", 0.3048), 9003: ("US survey feet", 1200.0 / 3937.0),
                9036: ("kilometres", 1000.0)}
_USER_DEFINED = 32767
#: RGB encodings of web elevation tiles.
ENCODINGS = ("terrain-rgb", "terrarium")


@dataclass
class Georef:
    """Where a DEM lies and how large its cells are.

    Attributes
    ----------
    crs : str
        ``"EPSG:<code>"``, or a description when the file names no code.
    crs_name : str
        The CRS's name (pyproj), or ``""``.
    geographic : bool
        Coordinates are degrees (longitude, latitude).
    corner : tuple of float
        ``(x, y)`` of the upper-left corner of the upper-left pixel (CRS units).
    pixel : tuple of float
        ``(sx, sy)`` CRS units per pixel, east and south (both positive).
    cell_m : tuple of float
        ``(dx, dy)`` metres per pixel at the tile's centre.
    shape : tuple of int
        ``(ny, nx)`` samples in the file.
    """

    crs: str
    crs_name: str
    geographic: bool
    corner: tuple
    pixel: tuple
    cell_m: tuple
    shape: tuple

    def centre(self) -> tuple:
        """``(x, y)`` of the tile's centre in CRS units: the scene's origin."""
        ny, nx = self.shape
        return (self.corner[0] + 0.5 * nx * self.pixel[0], self.corner[1] - 0.5 * ny * self.pixel[1])

    def lines(self) -> list:
        """Header lines: the CRS, the scene's origin on the map, the cells."""
        cx, cy = self.centre()
        name = f" ({self.crs_name})" if self.crs_name else ""
        where = (f"lon {cx:.7f}, lat {cy:.7f}" if self.geographic else f"x {cx:.3f}, y {cy:.3f} (CRS units)")
        unit = "deg" if self.geographic else "CRS units"
        return [f"Georeference: CRS {self.crs}{name}; the scene's origin (0, 0) is the tile's centre at {where}; "
                f"+x east, +y north",
                f"Georeference: upper-left corner {self.corner[0]:.7g}, {self.corner[1]:.7g}; pixel "
                f"{self.pixel[0]:.7g} x {self.pixel[1]:.7g} {unit} = {self.cell_m[0]:.4f} x {self.cell_m[1]:.4f} m"]


def _crs(code):
    """A pyproj CRS for an EPSG code, or None."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError
    try:
        return CRS.from_epsg(int(code))
    except (CRSError, ValueError, TypeError):
        return None


def metres_per_pixel(crs, centre, pixel, geographic=None, unit=1.0):
    """Metres per pixel ``(dx, dy)`` of a grid at ``centre``.

    Parameters
    ----------
    crs : pyproj.CRS or None
        The grid's CRS (None: projected in ``unit``, or WGS 84 when ``geographic``).
    centre : tuple of float
        ``(x, y)`` of the tile's centre (CRS units; longitude, latitude in degrees).
    pixel : tuple of float
        ``(sx, sy)`` pixel size in CRS units.
    geographic : bool, optional
        Override of ``crs.is_geographic``.
    unit : float
        Metres per CRS unit of a projected grid without a CRS.

    Returns
    -------
    tuple of float
        ``(dx, dy)`` in metres.

    References
    ----------
    Karney (2013): geodesics on the ellipsoid (``pyproj.Geod.inv``).
    """
    from pyproj import Geod
    geo = crs.is_geographic if geographic is None and crs is not None else bool(geographic)
    if not geo:
        if crs is not None and crs.axis_info:
            unit = float(crs.axis_info[0].unit_conversion_factor or 1.0)
        return float(pixel[0]) * unit, float(pixel[1]) * unit
    geod = crs.get_geod() if crs is not None and crs.get_geod() is not None else Geod(ellps="WGS84")
    lon, lat = float(centre[0]), float(centre[1])
    if not (-90.0 < lat < 90.0):
        raise ValueError(f"latitude {lat:g} of the tile's centre is outside (-90, 90)")
    sx, sy = float(pixel[0]), float(pixel[1])
    # Half a pixel on each side of the centre: the geodesic over one pixel is a parallel's arc.
    dx = geod.inv(lon - 0.5 * sx, lat, lon + 0.5 * sx, lat)[2]
    dy = geod.inv(lon, lat - 0.5 * sy, lon, lat + 0.5 * sy)[2]
    return float(dx), float(dy)


def _code(v):
    try:
        return int(v)
    except (TypeError, ValueError):
        return None


def geotiff_georef(page, shape):
    """Georeference and vertical unit of a GeoTIFF page.

    Parameters
    ----------
    page : tifffile.TiffPage
        The first page (its ``geotiff_tags``).
    shape : tuple of int
        ``(ny, nx)`` samples.

    Returns
    -------
    (Georef or None, float, list of str)
        The georeference (None without pixel scale and tie point or transformation),
        metres per vertical unit, notes.

    Raises
    ------
    ValueError
        A rotated or sheared grid, or a pixel size that is zero or not finite.
    """
    tags = page.geotiff_tags or {}
    notes = []
    vcode = _code(tags.get("VerticalUnitsGeoKey"))
    vname, vfactor = LINEAR_UNITS.get(vcode, ("metres", 1.0))
    if vcode is not None and vcode not in LINEAR_UNITS:
        notes.append(f"vertical unit code {vcode} unknown: heights read as metres")
    elif vfactor != 1.0:
        notes.append(f"heights in {vname} converted to metres (x {vfactor:.7g})")
    scale, tie, matrix = tags.get("ModelPixelScale"), tags.get("ModelTiepoint"), tags.get("ModelTransformation")
    if matrix is not None:
        m = np.asarray(matrix, np.float64).reshape(4, 4)
        if m[0, 1] != 0 or m[1, 0] != 0:
            raise ValueError("ModelTransformation rotates or shears the grid; only north-up grids are read "
                             "(warp it to north-up first, e.g. gdalwarp)")
        sx, sy, x0, y0 = m[0, 0], -m[1, 1], m[0, 3], m[1, 3]
    elif scale is not None and tie is not None and len(tie) >= 6:
        sx, sy = float(scale[0]), float(scale[1])
        i0, j0, x, y = float(tie[0]), float(tie[1]), float(tie[3]), float(tie[4])
        x0, y0 = x - i0 * sx, y + j0 * sy
    else:
        return None, vfactor, notes
    if not (math.isfinite(sx) and math.isfinite(sy) and sx > 0 and sy > 0):
        raise ValueError(f"ModelPixelScale {sx:g} x {sy:g}: pixel sizes must be finite and > 0 (north-up grid)")
    if int(_code(tags.get("GTRasterTypeGeoKey")) or 1) == 2:  # PixelIsPoint: the tie is a pixel's centre
        x0, y0 = x0 - 0.5 * sx, y0 + 0.5 * sy
    model = _code(tags.get("GTModelTypeGeoKey"))
    code = _code(tags.get("ProjectedCSTypeGeoKey")) if model != 2 else None
    code = code or _code(tags.get("GeographicTypeGeoKey"))
    crs = _crs(code) if code and code != _USER_DEFINED else None
    geographic = crs.is_geographic if crs is not None else model == 2
    unit = LINEAR_UNITS.get(_code(tags.get("ProjLinearUnitsGeoKey")), ("metres", 1.0))[1]
    if crs is None:
        notes.append("the CRS has no EPSG code: " + ("WGS 84 degrees assumed" if geographic else
                                                     "projected, in its linear unit (metres by default)"))
    ny, nx = shape
    centre = (x0 + 0.5 * nx * sx, y0 - 0.5 * ny * sy)
    cell = metres_per_pixel(crs, centre, (sx, sy), geographic, unit)
    ref = Georef(f"EPSG:{code}" if crs is not None else "user-defined", crs.name if crs is not None else "",
                 bool(geographic), (float(x0), float(y0)), (float(sx), float(sy)), cell, (int(ny), int(nx)))
    return ref, vfactor, notes


def read_asc(path):
    """Read an ESRI ASCII grid.

    Parameters
    ----------
    path : Path
        The ``.asc`` file (a ``.prj`` beside it names the CRS, if any).

    Returns
    -------
    (numpy.ndarray, float or None, Georef)
        Heights as in the file (rows north first), the no-data value, the georeference.

    Raises
    ------
    ValueError
        A missing or bad header key (named, with what it allows), or rows that do
        not match ``ncols x nrows``.
    """
    path = Path(path)
    head, rows = {}, 0
    with open(path, "r", encoding="ascii", errors="replace") as f:
        for line in f:
            parts = line.split()
            if len(parts) != 2 or parts[0][:1].isdigit() or parts[0][:1] in "+-.":
                break
            head[parts[0].lower()] = parts[1]
            rows += 1
    for key in ("ncols", "nrows"):
        if key not in head:
            raise ValueError(f"header key {key} missing (ESRI ASCII grid: ncols, nrows, xllcorner, yllcorner, "
                             f"cellsize, NODATA_value)")
    try:
        nx, ny = int(head["ncols"]), int(head["nrows"])
        vals = {k: float(v) for k, v in head.items() if k not in ("ncols", "nrows")}
    except ValueError:
        raise ValueError("header values must be numbers (ncols and nrows integers)") from None
    if "cellsize" in vals:
        sx = sy = vals["cellsize"]
    elif "dx" in vals and "dy" in vals:
        sx, sy = vals["dx"], vals["dy"]
    else:
        raise ValueError("header key cellsize missing (or dx and dy)")
    if not (nx >= 2 and ny >= 2 and math.isfinite(sx) and math.isfinite(sy) and sx > 0 and sy > 0):
        raise ValueError(f"ncols {nx}, nrows {ny} must be >= 2 and cellsize {sx:g} finite and > 0")
    if "xllcenter" in vals or "yllcenter" in vals:
        x0, y0 = vals.get("xllcenter", 0.0) - 0.5 * sx, vals.get("yllcenter", 0.0) - 0.5 * sy
    else:
        x0, y0 = vals.get("xllcorner", 0.0), vals.get("yllcorner", 0.0)
    data = np.loadtxt(path, skiprows=rows, dtype=np.float64, ndmin=2)
    if data.shape != (ny, nx):
        raise ValueError(f"{data.size} values in {data.shape[0]} rows; the header says nrows {ny} x ncols {nx}")
    crs = None
    prj = path.with_suffix(".prj")
    if prj.is_file():
        from pyproj import CRS
        from pyproj.exceptions import CRSError
        try:
            crs = CRS.from_user_input(prj.read_text(errors="replace"))
        except CRSError:
            crs = None
    top = y0 + ny * sy  # the ESRI origin is the lower-left corner; the first row is the north
    geographic = crs is not None and crs.is_geographic
    centre = (x0 + 0.5 * nx * sx, y0 + 0.5 * ny * sy)
    cell = metres_per_pixel(crs, centre, (sx, sy), geographic)
    epsg = crs.to_epsg() if crs is not None else None
    name = (f"EPSG:{epsg}" if epsg else "from the .prj") if crs is not None else "unknown (no .prj): metres assumed"
    ref = Georef(name, crs.name if crs is not None else "", geographic, (x0, top), (sx, sy), cell, (ny, nx))
    return data, vals.get("nodata_value"), ref


def read_npz(path):
    """Read a ``.npz`` DEM: ``heights`` (or the only 2-D array) and ``cell_size`` (m).

    Returns
    -------
    (numpy.ndarray, tuple of float or None)
        The heights and ``(dx, dy)`` in metres (None without ``cell_size``).

    Raises
    ------
    ValueError
        No 2-D array, or a ``cell_size`` that is not one or two finite numbers > 0.
    """
    with np.load(path, allow_pickle=False) as z:
        names = list(z.files)
        if "heights" in names:
            H = z["heights"]
        else:
            grids = [n for n in names if n != "cell_size" and z[n].ndim == 2]
            if len(grids) != 1:
                raise ValueError(f"holds {', '.join(names) or 'no array'}; a DEM .npz needs a 'heights' array "
                                 f"(or exactly one 2-D array) and optionally 'cell_size'")
            H = z[grids[0]]
        cell = None
        if "cell_size" in names:
            c = np.asarray(z["cell_size"], dtype=np.float64).ravel()
            if c.size not in (1, 2) or not np.all(np.isfinite(c)) or np.any(c <= 0):
                raise ValueError(f"cell_size {c.tolist()}: one or two finite numbers > 0 (metres: d or dx, dy)")
            cell = (float(c[0]), float(c[-1]))
    return H, cell


def square_cells(heights, dx, dy, max_samples=None):
    """Resample a grid of ``dx x dy`` cells to square cells (bilinear).

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` heights, row ``j`` at ``y0 + j dy``.
    dx, dy : float
        Cell sizes (m).
    max_samples : int, optional
        The result has at most this many samples (the cell grows beyond ``min(dx, dy)``).

    Returns
    -------
    (numpy.ndarray, float)
        The resampled heights and their square cell (m); the input when ``dx == dy``.
        The extent is the input's within half a cell.
    """
    H = np.asarray(heights, np.float64)
    ny, nx = H.shape
    if abs(dx - dy) <= 1e-9 * max(dx, dy):
        return H, float(dx)
    W, D = (nx - 1) * dx, (ny - 1) * dy
    cell = min(dx, dy)
    if max_samples and (W / cell + 1) * (D / cell + 1) > max_samples:
        cell = math.sqrt(W * D / max_samples) * 1.001 + 1e-12
    # Whole cells nearest the extent: it changes by half a cell at most (the last row or
    # column repeats the edge where it reaches past it).
    mx, my = int(round(W / cell)) + 1, int(round(D / cell)) + 1
    from scipy import ndimage
    J, I = np.meshgrid(np.arange(my) * (cell / dy), np.arange(mx) * (cell / dx), indexing="ij")
    return ndimage.map_coordinates(H, [J, I], order=1, mode="nearest"), float(cell)


def parse_cell_size(text):
    """``--cell-size D`` or ``DX,DY`` (metres, finite and > 0) -> ``(dx, dy)``.

    Raises
    ------
    ValueError
        With a one-line message naming the option and the allowed values.
    """
    parts = str(text).replace(" ", "").split(",")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        vals = []
    if len(vals) not in (1, 2) or not all(math.isfinite(v) and 0 < v <= 1e7 for v in vals):
        raise ValueError(f"--cell-size must be D or DX,DY: metres between samples, each > 0 and <= 1e7 "
                         f"(got {text!r})")
    return vals[0], vals[-1]


def decode_rgb(raw, encoding):
    """Heights (m) of an RGB web elevation tile.

    Parameters
    ----------
    raw : numpy.ndarray
        ``(ny, nx, 3 or 4)`` 8-bit channels.
    encoding : str
        ``"terrain-rgb"`` (Mapbox) or ``"terrarium"`` (Mapzen / AWS Terrain Tiles).

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` float64 metres.

    Raises
    ------
    ValueError
        Not an 8-bit RGB image, or an unknown encoding.

    References
    ----------
    Mapbox Terrain-RGB v1 (docs.mapbox.com, "Mapbox Terrain-RGB v1"); Mapzen
    Terrain Tiles, "Terrarium" format (github.com/tilezen/joerd, docs/formats.md).
    """
    if encoding not in ENCODINGS:
        raise ValueError(f"--encoding {encoding!r}: allowed {', '.join(ENCODINGS)}")
    if raw.ndim != 3 or raw.shape[-1] not in (3, 4) or raw.dtype != np.uint8:
        raise ValueError(f"--encoding {encoding} needs an 8-bit RGB image (got {raw.dtype} {raw.shape})")
    r, g, b = (raw[..., k].astype(np.float64) for k in range(3))
    if encoding == "terrain-rgb":
        return -10000.0 + 0.1 * (65536.0 * r + 256.0 * g + b)
    return 256.0 * r + g + b / 256.0 - 32768.0
