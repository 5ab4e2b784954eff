"""UV atlases of polygonized fields, by xatlas.

xatlas segments the mesh into charts (limited normal deviation and chart
distortion), parameterizes every chart (least-squares conformal maps, then
ABF-style refinement) and packs them into one square texture with a padding of a
few texels, so that texture filtering at a chart border does not read its
neighbours. It splits vertices along chart seams: the atlas mesh has more
vertices than its input (``vmapping`` maps them back) and the same triangles.

Pieces. Charting grows and merges charts over the whole mesh it is given, at a
cost that rises faster than the mesh: the default scene at a 2 m voxel (249k
triangles) took 130 s in one piece on one core, and 20, 6.7 and 4.1 s as the
pieces of :func:`~.chunks.polygonize_chunks` in chunks of 48, 24 and 16 cells.
:func:`uv_atlas` therefore takes a mesh *or its pieces*: xatlas charts each piece
on its own (its task scheduler spreads the pieces over the cores) and packs every
chart into the one texture. Chart boundaries then also run along the pieces'
seams (:data:`ATLAS_CHUNK_CELLS` keeps pieces large enough that these stay few).

References
----------
Young, J. (2018-). xatlas, https://github.com/jpcy/xatlas (after Castaño's
thekla_atlas). Lévy, B., Petitjean, S., Ray, N., Maillot, J. (2002). Least
squares conformal maps for automatic texture atlas generation. ACM TOG 21(3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .polygonize import TriangleMesh

__all__ = ["ATLAS_CHUNK_CELLS", "UVMesh", "uv_atlas"]

#: Cells along X and Y of the pieces a textured export is charted in (module docstring).
ATLAS_CHUNK_CELLS = 24


@dataclass
class UVMesh:
    """A mesh with a UV atlas: ``uvs (N, 2)`` in [0, 1], ``vmapping`` to the input vertices.

    ``width`` x ``height`` is the atlas size in texels that xatlas packed for
    (near the requested resolution; bake textures at this size).

    ``uvs`` follow the glTF/USD convention: ``v = 0`` is the *bottom* row of the image.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    vmapping: np.ndarray
    width: int
    height: int

    def to_trimesh(self, image=None):
        """A trimesh with UVs (and ``image`` as base colour texture, if given)."""
        import trimesh  # on use: slow to import, only export needs it
        from trimesh.visual import TextureVisuals
        from trimesh.visual.material import PBRMaterial
        mat = None
        if image is not None:
            from PIL import Image
            mat = PBRMaterial(baseColorTexture=Image.fromarray(image), metallicFactor=0.0, roughnessFactor=1.0)
        visual = TextureVisuals(uv=self.uvs, material=mat)
        return trimesh.Trimesh(self.vertices, self.faces, vertex_normals=self.normals, visual=visual,
                               process=False)


def uv_atlas(mesh, resolution: int = 1024, padding: int = 4) -> UVMesh:
    """Chart, parameterize and pack a mesh (or its pieces) into one ``resolution``² atlas.

    Parameters
    ----------
    mesh : TriangleMesh or sequence of TriangleMesh
        One mesh, or the pieces of one (charted each on its own, packed together;
        module docstring).
    resolution : int
        Requested atlas size in texels (xatlas may pack into a slightly
        different rectangle: see :attr:`UVMesh.width`, :attr:`UVMesh.height`).
    padding : int
        Texels between charts.

    Returns
    -------
    UVMesh
        The pieces' atlas meshes in order, as one mesh; ``vmapping`` indexes the
        pieces' vertices concatenated in that order.

    References
    ----------
    xatlas (``Atlas.generate`` with ``PackOptions.resolution``, ``padding``).
    """
    import xatlas  # on use: only --uv needs it
    pieces = [mesh] if isinstance(mesh, TriangleMesh) else list(mesh)
    atlas = xatlas.Atlas()
    for piece in pieces:
        atlas.add_mesh(np.ascontiguousarray(piece.vertices, np.float32),
                       np.ascontiguousarray(piece.faces, np.uint32),
                       np.ascontiguousarray(piece.normals, np.float32))
    pack = xatlas.PackOptions()
    pack.resolution = int(resolution)
    pack.padding = int(padding)
    pack.bilinear = True
    atlas.generate(xatlas.ChartOptions(), pack)
    parts, seen, first = [], 0, 0
    for k, piece in enumerate(pieces):
        vmapping, faces, uvs = atlas[k]
        parts.append((piece.vertices[vmapping], faces.astype(np.int64) + first, piece.normals[vmapping],
                      uvs.astype(np.float32), vmapping.astype(np.int64) + seen))
        seen += len(piece.vertices)
        first += len(vmapping)
    vertices, faces, normals, uvs, vmap = (np.concatenate(x) for x in zip(*parts))
    return UVMesh(vertices=vertices, faces=faces.astype(np.uint32), normals=normals, uvs=uvs, vmapping=vmap,
                  width=int(atlas.width), height=int(atlas.height))
