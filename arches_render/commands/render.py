"""``arches-render render SCENE``: an EXR (beauty and AOV layers) and a PNG preview beside it.

Options override the scene's ``[render]`` table (see the README's command list):
``-o`` (default ``out/SCENE.exr``), ``--spp``, ``--resolution``, ``--seed``,
``--camera NAME``, ``--geometry field|mesh``, ``--passes``, ``--voxel``, ``--no-aovs``, ``--denoise``,
``--view``, ``--tiles``, ``--workers``/``--scheduler`` (Dask) and ``-q``. A progress
bar on stderr counts the sample passes (or tiles).
"""

from __future__ import annotations

import time
from pathlib import Path

from ..imaging.colour import VIEWS, view_to_uint8
from ..imaging.exposure import exposure_of
from ..imaging.preview import write_png
from ..render.denoise import denoise
from ..render.distributed import dask_client, render_tiled
from ..render.jobs import RenderJob, job_clip, prime_cache, run_job, sensor_clip
from ..render.output import render_header, write_render
from ..render.renderer import build_scene, load_materials
from ..scene import load_scene
from . import (Progress, UsageError, bounded_int, check_render_memory, output_file, positive_float,
               resolution, scene_argument, voxel_errors, writable_output)


def register(subparsers) -> None:
    r = subparsers.add_parser("render", help="render a scene to an EXR (beauty + AOV layers) and a PNG preview")
    scene_argument(r)
    r.add_argument("-o", "--output", help="output EXR (default out/SCENE.exr); the PNG goes beside it")
    r.add_argument("--spp", type=bounded_int("--spp", 1, 1 << 20), help="samples per pixel")
    r.add_argument("--resolution", type=resolution, help="WxH, e.g. 640x360")
    r.add_argument("--seed", type=bounded_int("--seed", 0, 2 ** 31 - 1), help="sampler seed")
    r.add_argument("--camera", metavar="NAME", help="render through the scene's camera NAME "
                                                    "([cameras.NAME]; default: the first camera)")
    r.add_argument("--geometry", choices=("field", "mesh"),
                   help="sphere-trace the field (default) or render its marching-cubes mesh")
    r.add_argument("--passes", type=bounded_int("--passes", 1, 4096), help="sample passes")
    r.add_argument("--voxel", type=positive_float("--voxel"), help="mesh mode voxel size (m)")
    r.add_argument("--no-aovs", dest="aovs", action="store_false",
                   help="beauty only: no albedo/normal/depth/position/coverage/layers AOV layers")
    r.add_argument("--denoise", action="store_true",
                   help="add an OIDN-denoised 'denoised' layer (the raw beauty stays); the PNG shows it")
    r.add_argument("--view", help="view transform of the PNG: srgb (default), aces, aces-p3, untonemapped")
    r.add_argument("--tiles", type=bounded_int("--tiles", 1, 4096),
                   help="render as about N image tiles (each its own sample stream)")
    rg = r.add_mutually_exclusive_group()
    rg.add_argument("--workers", type=bounded_int("--workers", 1, 1024),
                    help="render the tiles on a Dask LocalCluster of N worker processes")
    rg.add_argument("--scheduler", metavar="ADDRESS", help="render the tiles on a running Dask cluster")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=run)


def run(args) -> int:
    out = output_file(args.output, ".exr") if args.output else Path("out") / f"{Path(args.scene).stem}.exr"
    writable_output(out, create=args.output is None)
    desc = load_scene(args.scene)
    cam = desc.select_camera(args.camera)
    s = desc.render
    view = args.view or s.view
    if view not in VIEWS:
        raise UsageError(f"--view must be one of {', '.join(VIEWS)} (got {view!r})")
    want_denoised = args.denoise or s.denoise
    spp = args.spp or s.spp
    seed = s.seed if args.seed is None else args.seed
    width, height = args.resolution or (s.width, s.height)
    geometry = args.geometry or s.geometry
    aovs = args.aovs or want_denoised
    tiles = args.tiles or (0 if not (args.scheduler or args.workers) else 4)
    if tiles and geometry == "mesh":
        raise UsageError("--tiles/--workers/--scheduler render the field; drop --geometry mesh")
    check_render_memory(desc, width, height, aovs, geometry, args.voxel)

    t0 = time.perf_counter()
    job = RenderJob(scene=str(Path(args.scene).resolve()), width=width, height=height, spp=spp, seed=seed,
                    passes=args.passes or s.passes, geometry=geometry, aovs=aovs, voxel=args.voxel or 0.0,
                    camera=(tuple(cam.origin), tuple(cam.target), tuple(cam.up), cam.fov))
    if tiles:
        bar = Progress(f"render {desc.name}", "tile", args.quiet)
        if args.scheduler or args.workers:
            with dask_client(args.scheduler, args.workers) as client:
                img, layers = render_tiled(job, tiles, client, bar)
        else:
            img, layers = render_tiled(job, tiles, None, bar)
        clip = job_clip(job)  # the tiles' sensors were built elsewhere, or cropped
    else:
        # Build here from the scene already loaded (generators run once; mesh mode
        # polygonizes with a bar); the job then finds the scene built.
        poly = Progress("polygonize", "slab", args.quiet) if geometry == "mesh" and desc.field else None
        bsdfs = load_materials(desc)
        with voxel_errors(args, desc):
            scene = build_scene(desc, geometry, width, height, args.voxel, progress=poly, aovs=aovs, bsdfs=bsdfs)
        if poly:
            poly.close()
        prime_cache(job, desc, scene, bsdfs)
        bar = Progress(f"render {desc.name}", "spp", args.quiet)
        img, layers = run_job(job, bar)
        clip = sensor_clip(scene)
    bar.close()
    denoised = None
    if want_denoised:
        denoised = denoise(img, layers["albedo"][0], layers["normal"][0])
    elapsed = time.perf_counter() - t0
    shown = img if denoised is None else denoised
    exposure, metered = exposure_of(s, shown)
    header = render_header(desc.name, args.scene, seed, spp, width, height, geometry,
                           (cam.origin, cam.target, cam.up, cam.fov), tiles=tiles)
    header.update(exposure=f"{exposure:.3f}", exposure_metered=str(metered).lower(), view=view)
    write_render(out, img, layers, header, denoised, clip=clip)
    png = out.with_suffix(".png")
    write_png(png, view_to_uint8(shown, view, exposure))
    print(f"wrote {out} and {png} ({width}x{height}, {spp} spp, {geometry}, {elapsed:.1f} s)")
    return 0
