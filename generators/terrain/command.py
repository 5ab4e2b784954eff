"""``arches-render amplify DEM -o SCENE.toml``: a DEM amplified into a volumetric terrain scene.

Reads a DEM (``.npy``, ``.npz``, 16-bit ``.png``, GeoTIFF ``.tif``, ESRI ``.asc``; see
:mod:`arches_render.field.heightmaps` and :mod:`arches_render.field.dem_readers`), builds the construction tree of a
preset (:mod:`.amplify`) and writes a scene that renders as it is: the
``[nodes.*]`` of the tree, the heights (``.npy``), the primitive arrays (``.npz``)
and the water (``.ply``) beside it (or under ``--data-dir``), named cameras
(close shots of the landforms first, then ``overview``: :mod:`.shots`), sun and
sky, the far field to the horizon (:mod:`.far_field`) and the triplanar
``terrain`` material fitted to the DEM's elevations. The data files go first and
the scene file last, each written atomically, so a reader never sees a scene whose
data is missing or half written; bad input exits 2 with one line and writes nothing.

Options: ``--cell-size`` metres between samples, ``D`` or ``DX,DY`` (default: the file's
georeference or ``cell_size``, else 1; non-square cells are resampled to square ones,
printed and written in the header, with the CRS and the map position of the scene's
origin), ``--encoding`` (``terrain-rgb`` or ``terrarium``: an RGB ``.png`` web elevation tile,
read in metres; needs ``--cell-size``), ``--height-scale``
(multiplies the heights; PNG samples are read as [0, 1], so their default is a
relief of a quarter of the tile's width), ``--preset`` (``auto``, the default,
picks from the DEM: :func:`.preset_choice.choose_preset`; or sea, river, karst,
hoodoos, strata), ``--sea-level`` (metres, default 0), ``--precision`` (smallest
detail in metres; default 10 cm for DEMs of 2 m cells or finer, cell / 16
otherwise), ``--seed``, ``--max-cells`` (larger DEMs are block-averaged down to it,
default 8192^2: the reduction is printed and written in the scene's header; at 8192^2
the implicit heightfield alone holds 1.3 GB, heights and maximum mipmaps, 2.6 GB peak),
``--data-dir`` (relative to the scene's folder), ``--refine`` (a DEM of 100 m cells or
coarser: amplify a crop of it at metres, the rest of the DEM as the far field;
:mod:`.refined_crop`; the default at such cells, ``--no-refine`` amplifies the whole DEM)
with ``--refine-cells``, ``-q``.

Heights quantized on a lattice whose terraces show (whole metres on gentle slopes, an
8-bit image) are smoothed within half a step first, and the header says so
(:mod:`arches_render.field.dequantize`).
A preset that finds nothing to carve (no coastal cliff, no tunnel, a flat DEM) says so
in one line, printed and written in the scene's header, and with ``auto`` the next
applicable preset runs instead (:mod:`.fallback`); the scene is written in any case.

Limits (exit 2, one line naming the file): at least 3 samples a side, sides at
most :data:`MAX_ASPECT` times longer than the other (the polygonizer's default
voxel is a 256th of the longer side: a narrower strip has no voxel across), and
heights within ``+-MAX_HEIGHT`` metres after scaling (float32 keeps a millimetre
at 1e4 m and a metre at 1e7 m; beyond, the field's squares overflow).
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

import numpy as np

from arches_render.atomic import atomic_write, temp_dir
from arches_render.commands import Progress, UsageError, bounded_int, positive_float, writable_output
from arches_render.field.dem_readers import ENCODINGS, parse_cell_size, square_cells
from arches_render.field.heightmaps import DEMError, read_dem

from .amplify import PRESET_NAMES
from .fallback import amplify_soft
from .hydrology import slope
from .presets import PRESETS
from .refined_crop import CROP_WIDTH_M, REFINE_ABOVE, REFINE_CELLS, attach_context, refine_crop
from arches_render.tomlfile import toml_text

#: Default largest DEM processed (cells); larger ones are averaged down.
MAX_CELLS = 8192 * 8192
#: Longest side / shortest side of a DEM.
MAX_ASPECT = 64
#: Largest absolute height after scaling (metres).
MAX_HEIGHT = 1e7
#: Median slope (degrees) over which a DEM whose cell was assumed (1 m: the file gives none)
#: gets a note: the cell is likely wrong (a 2.4 km DEM read at 1 m became needles).
UNSURE_SLOPE = 45.0


def _finite_float(name):
    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number of metres (got {text!r})") from None
        if not math.isfinite(v) or abs(v) > MAX_HEIGHT:
            raise argparse.ArgumentTypeError(f"{name} must be a finite number within +-{MAX_HEIGHT:g} m (got {text})")
        return v
    return parse


def _cell_size(text):
    import argparse
    try:
        return parse_cell_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def register(subparsers):
    p = subparsers.add_parser(
        "amplify", help="amplify a DEM (.npy, 16-bit .png, .tif) into a volumetric terrain scene",
        description="Build the construction tree of a terrain-amplification preset from a DEM and "
                    "write a scene file that renders as it is (Paris et al. 2019).")
    p.add_argument("dem", help="DEM file: .npy, 16-bit .png or GeoTIFF .tif")
    p.add_argument("-o", "--output", required=True, help="scene file to write (.toml)")
    p.add_argument("--cell-size", type=_cell_size, default=None,
                   help="metres between DEM samples: D or DX,DY (default: from the file's georeference or "
                        "cell_size, else 1); overrides the file")
    p.add_argument("--encoding", choices=ENCODINGS, default=None,
                   help="an RGB .png web elevation tile: terrain-rgb (Mapbox) or terrarium (Mapzen); "
                        "needs --cell-size")
    p.add_argument("--height-scale", type=positive_float("--height-scale"), default=None,
                   help="multiply the heights (default 1; for PNG, a relief of 1/4 of the tile width)")
    p.add_argument("--preset", choices=PRESET_NAMES, default="auto",
                   help="landforms to generate (default auto: chosen from the DEM); " +
                        "; ".join(f"{k}: {v.description}" for k, v in PRESETS.items()))
    p.add_argument("--sea-level", type=_finite_float("--sea-level"), default=0.0,
                   help="sea level in metres (default 0): the sea is the cells below it that reach the border")
    p.add_argument("--precision", type=positive_float("--precision"), default=None,
                   help="smallest detail in metres (default 0.1 for DEMs of 2 m cells or finer, cell/16 otherwise)")
    p.add_argument("--seed", type=bounded_int("--seed", 0, 2 ** 31 - 1), default=0, help="random seed (default 0)")
    p.add_argument("--max-cells", type=bounded_int("--max-cells", 4, 16384 ** 2), default=MAX_CELLS,
                   help=f"larger DEMs are block-averaged down to this many cells (default {MAX_CELLS})")
    p.add_argument("--data-dir", default=None,
                   help="folder for the heights and primitive arrays, relative to the scene's folder "
                        "(default: beside the scene)")
    p.add_argument("--no-fallen-blocks", dest="fallen_blocks", action="store_false",
                   help="strata preset: no blocks fallen from the cliffs at their feet (a shot that sees them "
                        "renders 30-45 %% faster, one that does not 3-15 %%)")
    p.add_argument("--refine", action=argparse.BooleanOptionalAction, default=None,
                   help=f"a DEM of {REFINE_ABOVE:g} m cells or coarser: amplify a crop of it (at least "
                        f"{CROP_WIDTH_M / 1000:g} km, where its relief is greatest) at {REFINE_CELLS} cells a side "
                        f"with detail continuing its spectrum, so that landforms are carved in metres; the rest of "
                        f"the DEM is the far field (the default at such cells; --no-refine amplifies the whole DEM "
                        f"at its cells)")
    p.add_argument("--refine-cells", type=bounded_int("--refine-cells", 64, 2048), default=REFINE_CELLS,
                   help=f"--refine: cells along the crop's side (default {REFINE_CELLS}; amplify's time grows "
                        f"with their square)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _checked_heights(args, dem):
    """Scaled heights and their cell, or a UsageError naming the file and the limit."""
    H = dem.heights
    ny, nx = H.shape
    if min(nx, ny) < 3:
        raise UsageError(f"{args.dem}: {nx}x{ny} samples; amplify needs at least 3x3")
    if max(nx, ny) > MAX_ASPECT * (min(nx, ny) - 1) + 1:
        raise UsageError(f"{args.dem}: {nx}x{ny} samples; a side may be at most {MAX_ASPECT} times longer than "
                         f"the other (crop the DEM into tiles)")
    if args.cell_size is not None:  # the user's override: metres between the file's samples
        dx, dy = (c * dem.step for c in args.cell_size)
    else:
        dx, dy = dem.cell if dem.cell is not None else (float(dem.step), float(dem.step))
    notes = []
    if abs(dx - dy) > 1e-9 * max(dx, dy):
        # The implicit heightfield has square cells: resample (a geographic grid, DX,DY).
        H, cell = square_cells(H, dx, dy, args.max_cells)
        notes.append(f"resampled {nx}x{ny} cells of {dx:.4g} x {dy:.4g} m to {H.shape[1]}x{H.shape[0]} square "
                     f"cells of {cell:.4g} m (bilinear)")
    else:
        cell = dx
    scale = args.height_scale
    if scale is None:
        scale = 0.25 * cell * (max(H.shape) - 1) if dem.normalised else 1.0
    with np.errstate(over="ignore", invalid="ignore"):
        H = H * scale
        big = float(np.max(np.abs(H)))
    if not math.isfinite(big) or big > MAX_HEIGHT or not np.all(np.isfinite(H.astype(np.float32))):
        raise UsageError(f"{args.dem}: heights reach {big:.3g} m after scaling by {scale:g}; "
                         f"amplify accepts heights within +-{MAX_HEIGHT:g} m")
    if dem.cell is None and args.cell_size is None and not dem.normalised:
        steep = _median_slope(H, cell)
        if steep > UNSURE_SLOPE:
            notes.append(f"the file gives no cell size, so {cell:g} m was assumed, and its median slope is then "
                         f"{steep:.0f} deg; --cell-size D gives the metres between samples")
    return H, cell, notes


def _median_slope(H, cell) -> float:
    """Median slope of ``H`` (degrees), on at most about a million samples."""
    k = max(1, int(math.sqrt(H.size / 1e6)))
    return math.degrees(math.atan(float(np.median(slope(H[::k, ::k], k * cell)))))


def run(args) -> int:
    out = Path(args.output)
    if out.suffix.lower() != ".toml":
        raise UsageError(f"-o {out}: the scene file must end in .toml")
    writable_output(out)
    data_dir = Path(args.data_dir) if args.data_dir else Path(".")
    if data_dir.is_absolute() or ".." in data_dir.parts:
        raise UsageError(f"--data-dir {args.data_dir}: must be a folder inside the scene's folder")
    if args.encoding and args.cell_size is None:
        raise UsageError(f"{args.dem}: --encoding {args.encoding} needs --cell-size (a web tile does not say "
                         f"where it is: 156543.03 cos(lat) / 2^zoom m for a 256-pixel tile)")
    try:
        dem = read_dem(args.dem, max_samples=args.max_cells, encoding=args.encoding)
    except DEMError as exc:
        raise UsageError(f"{args.dem}: {exc}" if str(args.dem) not in str(exc) else str(exc)) from None
    H, cell, resampled = _checked_heights(args, dem)
    # A reduction changes what the DEM resolves: say so in one line, with the way to keep more.
    notes = [f"{n}; the cell is now {cell:g} m (--max-cells {args.max_cells}; a larger value keeps more)"
             if n.startswith("reduced") else n for n in dem.notes] + resampled
    crop = None
    # Coarse cells are refined unless the user says not to (issue 34: landforms in metres).
    refine = args.refine if args.refine is not None else cell >= REFINE_ABOVE
    if refine and cell >= REFINE_ABOVE:
        crop = refine_crop(H, cell, args.sea_level, args.seed, cells=args.refine_cells)
        H, cell = crop.heights, crop.cell
        notes += crop.notes
    elif refine:
        notes.append(f"--refine: cells of {cell:g} m are finer than {REFINE_ABOVE:g} m; the whole DEM is amplified")
    elif cell >= REFINE_ABOVE:
        notes.append(f"cells of {cell:g} m: landforms are carved at this scale (--no-refine); without it a crop "
                     f"of the DEM is amplified at metres")
    georef = dem.georef.lines() if dem.georef is not None else []
    for note in notes + georef[:1]:
        print(f"arches-render amplify: {args.dem}: {note}", flush=True)

    cell_text = (",".join(f"{c:g}" for c in dict.fromkeys(args.cell_size)) if args.cell_size
                 else f"{cell:g} (from the file)" if dem.cell is not None else "1")
    bar = Progress(f"amplify {args.preset}", "step", args.quiet)
    prefix = (data_dir / out.stem).as_posix()
    # The work folder's name carries this process's id: one left by a kill is swept by the next run.
    with temp_dir(out.parent, out.stem) as work:
        shots_bar = Progress("shots", "landform", args.quiet)
        # A preset that finds nothing to carve says so and the next applicable one runs (.fallback).
        kept = amplify_soft(H, cell, args.preset, args.seed, work, prefix, out.stem, sea_level=args.sea_level,
                            precision=args.precision, shots_progress=shots_bar,
                            progress=lambda done, total, label: (bar.bar.set_postfix_str(label),
                                                                 bar(done, total)),
                            say=lambda line: print(f"arches-render amplify: {args.dem}: {line}", flush=True),
                            options=None if args.fallen_blocks else {"fallen_blocks": False},
                            context=None if crop is None else (crop.context, crop.context_extent),
                            lake_levels=None if crop is None else crop.lake_levels)
        bar.close()
        shots_bar.close()
        result, doc, lines = kept.result, kept.doc, kept.lines
        if crop is not None:
            result.files.append(attach_context(doc, crop, kept.folder, prefix))
        print(f"arches-render amplify: preset {result.preset} ({result.reason})", flush=True)
        # Publish the data files (atomic renames within one folder tree), then the scene.
        for rel in result.files:
            dest = out.parent / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            os.replace(kept.folder / rel, dest)
        header = "\n".join([f"Generated by: arches-render amplify {Path(args.dem).name} --preset {args.preset} "
                            f"--seed {args.seed} --cell-size {cell_text} --sea-level {args.sea_level:g}"
                            + ("" if args.fallen_blocks else " --no-fallen-blocks")
                            + (f" --refine --refine-cells {args.refine_cells}" if crop is not None
                               else " --no-refine" if args.refine is False else "")]
                           + [f"DEM: {note}" for note in notes] + georef + kept.notes + lines)
        text = toml_text(doc, header)
        with atomic_write(out, "w", encoding="utf-8") as f:
            f.write(text)
    bar.close()
    st = result.stats
    # A flat DEM's note was said already as a "nothing to carve" line.
    for note in ([st["note"]] if "note" in st and not kept.notes else []) + st.get("notes", []):
        print(f"arches-render amplify: {args.dem}: {note}", flush=True)
    print(f"arches-render amplify: wrote {out} ({st['nodes']} nodes, {st['primitives']} primitives, "
          f"{st['memory_bytes'] / 1e6:.2f} MB; heights {H.shape[1]}x{H.shape[0]} at {cell:g} m; "
          f"{len(doc['cameras'])} cameras: {', '.join(doc['cameras'])})", flush=True)
    return 0
