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
    from .imaging.exr import write_exr
    from .imaging.preview import write_png
    from .render.renderer import build_scene, render_image
    from .scene import load_scene

    desc = load_scene(args.scene)
    out = Path(args.output) if args.output else Path("out") / f"{Path(args.scene).stem}.exr"
    if out.suffix.lower() != ".exr":
        raise UsageError(f"-o/--output must end in .exr (got {out})")
    out.parent.mkdir(parents=True, exist_ok=True)
    s = desc.render
    spp = args.spp or s.spp
    seed = s.seed if args.seed is None else args.seed
    width, height = args.resolution or (s.width, s.height)
    geometry = args.geometry or s.geometry

    t0 = time.perf_counter()
    poly = Progress("polygonize", "slab", args.quiet) if geometry == "mesh" and desc.field else None
    scene = build_scene(desc, geometry, width, height, args.voxel, progress=poly)
    if poly:
        poly.close()
    bar = Progress(f"render {desc.name}", "spp", args.quiet)
    img = render_image(scene, spp, seed, args.passes or s.passes, bar)
    bar.close()
    elapsed = time.perf_counter() - t0
    cam = desc.camera
    header = {"arches_render_version": __version__, "scene_name": desc.name,
              "scene_file": str(args.scene), "seed": str(seed), "spp": str(spp),
              "geometry": geometry, "camera_origin": " ".join(f"{v:g}" for v in cam.origin),
              "camera_target": " ".join(f"{v:g}" for v in cam.target), "camera_fov": f"{cam.fov:g}"}
    write_exr(out, img, header=header)
    png = out.with_suffix(".png")
    write_png(png, img, exposure=s.exposure)
    print(f"wrote {out} and {png} ({width}x{height}, {spp} spp, {geometry}, {elapsed:.1f} s)")
    return EXIT_OK


def cmd_mesh(args) -> int:
    from .mesh.polygonize import export_mesh, polygonize
    from .scene import load_scene

    desc = load_scene(args.scene)
    if desc.field is None:
        raise UsageError(f"{args.scene}: field: the scene has no [field] to polygonize")
    out = Path(args.output)
    if out.suffix.lower() not in (".ply", ".obj", ".glb"):
        raise UsageError(f"-o/--output must end in .ply, .obj or .glb (got {out})")
    out.parent.mkdir(parents=True, exist_ok=True)
    bar = Progress("polygonize", "slab", args.quiet)
    tri = polygonize(desc.field, args.voxel or desc.render.voxel or None, bar)
    bar.close()
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

    r = sub.add_parser("render", help="render a scene to a half-float EXR and a PNG preview")
    r.add_argument("scene", help="scene file (.toml)")
    r.add_argument("-o", "--output", help="output EXR (default out/SCENE.exr); the PNG goes beside it")
    r.add_argument("--spp", type=bounded_int("--spp", 1, 1 << 20), help="samples per pixel")
    r.add_argument("--resolution", type=resolution, help="WxH, e.g. 640x360")
    r.add_argument("--seed", type=bounded_int("--seed", 0, 2 ** 31 - 1), help="sampler seed")
    r.add_argument("--geometry", choices=("field", "mesh"),
                   help="sphere-trace the field (default) or render its marching-cubes mesh")
    r.add_argument("--passes", type=bounded_int("--passes", 1, 4096), help="sample passes")
    r.add_argument("--voxel", type=positive_float("--voxel"), help="mesh mode voxel size (m)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=cmd_render)

    m = sub.add_parser("mesh", help="polygonize the scene's field (marching cubes)")
    m.add_argument("scene", help="scene file (.toml)")
    m.add_argument("-o", "--output", required=True, help="output mesh (.ply, .obj or .glb)")
    m.add_argument("--voxel", type=positive_float("--voxel"), help="voxel size in metres")
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
