"""``arches-render mesh SCENE -o OUT``: polygonize the scene's field and export it.

``OUT`` is a mesh (``.ply``, ``.obj``, ``.glb``; ``--uv`` adds an xatlas UV atlas,
``--bake`` bakes the field's material into albedo and normal textures) or a USD
stage (``.usd``, ``.usda``, ``.usdc``: terrain chunks of ``--chunk-cells`` voxels,
the scene's meshes and scene-table items as point instancers, materials).

A textured mesh is polygonized in chunks (``--chunk-cells``, default
:data:`~arches_render.mesh.uv_atlas.ATLAS_CHUNK_CELLS`) whose pieces xatlas charts
each on its own, over the cores, into one atlas (:mod:`~arches_render.mesh.uv_atlas`:
the default scene at ``--voxel 2``, 249k triangles, 130 s in one piece on one core).
"""

from __future__ import annotations

from pathlib import Path

from ..imaging.preview import write_png
from ..mesh.bake import bake_material
from ..mesh.chunks import polygonize_chunks
from ..mesh.polygonize import export_mesh, polygonize
from ..mesh.textured import export_textured
from ..mesh.usd_export import write_usd_stage
from ..mesh.uv_atlas import ATLAS_CHUNK_CELLS, uv_atlas
from ..render.renderer import load_materials
from ..scene import load_scene
from . import (Progress, UsageError, bounded_int, check_render_memory, positive_float, scene_argument,
               voxel_errors, writable_output)

MESH_FORMATS = (".ply", ".obj", ".glb", ".usd", ".usda", ".usdc")


def register(subparsers) -> None:
    m = subparsers.add_parser("mesh", help="polygonize the scene's field (marching cubes)")
    scene_argument(m)
    m.add_argument("-o", "--output", required=True,
                   help="output mesh (.ply, .obj, .glb) or USD stage (.usd, .usda, .usdc: terrain chunks, "
                        "mesh instances as point instancers, materials)")
    m.add_argument("--voxel", type=positive_float("--voxel"), help="voxel size in metres")
    m.add_argument("--uv", action="store_true", help="add a UV atlas (xatlas)")
    m.add_argument("--bake", action="store_true",
                   help="bake the field's material into albedo and normal textures (implies --uv)")
    m.add_argument("--texture-size", type=bounded_int("--texture-size", 16, 16384), default=1024,
                   help="atlas size in texels (default 1024)")
    m.add_argument("--chunk-cells", type=bounded_int("--chunk-cells", 8, 4096), default=None,
                   help="voxels per chunk along X and Y: USD terrain chunks (default 128), pieces of a "
                        f"textured mesh's atlas (default {ATLAS_CHUNK_CELLS})")
    m.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    m.set_defaults(func=run)


def run(args) -> int:
    desc = load_scene(args.scene)
    if desc.field is None:
        raise UsageError(f"{args.scene}: field: the scene has no [field] to polygonize")
    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in MESH_FORMATS:
        raise UsageError(f"-o/--output must end in .ply, .obj or .glb (a mesh) or .usd, .usda or .usdc "
                         f"(a USD stage) (got {out})")
    writable_output(out)
    check_render_memory(desc, 0, 0, False, "mesh", args.voxel)
    uv = args.uv or args.bake
    voxel = args.voxel or desc.render.voxel or None
    bsdf = None
    if args.bake:
        bsdf = load_materials(desc)[desc.field_material]

    def textured(tri, bar, done=0, total=None):
        # Atlas, then bake: two steps of ``bar`` (``total`` over several meshes).
        steps = 2 if args.bake else 1
        total = total or steps
        mesh = uv_atlas(tri, args.texture_size)
        bar(done + 1, total)
        tex = bake_material(mesh, bsdf, desc.field) if args.bake else None
        bar(done + steps, total)
        return mesh, tex

    if suffix in (".usd", ".usda", ".usdc"):
        bar = Progress("polygonize", "chunk", args.quiet)
        with voxel_errors(args, desc):
            chunks = polygonize_chunks(desc.field, voxel, args.chunk_cells or 128, bar)
        bar.close()
        pieces, textures = [], {}
        bar = Progress("atlas and bake" if args.bake else "atlas", "step", args.quiet or not uv)
        steps = 2 if args.bake else 1
        for k, c in enumerate(chunks):
            name = f"chunk_{c.index[0]}_{c.index[1]}"
            mesh, tex = textured(c.mesh, bar, k * steps, len(chunks) * steps) if uv else (c.mesh, None)
            if tex is not None:
                png = out.with_name(f"{out.stem}_{name}_albedo.png")
                write_png(png, tex.albedo)
                write_png(out.with_name(f"{out.stem}_{name}_normal.png"), tex.normal)
                textures[name] = png.name
            pieces.append((name, mesh))
        bar.close()
        write_usd_stage(out, pieces, desc, textures)
        nv = sum(len(m.vertices) for _, m in pieces)
        nf = sum(len(m.faces) for _, m in pieces)
        print(f"wrote {out} ({len(pieces)} terrain chunks, {nv} vertices, {nf} triangles, "
              f"{len(desc.meshes)} mesh instances)")
        return 0
    if uv:
        bar = Progress("polygonize", "chunk", args.quiet)
        with voxel_errors(args, desc):
            chunks = polygonize_chunks(desc.field, voxel, args.chunk_cells or ATLAS_CHUNK_CELLS, bar)
        pieces = [c.mesh for c in chunks]
        bar.close()
        bar = Progress("atlas and bake" if args.bake else "atlas", "step", args.quiet)
        bar(0, 2 if args.bake else 1)
        mesh, tex = textured(pieces, bar)
        bar.close()
        files = export_textured(mesh, tex, out)
        print(f"wrote {', '.join(map(str, files))} ({len(mesh.vertices)} vertices, {len(mesh.faces)} triangles, "
              f"{mesh.width}x{mesh.height} atlas)")
        return 0
    bar = Progress("polygonize", "slab", args.quiet)
    with voxel_errors(args, desc):
        tri = polygonize(desc.field, voxel, bar)
    bar.close()
    export_mesh(tri, out)
    print(f"wrote {out} ({len(tri.vertices)} vertices, {len(tri.faces)} triangles)")
    return 0
