"""``arches-render amplify DEM -o SCENE.toml``: a DEM amplified into a volumetric terrain scene.

Reads a DEM (``.npy``, 16-bit ``.png``, GeoTIFF ``.tif``; see
:mod:`arches_render.field.heightmaps`), builds the construction tree of a
preset (:mod:`.amplify`) and writes a scene that
renders as it is: the ``[nodes.*]`` of the tree, the heights (``.npy``) and the
primitive arrays (``.npz``) beside it (or under ``--data-dir``), a camera framed on
the terrain, sun and sky, and the triplanar ``terrain`` material fitted to the
DEM's elevations. The data files go first and the scene file last, each written
atomically, so a reader never sees a scene whose data is missing or half written.

Options: ``--cell-size`` metres between samples (default 1), ``--height-scale``
(multiplies the heights; PNG samples are read as [0, 1], so their default is a
relief of a quarter of the tile's width), ``--preset`` (sea, river, karst,
hoodoos, strata), ``--seed``, ``--max-cells`` (larger DEMs are block-averaged
down to it), ``--data-dir`` (relative to the scene's folder), ``-q``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from arches_render.atomic import atomic_write, temp_dir
from arches_render.commands import Progress, UsageError, bounded_int, positive_float, writable_output
from arches_render.field.heightmaps import DEMError, read_dem
from arches_render.scene.nodes import NodeBuilder

from .amplify import amplify
from .presets import PRESETS
from .scene_writer import frame_camera, landscape_material, sun_for, toml_text

#: Default largest DEM processed (cells); larger ones are averaged down.
MAX_CELLS = 1024 * 1024


def register(subparsers):
    p = subparsers.add_parser(
        "amplify", help="amplify a DEM (.npy, 16-bit .png, .tif) into a volumetric terrain scene",
        description="Build the construction tree of a terrain-amplification preset from a DEM and "
                    "write a scene file that renders as it is (Paris et al. 2019).")
    p.add_argument("dem", help="DEM file: .npy, 16-bit .png or GeoTIFF .tif")
    p.add_argument("-o", "--output", required=True, help="scene file to write (.toml)")
    p.add_argument("--cell-size", type=positive_float("--cell-size"), default=1.0,
                   help="metres between DEM samples (default 1)")
    p.add_argument("--height-scale", type=positive_float("--height-scale"), default=None,
                   help="multiply the heights (default 1; for PNG, a relief of 1/4 of the tile width)")
    p.add_argument("--preset", choices=sorted(PRESETS), default="sea",
                   help="landforms to generate (default sea): " +
                        "; ".join(f"{k}: {v.description}" for k, v in PRESETS.items()))
    p.add_argument("--seed", type=bounded_int("--seed", 0, 2 ** 31 - 1), default=0, help="random seed (default 0)")
    p.add_argument("--max-cells", type=bounded_int("--max-cells", 4, 16384 ** 2), default=MAX_CELLS,
                   help=f"larger DEMs are block-averaged down to this many cells (default {MAX_CELLS})")
    p.add_argument("--data-dir", default=None,
                   help="folder for the heights and primitive arrays, relative to the scene's folder "
                        "(default: beside the scene)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _geology(result, base, zhi):
    """The built geology node (the material's strata read it) and the rock's volume."""
    if "geology" not in result.tables:
        return None, None
    node = NodeBuilder({"geology": result.tables["geology"]}, Path("geology.toml"), Path(".")).named("geology")
    x0, y0, x1, y1 = result.extent
    return node, (np.array([x0, y0, base]), np.array([x1, y1, zhi]))


def _scene_doc(result, name):
    H, extent = result.heights, result.extent
    base = min(float(n.bounds()[0][2]) for n in result.root.walk() if n.kind == "implicit_heightfield")
    zlo, zhi = float(H.min()), float(H.max())
    cam = frame_camera(H, extent, result.focus, elevation=PRESETS[result.stats["preset"]].camera_elevation)
    x0, y0, x1, y1 = extent
    size = max(x1 - x0, y1 - y0)
    stats = result.stats
    doc = {
        "scene": {"name": name,
                  "description": f"DEM amplified with the '{stats['preset']}' preset (seed {stats['seed']}): "
                                 f"{stats['nodes']} nodes, {stats['primitives']} primitives"},
        "render": {"resolution": [640, 360], "spp": 32, "max_depth": 3},
        "camera": {"origin": cam["origin"], "target": cam["target"], "fov": cam["fov"]},
        "lights": [sun_for(cam)],
        "materials": {"landscape": landscape_material(zlo, zhi, result.sea_level, *_geology(result, base, zhi),
                                                      preset=stats["preset"], cell=stats["cell_size"])},
        # The far ground plane lies under the terrain's prism: inside the solid the implicit
        # field is constant (no gradient, no normal) and a surface there would shade as NaN.
        "meshes": [{"shape": "disk", "translate": [0.5 * (x0 + x1), 0.5 * (y0 + y1), base - 0.01 * (zhi - zlo) - 0.05],
                    "scale": 50.0 * size, "material": "landscape"}],
        "field": {"root": "world", "material": "landscape"},
        "nodes": result.tables,
    }
    if result.sea_level is not None:
        doc["materials"]["water"] = {"type": "diffuse", "color": [0.03, 0.09, 0.12]}
        doc["meshes"].append({"file": result.water_file, "material": "water"})
    return doc


def run(args) -> int:
    out = Path(args.output)
    if out.suffix.lower() != ".toml":
        raise UsageError(f"-o {out}: the scene file must end in .toml")
    writable_output(out)
    data_dir = Path(args.data_dir) if args.data_dir else Path(".")
    if data_dir.is_absolute() or ".." in data_dir.parts:
        raise UsageError(f"--data-dir {args.data_dir}: must be a folder inside the scene's folder")
    try:
        dem = read_dem(args.dem, max_samples=args.max_cells)
    except DEMError as exc:
        raise UsageError(f"{args.dem}: {exc}" if str(args.dem) not in str(exc) else str(exc)) from None
    H = dem.heights
    cell = args.cell_size * dem.step
    scale = args.height_scale
    if scale is None:
        scale = 0.25 * cell * (max(H.shape) - 1) if dem.normalised else 1.0
    H = H * scale
    for note in dem.notes:
        print(f"arches-render amplify: {args.dem}: {note}", flush=True)
    if min(H.shape) < 3:
        raise UsageError(f"{args.dem}: {H.shape[1]}x{H.shape[0]} samples; amplify needs at least 3x3")

    bar = Progress(f"amplify {args.preset}", "step", args.quiet)
    prefix = (data_dir / out.stem).as_posix()
    # The work folder's name carries this process's id: one left by a kill is swept by the next run.
    with temp_dir(out.parent, out.stem) as work:
        result = amplify(H, cell, args.preset, args.seed, work, prefix,
                         progress=lambda done, total, label: (bar.bar.set_postfix_str(label), bar(done, total)))
        bar.close()
        # Publish the data files (atomic renames within one folder tree), then the scene.
        for rel in result.files:
            dest = out.parent / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            os.replace(work / rel, dest)
        header = (f"Generated by: arches-render amplify {Path(args.dem).name} --preset {args.preset} "
                  f"--seed {args.seed} --cell-size {args.cell_size:g}\n"
                  f"Terrain amplification (Paris et al. 2019): {result.stats['nodes']} nodes, "
                  f"{result.stats['primitives']} primitives, {result.stats['memory_bytes'] / 1e6:.2f} MB")
        text = toml_text(_scene_doc(result, out.stem), header)
        with atomic_write(out, "w", encoding="utf-8") as f:
            f.write(text)
    bar.close()
    st = result.stats
    if "note" in st:
        print(f"arches-render amplify: {args.dem}: {st['note']}", flush=True)
    print(f"arches-render amplify: wrote {out} ({st['nodes']} nodes, {st['primitives']} primitives, "
          f"{st['memory_bytes'] / 1e6:.2f} MB; heights {H.shape[1]}x{H.shape[0]} at {cell:g} m)", flush=True)
    return 0
