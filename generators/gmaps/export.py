"""Triangulated meshes of a 3-G-map's volumes, one material per volume (trimesh).

Each volume (⟨α0, α1, α2⟩ orbit) becomes a closed, outward-oriented triangle mesh:
its faces are ear-clipped (:func:`geometry.triangulate_polygon`, holed faces
included) and vertices are shared through the map's vertex ids, so a volume
whose map is closed gives a watertight mesh. Writers are atomic
(:mod:`arches_render.atomic`): a folder of PLY files plus ``manifest.json``
(written last), or one glTF binary (``.glb``) holding a mesh and a PBR material
per volume.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from arches_render.atomic import atomic_path, atomic_write

from .geometry import face_triangles, oriented_faces
from .gmap import GMap

#: Base colours (linear RGB) of the glTF materials, from the triplanar presets' tints.
MATERIAL_COLOURS = {"sandstone": (0.55, 0.27, 0.14), "limestone": (0.62, 0.60, 0.55),
                    "basalt": (0.12, 0.12, 0.13)}


def volume_meshes(g: GMap, materials: dict | None = None):
    """One trimesh per volume.

    Returns
    -------
    list of (label, part, material, trimesh.Trimesh)
        ``part`` numbers the connected volumes sharing a label (0 unless the
        volume was pinched in two).
    """
    import trimesh
    out, parts = [], {}
    for label, faces in oriented_faces(g):
        tris, _ = face_triangles(g, faces)
        used, inv = np.unique(tris, return_inverse=True)
        mesh = trimesh.Trimesh(g.points[used], inv.reshape(-1, 3), process=False)
        part = parts.get(label, 0)
        parts[label] = part + 1
        mat = (materials or {}).get(label, "default")
        out.append((label, part, mat, mesh))
    return out


def write_ply_folder(g: GMap, folder, materials: dict | None = None, meta: dict | None = None) -> list[Path]:
    """Write ``volume_<label>[_<part>].ply`` per volume and ``manifest.json`` (last).

    The manifest lists ``{"file", "label", "material", "faces", "watertight"}``
    per volume, plus ``meta``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    entries, paths = [], []
    for label, part, mat, mesh in volume_meshes(g, materials):
        name = f"volume_{label}" + (f"_{part}" if part else "") + ".ply"
        with atomic_path(folder / name) as tmp:
            mesh.export(tmp, file_type="ply")
        paths.append(folder / name)
        entries.append({"file": name, "label": int(label), "material": mat, "faces": int(len(mesh.faces)),
                        "watertight": bool(mesh.is_watertight)})
    doc = dict(meta or {}, volumes=entries)
    with atomic_write(folder / "manifest.json", "w", encoding="utf-8") as f:
        json.dump(doc, f, indent=1)
    paths.append(folder / "manifest.json")
    return paths


def write_gltf(g: GMap, path, materials: dict | None = None) -> Path:
    """Write all volumes to one ``.glb``/``.gltf`` scene, a PBR material per volume."""
    import trimesh
    path = Path(path)
    scene = trimesh.Scene()
    for label, part, mat, mesh in volume_meshes(g, materials):
        colour = MATERIAL_COLOURS.get(mat, (0.5, 0.5, 0.5))
        pbr = trimesh.visual.material.PBRMaterial(name=mat, baseColorFactor=[*colour, 1.0],
                                                  roughnessFactor=0.8, metallicFactor=0.0)
        m = mesh.copy()
        m.visual = trimesh.visual.TextureVisuals(material=pbr)
        scene.add_geometry(m, node_name=f"volume_{label}" + (f"_{part}" if part else ""),
                           geom_name=f"volume_{label}" + (f"_{part}" if part else ""))
    with atomic_path(path) as tmp:
        scene.export(tmp, file_type=path.suffix.lower()[1:])
    return path
