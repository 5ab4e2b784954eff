"""USD stages for layout in Houdini, Blender or Omniverse (usd-core).

Stage layout (Z-up, metres: ``upAxis = Z``, ``metersPerUnit = 1``)::

    /World
      /Terrain                  Xform
        /chunk_X_Y              Mesh (points, normals, faceVertex*, primvars:st)
      /Instances
        /<file stem>            PointInstancer: positions, orientations, scales,
          /Prototypes/proto     the mesh file's geometry, once
        /shape_<i>              analytic shapes (sphere, cube, rectangle, disk)
      /Materials
        /<name>                 UsdPreviewSurface: baked albedo texture (UsdUVTexture
                                on primvars:st) or the material's mean colour

Instances of one mesh file become one ``PointInstancer`` (its transforms are
decomposed into translation, rotation quaternion and scale): thousands of rocks
or blocks cost one prototype. An item of a generator's scene table (a
``[[rock_piles]]`` entry: the stones of its tile set as prototypes) becomes one
``PointInstancer`` from its ``point_instancer()`` data. Terrain chunks come from
:mod:`arches_render.mesh.chunks` with welded seams. The stage is written to a
temporary file and renamed; ``.usd``/``.usdc`` are binary (crate), ``.usda`` text.

References
----------
Pixar (2016-). Universal Scene Description: ``UsdGeom.Mesh``,
``UsdGeom.PointInstancer``, ``UsdShade`` with ``UsdPreviewSurface``,
https://openusd.org/release/spec_usdpreviewsurface.html
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..atomic import atomic_path

# pxr (usd-core), trimesh and scipy are imported inside the functions that use
# them: they load slowly, and only USD output needs them (the CLI loads this module).

__all__ = ["USD_FORMATS", "decompose", "write_usd_stage"]

USD_FORMATS = ("usd", "usda", "usdc")


def decompose(matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Translation, rotation quaternion ``(w, x, y, z)`` and scale of an affine 4x4 matrix.

    The linear part ``A = R S`` is split by the polar decomposition (``R`` the
    orthogonal factor); shear, if any, is dropped.
    """
    from scipy.linalg import polar
    from scipy.spatial.transform import Rotation
    m = np.asarray(matrix, np.float64).reshape(4, 4)
    R, S = polar(m[:3, :3])  # A = R S with S symmetric positive semi-definite
    if np.linalg.det(R) < 0:
        R, S = -R, -S
    q = Rotation.from_matrix(R).as_quat()  # x, y, z, w
    return m[:3, 3].copy(), np.array([q[3], q[0], q[1], q[2]]), np.diag(S).copy()


def _mesh_prim(stage, path, vertices, faces, normals=None, uvs=None):
    from pxr import UsdGeom, Vt
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(vertices, np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(faces, np.int32).ravel()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    if normals is not None:
        mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(normals, np.float32)))
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    if uvs is not None:
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", _sdf_type("TexCoord2fArray"), UsdGeom.Tokens.vertex)
        st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(uvs, np.float32)))
    lo, hi = np.min(vertices, axis=0), np.max(vertices, axis=0)
    mesh.CreateExtentAttr([tuple(map(float, lo)), tuple(map(float, hi))])
    return mesh


def _sdf_type(name):
    from pxr import Sdf
    return getattr(Sdf.ValueTypeNames, name)


def _material(stage, path, colour, texture=None):
    """A UsdPreviewSurface material: ``texture`` (a file name) or a constant ``colour``."""
    from pxr import Gf, Sdf, UsdShade
    mat = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(1.0)
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    diffuse = shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f)
    if texture is None:
        diffuse.Set(Gf.Vec3f(*map(float, colour)))
    else:
        reader = UsdShade.Shader.Define(stage, f"{path}/stReader")
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        # A string since UsdPreviewSurface 2.5 (a token fails OpenUSD's validators).
        reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
        tex = UsdShade.Shader.Define(stage, f"{path}/Albedo")
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(str(texture))
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
        diffuse.ConnectToSource(tex.ConnectableAPI(), "rgb")
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return mat


def _bind(prim, mat):
    from pxr import UsdShade
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim()).Bind(mat)


def _mean_colour(mat_dict) -> tuple:
    if mat_dict.get("type") == "diffuse":
        return tuple(mat_dict["reflectance"]["value"])
    tints = [v for k, v in mat_dict.items() if k.endswith("_tint")]
    return tuple(np.mean(np.asarray(tints, np.float64), axis=0)) if tints else (0.5, 0.5, 0.5)


def _analytic(stage, path, kind, xf):
    from pxr import Gf, UsdGeom
    if kind == "sphere":
        prim = UsdGeom.Sphere.Define(stage, path)
        prim.CreateRadiusAttr(1.0)
    elif kind == "cube":
        prim = UsdGeom.Cube.Define(stage, path)
        prim.CreateSizeAttr(2.0)  # Mitsuba's cube spans [-1, 1]^3
    else:  # rectangle [-1, 1]^2 or disk of radius 1, in the z = 0 plane
        n = 4 if kind == "rectangle" else 64
        ang = np.arange(n) * 2 * np.pi / n + (np.pi / 4 if n == 4 else 0.0)
        r = np.sqrt(2.0) if n == 4 else 1.0
        v = np.stack([r * np.cos(ang), r * np.sin(ang), np.zeros(n)], axis=1)
        prim = _mesh_prim(stage, path, v, np.array([[0, i, i + 1] for i in range(1, n - 1)]))
    UsdGeom.Xformable(prim).AddTransformOp().Set(Gf.Matrix4d(np.asarray(xf, np.float64).T.tolist()))
    return prim


def write_usd_stage(path, chunks, desc=None, textures=None) -> Path:
    """Write a USD stage of terrain chunks, mesh instances and materials, atomically.

    Parameters
    ----------
    path : str or Path
        ``.usd``, ``.usdc`` (binary) or ``.usda`` (text).
    chunks : list of (name, mesh)
        Terrain pieces: a :class:`~arches_render.mesh.polygonize.TriangleMesh` or a
        :class:`~arches_render.mesh.uv_atlas.UVMesh` (then its ``st`` primvar).
    desc : SceneDescription, optional
        Source of the mesh instances (``[[meshes]]``) and materials.
    textures : dict, optional
        ``{chunk name: albedo file name}`` (relative to the stage) for baked chunks.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    ValueError
        For another extension.
    """
    from pxr import Usd, UsdGeom
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in USD_FORMATS:
        raise ValueError(f"{path}: unsupported USD format '.{fmt}' (use .usd, .usda or .usdc)")
    textures = textures or {}
    with atomic_path(path) as tmp:
        tmp.unlink()  # USD refuses to create a layer over an existing file
        stage = Usd.Stage.CreateNew(str(tmp))
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, 1.0)
        world = UsdGeom.Xform.Define(stage, "/World")
        stage.SetDefaultPrim(world.GetPrim())
        UsdGeom.Xform.Define(stage, "/World/Terrain")
        UsdGeom.Scope.Define(stage, "/World/Materials")
        mats = {}
        if desc is not None:
            for name, d in desc.materials.items():
                mats[name] = _material(stage, f"/World/Materials/{name}", _mean_colour(d))
        field_mat = mats.get(desc.field_material) if desc is not None else None
        for name, mesh in chunks:
            prim = _mesh_prim(stage, f"/World/Terrain/{name}", mesh.vertices, mesh.faces, mesh.normals,
                              getattr(mesh, "uvs", None))
            if name in textures:
                _bind(prim, _material(stage, f"/World/Materials/{name}_baked", (1, 1, 1), textures[name]))
            elif field_mat is not None:
                _bind(prim, field_mat)
        if desc is not None and (desc.meshes or any(desc.tables.values())):
            _instances(stage, desc, mats)
        stage.GetRootLayer().Save()
        del stage
    return path


def _instances(stage, desc, mats):
    import trimesh
    from pxr import Gf, UsdGeom, Vt
    UsdGeom.Scope.Define(stage, "/World/Instances")
    groups: dict[str, list] = {}
    for i, m in enumerate(desc.meshes):
        xf = np.asarray(m["to_world"].matrix, np.float64)
        if "filename" in m:
            groups.setdefault(m["filename"], []).append((xf, m["bsdf"]["id"]))
        else:
            prim = _analytic(stage, f"/World/Instances/shape_{i}", m["type"], xf)
            if m["bsdf"]["id"] in mats:
                _bind(prim, mats[m["bsdf"]["id"]])
    for k, (filename, items) in enumerate(sorted(groups.items())):
        stem = "".join(c if c.isalnum() else "_" for c in Path(filename).stem) or "mesh"
        base = f"/World/Instances/{stem}_{k}"
        inst = UsdGeom.PointInstancer.Define(stage, base)
        tm = trimesh.load(filename, force="mesh", process=False)
        proto = _mesh_prim(stage, f"{base}/Prototypes/proto", tm.vertices, tm.faces, tm.vertex_normals)
        if items[0][1] in mats:
            _bind(proto, mats[items[0][1]])
        inst.CreatePrototypesRel().SetTargets([proto.GetPath()])
        parts = [decompose(xf) for xf, _ in items]
        inst.CreateProtoIndicesAttr(Vt.IntArray([0] * len(items)))
        inst.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, t)) for t, _, _ in parts]))
        inst.CreateOrientationsAttr(Vt.QuathArray([Gf.Quath(float(q[0]), Gf.Vec3h(*map(float, q[1:])))
                                                   for _, q, _ in parts]))
        inst.CreateScalesAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, s)) for _, _, s in parts]))
    # The generators' scene tables (a rock pile: the stones of its tile set).
    for items in desc.tables.values():
        for item in items:
            _point_instancer(stage, item.point_instancer(), mats.get(item.material))


def _point_instancer(stage, data, mat):
    """One PointInstancer ``/World/Instances/<name>`` from a scene-table item's
    ``point_instancer()`` data: ``name``, prototypes ``[(name, vertices, faces, normals)]``,
    ``proto_index``, ``positions``, ``scales`` (``None``: nothing to write)."""
    from pxr import UsdGeom, Vt
    if data is None:
        return
    base = f"/World/Instances/{data['name']}"
    pi = UsdGeom.PointInstancer.Define(stage, base)
    protos = []
    for name, v, f, n in data["prototypes"]:
        proto = _mesh_prim(stage, f"{base}/Prototypes/{name}", v, f, n)
        if mat is not None:
            _bind(proto, mat)
        protos.append(proto.GetPath())
    pi.CreatePrototypesRel().SetTargets(protos)
    pi.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.asarray(data["proto_index"], np.int32).ravel()))
    pi.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(data["positions"], np.float32)))
    pi.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(np.asarray(data["scales"], np.float32)))
