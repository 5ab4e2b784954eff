"""UV atlases of polygonized fields, by xatlas.

xatlas segments the mesh into charts (limited normal deviation and chart
distortion), parameterizes every chart (least-squares conformal maps, then
ABF-style refinement) and packs them into one square texture with a padding of a
few texels, so that texture filtering at a chart border does not read its
neighbours. It splits vertices along chart seams: the atlas mesh has more
vertices than its input (``vmapping`` maps them back) and the same triangles.

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

__all__ = ["UVMesh", "uv_atlas"]


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


def uv_atlas(mesh: TriangleMesh, resolution: int = 1024, padding: int = 4) -> UVMesh:
    """Chart, parameterize and pack a mesh into one ``resolution``² atlas.

    Parameters
    ----------
    mesh : TriangleMesh
    resolution : int
        Requested atlas size in texels (xatlas may pack into a slightly
        different rectangle: see :attr:`UVMesh.width`, :attr:`UVMesh.height`).
    padding : int
        Texels between charts.

    Returns
    -------
    UVMesh

    References
    ----------
    xatlas (``Atlas.generate`` with ``PackOptions.resolution``, ``padding``).
    """
    import xatlas  # on use: only --uv needs it
    atlas = xatlas.Atlas()
    atlas.add_mesh(np.ascontiguousarray(mesh.vertices, np.float32), np.ascontiguousarray(mesh.faces, np.uint32),
                   np.ascontiguousarray(mesh.normals, np.float32))
    pack = xatlas.PackOptions()
    pack.resolution = int(resolution)
    pack.padding = int(padding)
    pack.bilinear = True
    atlas.generate(xatlas.ChartOptions(), pack)
    vmapping, faces, uvs = atlas[0]
    return UVMesh(vertices=mesh.vertices[vmapping], faces=faces.astype(np.uint32),
                  normals=mesh.normals[vmapping], uvs=uvs.astype(np.float32),
                  vmapping=vmapping.astype(np.int64), width=int(atlas.width), height=int(atlas.height))
