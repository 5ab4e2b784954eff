"""``arches-render``: render, polygonize and inspect scene files.

The CLI is thin: it parses arguments, calls the library, and reports. Bad input
(scene files, arguments) exits with status 2 and one line naming the file, key and
allowed range; no traceback reaches the user for an error of theirs.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from . import __version__
from .commands import Progress, UsageError, bounded_int, discover, positive_float, resolution

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2


def cmd_render(args) -> int:
    from .imaging.colour import VIEWS, view_to_uint8
    from .imaging.preview import write_png
    from .render.jobs import RenderJob, run_job
    from .render.output import render_header, write_render
    from .scene import load_scene

    desc = load_scene(args.scene)
    out = Path(args.output) if args.output else Path("out") / f"{Path(args.scene).stem}.exr"
    if out.suffix.lower() != ".exr":
        raise UsageError(f"-o/--output must end in .exr (got {out})")
    view = args.view or "srgb"
    if view not in VIEWS:
        raise UsageError(f"--view must be one of {', '.join(VIEWS)} (got {view!r})")
    out.parent.mkdir(parents=True, exist_ok=True)
    s = desc.render
    spp = args.spp or s.spp
    seed = s.seed if args.seed is None else args.seed
    width, height = args.resolution or (s.width, s.height)
    geometry = args.geometry or s.geometry
    aovs = args.aovs or args.denoise
    tiles = args.tiles or (0 if not (args.scheduler or args.workers) else 4)
    if tiles and geometry == "mesh":
        raise UsageError("--tiles/--workers/--scheduler render the field; drop --geometry mesh")

    t0 = time.perf_counter()
    job = RenderJob(scene=str(Path(args.scene).resolve()), width=width, height=height, spp=spp, seed=seed,
                    passes=args.passes or s.passes, geometry=geometry, aovs=aovs, voxel=args.voxel or 0.0)
    if tiles:
        from .render.distributed import dask_client, render_tiled
        bar = Progress(f"render {desc.name}", "tile", args.quiet)
        if args.scheduler or args.workers:
            with dask_client(args.scheduler, args.workers) as client:
                img, layers = render_tiled(job, tiles, client, bar)
        else:
            img, layers = render_tiled(job, tiles, None, bar)
    else:
        # Build here from the scene already loaded (generators run once; mesh mode
        # polygonizes with a bar); the job then finds the scene built.
        from .render import jobs
        from .render.renderer import build_scene
        poly = Progress("polygonize", "slab", args.quiet) if geometry == "mesh" and desc.field else None
        scene = build_scene(desc, geometry, width, height, args.voxel, progress=poly, aovs=aovs)
        if poly:
            poly.close()
        jobs.prime_cache(job, desc, scene)
        bar = Progress(f"render {desc.name}", "spp", args.quiet)
        img, layers = run_job(job, bar)
    bar.close()
    denoised = None
    if args.denoise:
        from .render.denoise import denoise
        denoised = denoise(img, layers["albedo"][0], layers["normal"][0])
    elapsed = time.perf_counter() - t0
    cam = desc.camera
    header = render_header(desc.name, args.scene, seed, spp, width, height, geometry,
                           (cam.origin, cam.target, cam.up, cam.fov), tiles=tiles)
    write_render(out, img, layers, header, denoised)
    png = out.with_suffix(".png")
    write_png(png, view_to_uint8(img if denoised is None else denoised, view, s.exposure))
    print(f"wrote {out} and {png} ({width}x{height}, {spp} spp, {geometry}, {elapsed:.1f} s)")
    return EXIT_OK


MESH_FORMATS = (".ply", ".obj", ".glb", ".usd", ".usda", ".usdc")


def cmd_mesh(args) -> int:
    from .mesh.polygonize import export_mesh, polygonize
    from .scene import load_scene

    desc = load_scene(args.scene)
    if desc.field is None:
        raise UsageError(f"{args.scene}: field: the scene has no [field] to polygonize")
    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in MESH_FORMATS:
        raise UsageError(f"-o/--output must end in .ply, .obj or .glb (a mesh) or .usd, .usda or .usdc "
                         f"(a USD stage) (got {out})")
    out.parent.mkdir(parents=True, exist_ok=True)
    uv = args.uv or args.bake
    voxel = args.voxel or desc.render.voxel or None
    bsdf = None
    if args.bake:
        from .render.renderer import load_materials
        bsdf = load_materials(desc)[desc.field_material]

    def textured(tri, stem):
        from .mesh.bake import bake_material
        from .mesh.uv_atlas import uv_atlas
        mesh = uv_atlas(tri, args.texture_size)
        return mesh, (bake_material(mesh, bsdf, desc.field) if args.bake else None)

    if suffix in (".usd", ".usda", ".usdc"):
        from .imaging.preview import write_png
        from .mesh.chunks import polygonize_chunks
        from .mesh.usd_export import write_usd_stage
        bar = Progress("polygonize", "chunk", args.quiet)
        chunks = polygonize_chunks(desc.field, voxel, args.chunk_cells, bar)
        bar.close()
        pieces, textures = [], {}
        for c in chunks:
            name = f"chunk_{c.index[0]}_{c.index[1]}"
            mesh, tex = textured(c.mesh, name) if uv else (c.mesh, None)
            if tex is not None:
                png = out.with_name(f"{out.stem}_{name}_albedo.png")
                write_png(png, tex.albedo)
                write_png(out.with_name(f"{out.stem}_{name}_normal.png"), tex.normal)
                textures[name] = png.name
            pieces.append((name, mesh))
        write_usd_stage(out, pieces, desc, textures)
        nv = sum(len(m.vertices) for _, m in pieces)
        nf = sum(len(m.faces) for _, m in pieces)
        print(f"wrote {out} ({len(pieces)} terrain chunks, {nv} vertices, {nf} triangles, "
              f"{len(desc.meshes)} mesh instances)")
        return EXIT_OK
    bar = Progress("polygonize", "slab", args.quiet)
    tri = polygonize(desc.field, voxel, bar)
    bar.close()
    if uv:
        from .mesh.textured import export_textured
        mesh, tex = textured(tri, out.stem)
        files = export_textured(mesh, tex, out)
        print(f"wrote {', '.join(map(str, files))} ({len(mesh.vertices)} vertices, {len(mesh.faces)} triangles, "
              f"{mesh.width}x{mesh.height} atlas)")
        return EXIT_OK
    export_mesh(tri, out)
    print(f"wrote {out} ({len(tri.vertices)} vertices, {len(tri.faces)} triangles)")
    return EXIT_OK


def cmd_info(args) -> int:
    from collections import Counter

    from .scene import load_scene

    desc = load_scene(args.scene)
    print(f"scene      {desc.name}  ({args.scene})")
    if desc.description:
        print(f"           {desc.description}")
    s = desc.render
    print(f"render     {s.width}x{s.height}, {s.spp} spp, seed {s.seed}, geometry {s.geometry}, "
          f"max_depth {s.max_depth}")
    print(f"lights     {', '.join(l['type'] for l in desc.lights)}")
    print(f"materials  {', '.join(desc.materials)}")
    print(f"meshes     {len(desc.meshes)}")
    if desc.atmosphere is not None:
        a = desc.atmosphere
        haze = f", haze {a.haze_density:g} /m over {a.haze_height:g} m" if a.haze_density > 0 else ""
        print(f"atmosphere turbidity {a.turbidity:g}, density x{a.density:g}{haze}")
    if desc.field is None:
        print("field      none")
        return EXIT_OK
    f = desc.field
    lo, hi = f.bounds()
    kinds = Counter(n.kind for n in f.walk())
    print(f"field      {f.count()} nodes ({', '.join(f'{k} {v}' for k, v in sorted(kinds.items()))})")
    print(f"bounds     [{lo[0]:.2f}, {lo[1]:.2f}, {lo[2]:.2f}] .. [{hi[0]:.2f}, {hi[1]:.2f}, {hi[2]:.2f}] m")
    print(f"lipschitz  {f.lipschitz:.3f}")
    print(f"memory     {f.tree_nbytes() / 1024:.1f} KiB")
    print(f"material   {desc.field_material}")
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="arches-render", description=__doc__.splitlines()[0])
    p.add_argument("--version", action="version", version=f"arches-render {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="SUBCOMMAND")

    r = sub.add_parser("render", help="render a scene to an EXR (beauty + AOV layers) and a PNG preview")
    r.add_argument("scene", help="scene file (.toml)")
    r.add_argument("-o", "--output", help="output EXR (default out/SCENE.exr); the PNG goes beside it")
    r.add_argument("--spp", type=bounded_int("--spp", 1, 1 << 20), help="samples per pixel")
    r.add_argument("--resolution", type=resolution, help="WxH, e.g. 640x360")
    r.add_argument("--seed", type=bounded_int("--seed", 0, 2 ** 31 - 1), help="sampler seed")
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
    r.set_defaults(func=cmd_render)

    m = sub.add_parser("mesh", help="polygonize the scene's field (marching cubes)")
    m.add_argument("scene", help="scene file (.toml)")
    m.add_argument("-o", "--output", required=True,
                   help="output mesh (.ply, .obj, .glb) or USD stage (.usd, .usda, .usdc: terrain chunks, "
                        "mesh instances as point instancers, materials)")
    m.add_argument("--voxel", type=positive_float("--voxel"), help="voxel size in metres")
    m.add_argument("--uv", action="store_true", help="add a UV atlas (xatlas)")
    m.add_argument("--bake", action="store_true",
                   help="bake the field's material into albedo and normal textures (implies --uv)")
    m.add_argument("--texture-size", type=bounded_int("--texture-size", 16, 16384), default=1024,
                   help="atlas size in texels (default 1024)")
    m.add_argument("--chunk-cells", type=bounded_int("--chunk-cells", 8, 4096), default=128,
                   help="USD output: voxels per terrain chunk along X and Y (default 128)")
    m.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    m.set_defaults(func=cmd_mesh)

    i = sub.add_parser("info", help="print the scene's field: node count, bounds, memory")
    i.add_argument("scene", help="scene file (.toml)")
    i.set_defaults(func=cmd_info)

    for module in discover():
        module.register(sub)
    return p


def main(argv=None) -> int:
    """Entry point of the ``arches-render`` console script."""
    args = build_parser().parse_args(argv)
    from .backend import BackendError, set_variant
    from .scene import SceneError
    try:
        set_variant()
        return args.func(args)
    except (SceneError, UsageError) as exc:
        print(f"arches-render: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except BackendError as exc:
        print(f"arches-render: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print("arches-render: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
