"""Height grids for ``Heightfield`` nodes: read from DEM files or made from fBm.

One module for the height data of the whole project: the ``heightfield`` scene node
(``source = "file"`` or ``"fbm"``), the terrain generators and ``arches-render
amplify`` all call :func:`read_dem` and :func:`fbm_heightmap`, so a DEM reads, and
an fBm relief is made, the same way everywhere. Nothing here knows a scene file or
a generator.

DEM formats and units
---------------------
``.npy``          a 2-D numeric array, read through a memory map (large files are
                  never loaded whole); values are metres.
``.tif/.tiff``    GeoTIFF through tifffile (first page; memory-mapped when the file
                  is uncompressed). The GDAL no-data tag (42113) is honoured; the
                  GeoKeys give the cell size in metres, the CRS and the map position
                  and the vertical unit (:mod:`.dem_readers`).
``.asc``          ESRI ASCII grid (header with cell size, corner and no-data value).
``.npz``          ``heights`` and ``cell_size`` (metres: one number or ``dx, dy``).
``.png``          8- or 16-bit grey (an RGB image uses its first channel). Image
                  values carry no unit, so integer samples are normalised to
                  ``[0, 1]`` (``value / 65535`` for 16 bits); the caller scales them
                  (``height_scale`` in scene files, ``--height-scale`` in amplify).

No-data cells
-------------
NaN, infinite and no-data cells are filled with the height of the *nearest* valid
cell (Euclidean distance transform): this keeps cliffs sharp and invents no relief,
unlike a smooth interpolation that would bulge across a large hole. How many cells
were filled is reported in :attr:`DEM.notes`. A DEM with no valid cell is an error.

Size limits
-----------
A DEM of more than ``max_samples`` cells is reduced by an integer factor ``k`` with
the mean of ``k x k`` blocks (NaN-aware), computed band by band from the memory map,
so a 20,000 x 20,000 ``.npy`` is read with a few megabytes of memory. A compressed
GeoTIFF or a PNG must be decoded whole; beyond :data:`DECODE_LIMIT` samples they are
refused with a clear error (convert them to ``.npy`` or an uncompressed GeoTIFF).
A DEM must have at least 2 x 2 samples.

Georeferenced DEMs (GeoTIFF with a geotransform, ``.asc``) store their rows north
first; they are flipped so that row ``j`` is ``y = y0 + j dy`` with ``+y`` north, and
their heights are converted to metres. :attr:`DEM.cell` and :attr:`DEM.georef` carry
the cell sizes (after any reduction) and the map position.

fBm heightmaps
--------------
:func:`fbm_heightmap` samples the same :class:`~arches_render.field.Noise` node that
scenes use elsewhere (one construction tree, one noise), on the plane ``z = 0``:

    h(x, y) = offset + amplitude * shape(n(x, y)),

where ``n`` is fBm normalized to about ``[0, 1]``, ``shape`` optionally folds it into
ridges (``1 - |2n - 1|``, Musgrave's ridged multifractal idea) and raises it to
``power`` (values > 1 widen valleys and sharpen peaks). With ``edge_falloff`` the
relief fades to ``offset`` over that many metres at the border of the tile, so the
tile meets a plain without a cliff.

References
----------
Musgrave, F. K., Kolb, C. E., Mace, R. S. (1989). The synthesis and rendering of
eroded fractal terrains. SIGGRAPH '89.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image

from .dem_readers import decode_rgb, geotiff_georef, read_asc, read_npz
from .node import evaluate
from .noise import fbm_range
from .warps import Noise

__all__ = ["DEM", "DEMError", "read_dem", "fill_nodata", "block_mean", "DECODE_LIMIT", "fbm_heightmap"]

#: Largest number of samples decoded whole (PNG, compressed TIFF): 16384^2.
DECODE_LIMIT = 16384 * 16384
#: Default size after reduction, in samples.
DEFAULT_MAX_SAMPLES = 4096 * 4096


class DEMError(ValueError):
    """A DEM that cannot be used; ``str(err)`` is one line naming the problem."""


@dataclass
class DEM:
    """Heights read from a file.

    Attributes
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` float64, all finite. Row ``j`` is ``y = y0 + j dy`` (rows go
        north-up in the file order; the caller chooses the extent).
    path : Path
        The file read.
    source_shape : tuple
        Shape in the file, before any reduction.
    step : int
        Block size of the reduction (1: none).
    normalised : bool
        Whether integer image values were mapped to ``[0, 1]`` (PNG).
    filled : int
        Number of no-data cells filled.
    notes : list of str
        What was done to the data, one sentence each (for the user).
    cell : tuple of float or None
        ``(dx, dy)`` metres per sample after the reduction, when the file says it.
    georef : dem_readers.Georef or None
        CRS and map position (GeoTIFF, ``.asc``).
    """

    heights: np.ndarray
    path: Path
    source_shape: tuple
    step: int = 1
    normalised: bool = False
    filled: int = 0
    notes: list = field(default_factory=list)
    cell: tuple | None = None
    georef: object = None


def block_mean(array, step):
    """Mean of ``step x step`` blocks, NaN-aware, read one band of ``step`` rows at a time.

    Parameters
    ----------
    array : array_like
        ``(ny, nx)`` array, possibly a memory map.
    step : int
        Block edge in samples, >= 1; partial blocks at the far edges are averaged
        over the samples they hold.

    Returns
    -------
    numpy.ndarray
        ``(ceil(ny / step), ceil(nx / step))`` float64; NaN where a block held no
        finite value.
    """
    ny, nx = array.shape
    if step == 1:
        return np.array(array[0:ny], dtype=np.float64)
    oy, ox = math.ceil(ny / step), math.ceil(nx / step)
    out = np.empty((oy, ox), dtype=np.float64)
    pad = ox * step - nx
    for j in range(oy):
        band = np.asarray(array[j * step:(j + 1) * step], dtype=np.float64)
        if pad:
            band = np.pad(band, ((0, 0), (0, pad)), constant_values=np.nan)
        band = band.reshape(band.shape[0], ox, step)
        ok = np.isfinite(band)
        n = ok.sum(axis=(0, 2))
        s = np.where(ok, band, 0.0).sum(axis=(0, 2))
        with np.errstate(invalid="ignore", divide="ignore"):
            out[j] = np.where(n > 0, s / np.maximum(n, 1), np.nan)
    return out


def fill_nodata(heights, invalid=None):
    """Fill invalid cells with the height of the nearest valid cell.

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` float64 heights.
    invalid : numpy.ndarray of bool, optional
        Cells to fill; default the non-finite ones.

    Returns
    -------
    (numpy.ndarray, int)
        The filled copy and the number of cells filled.

    Raises
    ------
    DEMError
        When no cell is valid.
    """
    H = np.array(heights, dtype=np.float64)
    bad = ~np.isfinite(H) if invalid is None else (invalid | ~np.isfinite(H))
    n = int(bad.sum())
    if n == 0:
        return H, 0
    if n == H.size:
        raise DEMError("no valid height (every cell is NaN or no-data)")
    from scipy.ndimage import distance_transform_edt  # on use: scipy.ndimage takes 0.17 s to import
    idx = distance_transform_edt(bad, return_distances=False, return_indices=True)
    return H[tuple(idx)], n


class _Rows:
    """Row bands of a raw C-order array in a file, read with plain reads.

    A memory map would do, but every page it touches stays resident until the map
    is closed, so the block means of a 20,000^2 DEM would count gigabytes of
    resident memory; plain reads hold one band at a time.
    """

    def __init__(self, path, offset, dtype, shape):
        self.path, self.offset, self.dtype, self.shape = path, int(offset), np.dtype(dtype), tuple(shape)
        self.ndim = len(self.shape)

    def __getitem__(self, rows):
        start, stop, _ = rows.indices(self.shape[0])
        row = int(np.prod(self.shape[1:])) * self.dtype.itemsize
        with open(self.path, "rb") as f:
            f.seek(self.offset + start * row)
            data = np.fromfile(f, dtype=self.dtype, count=max(stop - start, 0) * row // self.dtype.itemsize)
        return data.reshape((-1,) + self.shape[1:])


def _open_npy(path):
    with open(path, "rb") as f:
        try:
            version = np.lib.format.read_magic(f)
            read_header = {(1, 0): np.lib.format.read_array_header_1_0,
                           (2, 0): np.lib.format.read_array_header_2_0}.get(version)
            header = read_header(f) if read_header else None
        except ValueError as exc:
            raise DEMError(f"cannot read {path} as a .npy array: {exc}") from None
        offset = f.tell()
    if header is None or header[1] or len(header[0]) != 2 or header[2].hasobject:
        # Rare layouts (Fortran order, not 2-D, objects): let numpy read or refuse them.
        try:
            return np.load(path, mmap_mode="r", allow_pickle=False), False, None
        except ValueError as exc:
            raise DEMError(f"cannot read {path} as a numeric .npy array: {exc}") from None
    shape, _, dtype = header
    return _Rows(path, offset, dtype, shape), False, None


def _open_png(path, encoding=None):
    with Image.open(path) as im:
        w, h = im.size
    if w * h > DECODE_LIMIT:
        raise DEMError(f"{path} has {w}x{h} samples, more than a PNG can be decoded whole "
                       f"({DECODE_LIMIT} samples); convert it to .npy or an uncompressed GeoTIFF")
    limit = Image.MAX_IMAGE_PIXELS
    try:  # Pillow's decompression-bomb guard also trips on honest large DEMs
        Image.MAX_IMAGE_PIXELS = None
        import imageio.v3 as iio  # on use: 0.03 s to import, for image DEMs only
        raw = iio.imread(path)
    finally:
        Image.MAX_IMAGE_PIXELS = limit
    if encoding:  # web elevation tiles: metres packed in the colour channels
        return decode_rgb(raw, encoding), False, None, dict(notes=[f"{encoding} encoding decoded to metres"])
    if raw.ndim == 3:
        raw = raw[..., 0]
    if np.issubdtype(raw.dtype, np.integer):
        return raw.astype(np.float64) / float(np.iinfo(raw.dtype).max), True, None
    return raw.astype(np.float64), False, None


def _open_tiff(path):
    import tifffile  # on use: 0.02 s to import, for GeoTIFF DEMs only
    with tifffile.TiffFile(path) as tf:
        page = tf.pages[0]
        nodata = None
        tag = page.tags.get(42113)  # GDAL_NODATA, stored as text
        if tag is not None:
            try:
                nodata = float(str(tag.value).strip().strip("\x00"))
            except ValueError:
                nodata = None
        shape = page.shape
        georef, vfactor, gnotes = geotiff_georef(page, shape[:2])
        memmappable = page.is_memmappable and len(shape) == 2
        if memmappable:
            offset, dtype = page.dataoffsets[0], np.dtype(tf.byteorder + page.dtype.char)
    size = int(np.prod(shape))
    if memmappable:
        a = _Rows(path, offset, dtype, shape)
    elif size > DECODE_LIMIT:
        raise DEMError(f"{path} is a compressed TIFF of {shape} samples, more than can be decoded "
                       f"whole ({DECODE_LIMIT}); write it uncompressed or as .npy")
    else:
        a = tifffile.imread(path)
    return a, False, nodata, dict(georef=georef, vertical=vfactor, notes=gnotes)


def _open_asc(path):
    data, nodata, georef = read_asc(path)
    return data, False, nodata, dict(georef=georef)


def _open_npz(path):
    heights, cell = read_npz(path)
    return heights, False, None, dict(cell=cell)


_READERS = {".npy": _open_npy, ".png": _open_png, ".tif": _open_tiff, ".tiff": _open_tiff, ".asc": _open_asc,
            ".npz": _open_npz}


def read_dem(path, max_samples=DEFAULT_MAX_SAMPLES, nodata=None, encoding=None):
    """Read a DEM, fill its no-data cells and reduce it to at most ``max_samples`` cells.

    Parameters
    ----------
    path : str or Path
        A ``.npy``, ``.png``, ``.tif`` or ``.tiff`` file (see module docstring).
    max_samples : int
        Largest number of cells returned; larger DEMs are block-averaged.
    nodata : float, optional
        A value marking missing cells, besides NaN/inf and the GeoTIFF tag.
    encoding : str, optional
        ``"terrain-rgb"`` or ``"terrarium"``: an RGB ``.png`` web elevation tile
        (:func:`.dem_readers.decode_rgb`).

    Returns
    -------
    DEM
        Finite float64 heights and notes on what was done.

    Raises
    ------
    DEMError
        Unknown format, unreadable file, not 2-D, fewer than 2 x 2 samples, no
        valid height, or too large to decode (one-line message).
    """
    path = Path(path)
    if not path.is_file():
        raise DEMError(f"no such file: {path}")
    reader = _READERS.get(path.suffix.lower())
    if reader is None:
        raise DEMError(f"{path}: unknown DEM format {path.suffix!r} (use .npy, .npz, 16-bit .png, .tif, .tiff "
                       f"or .asc)")
    if encoding and reader is not _open_png:
        raise DEMError(f"{path}: --encoding {encoding} reads RGB .png web tiles only")
    try:
        raw, normalised, tag_nodata, *meta = reader(path, encoding) if encoding else reader(path)
    except DEMError:
        raise
    except Exception as exc:  # a corrupt file: name it, no traceback
        raise DEMError(f"cannot read {path}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    if raw.ndim == 3 and raw.shape[-1] in (1, 3, 4):
        raw = raw[..., 0]
    if raw.ndim != 2:
        raise DEMError(f"{path} must hold a 2-D array of heights (got shape {raw.shape})")
    if not (np.issubdtype(raw.dtype, np.number) and not np.issubdtype(raw.dtype, np.complexfloating)):
        raise DEMError(f"{path} holds {raw.dtype} values, not real numbers")
    if min(raw.shape) < 2:
        raise DEMError(f"{path} has {raw.shape[0]}x{raw.shape[1]} samples; a DEM needs at least 2x2")
    shape = tuple(int(v) for v in raw.shape)
    notes = []
    step = 1
    if raw.shape[0] * raw.shape[1] > max_samples:
        step = math.ceil(math.sqrt(raw.shape[0] * raw.shape[1] / max_samples))
        while math.ceil(shape[0] / step) * math.ceil(shape[1] / step) > max_samples:
            step += 1
    marks = [v for v in (nodata, tag_nodata) if v is not None]
    if marks and step > 1:
        # Mark no-data as NaN band by band, so the block means skip it.
        class _Masked:
            shape = raw.shape

            def __getitem__(self, s):
                band = np.asarray(raw[s], dtype=np.float64)
                for v in marks:
                    band[band == v] = np.nan
                return band
        H = block_mean(_Masked(), step)
    else:
        H = block_mean(raw, step)
        for v in marks:
            H[H == v] = np.nan
    if step > 1:
        notes.append(f"reduced {shape[1]}x{shape[0]} samples to {H.shape[1]}x{H.shape[0]} "
                     f"(mean of {step}x{step} blocks)")
    if min(H.shape) < 2:
        raise DEMError(f"{path} reduces to {H.shape[0]}x{H.shape[1]} samples; a DEM needs at least 2x2")
    H, filled = fill_nodata(H)
    if filled:
        notes.append(f"filled {filled} no-data cells ({100.0 * filled / H.size:.2g}%) "
                     f"with the height of the nearest valid cell")
    meta = meta[0] if meta else {}
    georef, cell = meta.get("georef"), meta.get("cell")
    notes += meta.get("notes", [])
    if meta.get("vertical", 1.0) != 1.0:
        H = H * meta["vertical"]
    if georef is not None:
        H = np.ascontiguousarray(H[::-1])  # rows north first in the file; +y is north in the scene
        cell = georef.cell_m
    if cell is not None:
        cell = (cell[0] * step, cell[1] * step)
    if H.max() == H.min():  # (a difference overflows for heights near the float32 limits)
        notes.append("the DEM is flat (all heights equal)")
    return DEM(H, path, shape, step, normalised, filled, notes, cell, georef)


def fbm_heightmap(extent, resolution, amplitude=30.0, wavelength=80.0, octaves=6, lacunarity=2.0,
                  gain=0.5, seed=0, ridged=False, power=1.0, offset=0.0, edge_falloff=0.0):
    """Sample an fBm heightmap (see the module docstring).

    Parameters
    ----------
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` in metres.
    resolution : sequence of 2 ints
        ``(nx, ny)`` samples, each >= 2.
    amplitude, offset : float
        Height range and base elevation in metres.
    wavelength : float
        Period of the first octave in metres.
    octaves : int
        fBm octaves.
    lacunarity, gain : float
        Frequency and amplitude ratios between octaves.
    seed : int
        Noise seed: the same seed gives the same heights.
    ridged : bool
        Fold the noise into ridges.
    power : float
        Exponent applied to the normalized noise.
    edge_falloff : float
        Width in metres of the border over which the relief fades out (0: none).

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` float64 heights.

    References
    ----------
    Musgrave, Kolb, Mace (1989), ridged multifractal terrains.
    """
    x0, y0, x1, y1 = extent
    nx, ny = int(resolution[0]), int(resolution[1])
    xs, ys = np.linspace(x0, x1, nx), np.linspace(y0, y1, ny)
    X, Y = np.meshgrid(xs, ys)
    pts = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    noise = Noise(1.0, wavelength, octaves, lacunarity, gain, seed)
    n = evaluate(noise, pts).astype(np.float64).reshape(ny, nx)
    # Gradient noise rarely exceeds ~0.7 of its bound: map that range onto [0, 1].
    typical = 0.7 * fbm_range(octaves, gain) / 1.5
    u = np.clip(0.5 + 0.5 * n / typical, 0.0, 1.0)
    if ridged:
        u = 1.0 - np.abs(2.0 * u - 1.0)
    u = u ** float(power)
    if edge_falloff > 0:
        border = np.minimum(np.minimum(X - x0, x1 - X), np.minimum(Y - y0, y1 - Y))
        t = np.clip(border / edge_falloff, 0.0, 1.0)
        u = u * t * t * (3.0 - 2.0 * t)
    return offset + amplitude * u
