"""Export of UV-mapped meshes with baked textures: glTF binary, OBJ + MTL, PLY.

* ``.glb``: one file; the albedo is the PBR base colour texture (sRGB),
  metallic 0, roughness 1 (the material is diffuse); the normal map is written
  beside as ``STEM_normal.png`` (world-space normals, see
  :mod:`arches_render.mesh.bake`), since glTF's ``normalTexture`` is tangent-space.
* ``.obj``: ``STEM.obj``, ``STEM.mtl`` (``map_Kd STEM_albedo.png``) and the PNGs.
* ``.ply``: positions, normals, UVs (``s``, ``t``) and the albedo sampled at each
  vertex as vertex colours; the PNGs beside.

Every file is written atomically. Blender, Houdini and other DCCs import all three
(glTF 2.0 base colour, OBJ ``map_Kd``).

References
----------
Khronos Group (2021). glTF 2.0 specification, section 3.9 (materials).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..atomic import atomic_write
from ..imaging.preview import write_png
from .bake import BakedTextures
from .uv_atlas import UVMesh

__all__ = ["export_textured", "TEXTURED_FORMATS"]

TEXTURED_FORMATS = ("glb", "obj", "ply")


def _vertex_colours(mesh: UVMesh, image: np.ndarray) -> np.ndarray:
    h, w = image.shape[:2]
    x = np.clip((mesh.uvs[:, 0] * w).astype(int), 0, w - 1)
    y = np.clip(((1.0 - mesh.uvs[:, 1]) * h).astype(int), 0, h - 1)
    rgb = image[y, x]
    return np.concatenate([rgb, np.full((len(rgb), 1), 255, np.uint8)], axis=1)


def export_textured(mesh: UVMesh, textures: BakedTextures | None, path) -> list[Path]:
    """Write a UV-mapped mesh and its baked textures (format from the extension).

    Parameters
    ----------
    mesh : UVMesh
    textures : BakedTextures or None
        Baked albedo/normal (``None``: UVs only).
    path : str or Path
        ``.glb``, ``.obj`` or ``.ply``.

    Returns
    -------
    list of pathlib.Path
        Every file written (the mesh first).

    Raises
    ------
    ValueError
        For another extension.
    """
    import trimesh  # on use: slow to import, only mesh export needs it
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in TEXTURED_FORMATS:
        raise ValueError(f"{path}: unsupported textured mesh format '.{fmt}' (use .glb, .obj or .ply)")
    written = [path]
    extra = []
    if textures is not None:
        extra.append((path.with_name(f"{path.stem}_normal.png"), textures.normal))
        if fmt != "glb":
            extra.append((path.with_name(f"{path.stem}_albedo.png"), textures.albedo))
    if fmt == "glb":
        data = mesh.to_trimesh(None if textures is None else textures.albedo).export(file_type="glb")
    elif fmt == "obj":
        tm = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_normals=mesh.normals, process=False,
                             visual=trimesh.visual.TextureVisuals(uv=mesh.uvs))
        text = trimesh.exchange.obj.export_obj(tm, include_normals=True, include_texture=True,
                                               write_texture=False, mtl_name=f"{path.stem}.mtl")
        if isinstance(text, tuple):
            text = text[0]
        body = "\n".join(line for line in text.splitlines() if not line.startswith("mtllib"))
        data = (f"mtllib {path.stem}.mtl\nusemtl baked\n" + body + "\n").encode()
        mtl = path.with_name(f"{path.stem}.mtl")
        with atomic_write(mtl, "w") as f:
            f.write("newmtl baked\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nillum 1\n"
                    + (f"map_Kd {path.stem}_albedo.png\n" if textures is not None else ""))
        written.append(mtl)
    else:
        colours = None if textures is None else _vertex_colours(mesh, textures.albedo)
        tm = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_normals=mesh.normals, process=False,
                             vertex_colors=colours)
        tm.vertex_attributes["s"] = mesh.uvs[:, 0].astype(np.float32)
        tm.vertex_attributes["t"] = mesh.uvs[:, 1].astype(np.float32)
        data = tm.export(file_type="ply", include_attributes=True)
    with atomic_write(path) as f:
        f.write(data if isinstance(data, bytes) else data.encode())
    for p, img in extra:
        write_png(p, img)
        written.append(p)
    return written
