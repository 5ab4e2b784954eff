"""`arches-render mesh --uv/--bake` and USD stages: UV atlases, baked textures that
load back (trimesh / pxr), chunked terrain with welded seams, point instancers."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant

variant()

from arches_render.cli import main  # noqa: E402

BALL = """
[scene]
name = "ball"
[camera]
origin = [0.0, -5.0, 1.0]
target = [0.0, 0.0, 0.0]
[[lights]]
type = "constant"
[materials.paint]
type = "diffuse"
color = [0.2, 0.4, 0.6]
[materials.stone]
type = "triplanar"
preset = "terrain"
[field]
root = { type = "blend", radius = 0.3, children = [
  { type = "sphere", center = [0.0, 0.0, 0.0], radius = 1.0 },
  { type = "sphere", center = [1.6, 0.4, 0.1], radius = 0.8 }] }
material = "MATERIAL"
"""


def _scene(tmp_path, material="paint", extra=""):
    p = tmp_path / "ball.toml"
    p.write_text(BALL.replace("MATERIAL", material) + extra)
    return p


def test_glb_with_uv_atlas_and_baked_albedo_loads_back(tmp_path):
    import trimesh
    scene = _scene(tmp_path)
    out = tmp_path / "ball.glb"
    assert main(["mesh", str(scene), "-o", str(out), "--voxel", "0.12", "--bake", "--texture-size", "128",
                 "-q"]) == 0
    tm = trimesh.load(out, force="mesh")
    uv = tm.visual.uv
    assert uv.shape == (len(tm.vertices), 2) and uv.min() >= 0 and uv.max() <= 1
    img = np.asarray(tm.visual.material.baseColorTexture)[..., :3]
    # A constant diffuse colour bakes to that colour (stored sRGB-encoded).
    expected = np.round(np.array([0.2, 0.4, 0.6]) ** (1 / 2.4) * 1.055 * 255 - 0.055 * 255)
    assert np.abs(img.reshape(-1, 3).mean(0) - expected).max() <= 1.0
    normal = (tmp_path / "ball_normal.png")
    assert normal.is_file()


def _gradient_texture(path, n=64):
    """A smooth, tileable colour texture: a half-texel shift or a flip of its lookup shows."""
    import imageio.v3 as iio
    x = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(x, x)
    rgb = np.stack([0.5 + 0.4 * np.sin(2 * np.pi * X), 0.5 + 0.4 * np.sin(2 * np.pi * Y),
                    0.5 + 0.4 * np.cos(2 * np.pi * (X + Y))], -1)
    iio.imwrite(path, np.round(rgb * 255).astype(np.uint8))


def _bilinear(img, uv):
    """Sample an ``(H, W, C)`` image at ``uv`` (v = 0 the bottom row, texel centres at (i + 0.5) / W)."""
    h, w = img.shape[:2]
    x = np.clip(uv[:, 0] * w - 0.5, 0, w - 1)
    y = np.clip((1.0 - uv[:, 1]) * h - 0.5, 0, h - 1)
    x0, y0 = np.minimum(x.astype(int), w - 2), np.minimum(y.astype(int), h - 2)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    im = img.astype(np.float64)
    return ((im[y0, x0] * (1 - fx) + im[y0, x0 + 1] * fx) * (1 - fy)
            + (im[y0 + 1, x0] * (1 - fx) + im[y0 + 1, x0 + 1] * fx) * fy)


def test_bake_matches_the_renderers_triplanar_albedo(tmp_path):
    """The baked texture, looked up at the interpolated UVs of random surface points, gives the
    albedo the renderer shades there (a material that varies in space: a v-flip, a half-texel
    offset or a swapped axis of the bake shows as a colour error)."""
    import drjit as dr
    import mitsuba as mi

    from arches_render.mesh.bake import bake_material
    from arches_render.mesh.polygonize import default_voxel, field_normals, polygonize
    from arches_render.mesh.uv_atlas import uv_atlas
    from arches_render.render.renderer import load_materials
    from arches_render.scene import load_scene
    _gradient_texture(tmp_path / "gradient.png")
    over = (f'overrides = {{ "rock.texture" = "{tmp_path / "gradient.png"}", "rock.scale" = 2.5, '
            '"rock.tint" = [0.8, 0.8, 0.8], "sand.coverage" = 0.0, "grass.coverage" = 0.0, '
            '"snow.coverage" = 0.0 }')
    text = BALL.replace("MATERIAL", "stone").replace('preset = "terrain"', 'preset = "terrain"\n' + over)
    (tmp_path / "ball.toml").write_text(text)
    desc = load_scene(tmp_path / "ball.toml")
    bsdf = load_materials(desc)["stone"]
    mesh = uv_atlas(polygonize(desc.field, 0.12), 256)
    baked = bake_material(mesh, bsdf, desc.field)
    assert baked.coverage.mean() > 0.15  # charts fill part of the atlas (padding, packing)
    # Random points on the surface: area-weighted faces, uniform barycentrics.
    rng = np.random.default_rng(0)
    V, Fc = mesh.vertices.astype(np.float64), mesh.faces.astype(np.int64)
    area = np.linalg.norm(np.cross(V[Fc[:, 1]] - V[Fc[:, 0]], V[Fc[:, 2]] - V[Fc[:, 0]]), axis=1)
    f = rng.choice(len(Fc), 3000, p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(len(f))), rng.random(len(f))
    lam = np.stack([1 - r1, r1 * (1 - r2), r1 * r2], -1)
    p = np.einsum("nk,nkd->nd", lam, V[Fc[f]])
    uv = np.einsum("nk,nkd->nd", lam, mesh.uvs.astype(np.float64)[Fc[f]])
    # The albedo the renderer shades at p (the field's normal there).
    n = field_normals(desc.field, p, 0.05 * default_voxel(desc.field))
    si = dr.zeros(mi.SurfaceInteraction3f, len(p))
    si.p = mi.Point3f(*(mi.Float(p[:, i].astype(np.float32)) for i in range(3)))
    si.sh_frame = mi.Frame3f(mi.Normal3f(*(mi.Float(n[:, i]) for i in range(3))))
    a = bsdf.albedo(si, True)
    want = np.stack([a.x.numpy(), a.y.numpy(), a.z.numpy()], -1)

    def error(at):
        c = _bilinear(baked.albedo, at) / 255.0
        got = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)  # sRGB decoding (IEC 61966-2-1)
        return np.abs(got - want).max(axis=1)
    err = error(uv)
    assert want.std(axis=0).min() > 0.05  # the albedo does vary over the surface
    # Texels at chart seams mix charts under bilinear lookup, hence a looser 90th percentile
    # (measured: median 0.009, 90 % 0.034).
    assert np.median(err) < 0.015 and np.quantile(err, 0.9) < 0.05, (np.median(err), np.quantile(err, 0.9))
    # The lookup that a correct bake implies beats the lookups a buggy one would imply: half a
    # texel off in u or v, and v flipped.
    half = 0.5 / baked.albedo.shape[0]
    for shift in ([half, 0.0], [0.0, half], [-half, 0.0], [0.0, -half]):
        worse = np.median(error(uv + shift))
        assert worse > 1.2 * np.median(err), (shift, worse, np.median(err))
    flipped = np.median(error(uv * [1.0, -1.0] + [0.0, 1.0]))
    assert flipped > 3 * np.median(err), (flipped, np.median(err))
    # World-space normal map: the normals at the same UVs are the field's.
    dec = _bilinear(baked.normal, uv) / 255.0 * 2 - 1
    dec /= np.linalg.norm(dec, axis=1, keepdims=True)
    assert np.median(np.einsum("ij,ij->i", dec, n)) > 0.999 and np.quantile(np.einsum("ij,ij->i", dec, n), 0.05) > 0.98


@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_obj_and_ply_with_uvs(tmp_path, fmt):
    import trimesh
    out = tmp_path / f"ball.{fmt}"
    assert main(["mesh", str(_scene(tmp_path)), "-o", str(out), "--voxel", "0.15", "--bake",
                 "--texture-size", "64", "-q"]) == 0
    assert (tmp_path / "ball_albedo.png").is_file()
    if fmt == "obj":
        tm = trimesh.load(out, force="mesh")
        assert tm.visual.uv is not None and len(tm.visual.uv) == len(tm.vertices)
        assert "map_Kd ball_albedo.png" in (tmp_path / "ball.mtl").read_text()
    else:
        tm = trimesh.load(out, force="mesh", process=False)
        assert len(tm.faces) > 100
        assert tm.visual.uv.shape == (len(tm.vertices), 2)  # s, t read back as UVs
        raw = tm.metadata["_ply_raw"]["vertex"]["data"]
        c = np.stack([raw[k] for k in ("red", "green", "blue")], -1).astype(float).mean(0)
        assert np.abs(c - [124, 170, 203]).max() < 3  # sRGB of (0.2, 0.4, 0.6)


def _edge_counts(meshes):
    """(open edges, edges of more than two faces) after merging vertices by exact position."""
    V = np.concatenate([np.asarray(m.vertices, np.float64) for m in meshes])
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])[:-1]
    F = np.concatenate([np.asarray(m.faces, np.int64) + o for m, o in zip(meshes, offsets)])
    _, inv = np.unique(V, axis=0, return_inverse=True)
    F = inv.ravel()[F]
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, count = np.unique(E, axis=0, return_counts=True)
    return int((count == 1).sum()), int((count > 2).sum())


def test_usd_stage_chunks_are_welded_and_instances_are_point_instancers(tmp_path):
    import trimesh
    from pxr import Usd, UsdGeom

    from arches_render.mesh.chunks import polygonize_chunks
    from arches_render.mesh.polygonize import polygonize
    from arches_render.scene import load_scene
    rock = trimesh.creation.icosphere(1, radius=0.2)
    rock.export(tmp_path / "rock.ply")
    extra = "".join(f"""
[[meshes]]
file = "rock.ply"
translate = [{x}, 2.0, 0.0]
rotate = {{ axis = [0.0, 0.0, 1.0], angle = {10 * i} }}
scale = {0.5 + 0.25 * i}
material = "paint"
""" for i, x in enumerate((-1.0, 0.0, 1.5)))
    scene = _scene(tmp_path, "stone", extra)
    out = tmp_path / "stage.usda"
    assert main(["mesh", str(scene), "-o", str(out), "--voxel", "0.1", "--chunk-cells", "12", "-q"]) == 0
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    chunks = [p for p in stage.Traverse() if p.GetPath().pathString.startswith("/World/Terrain/chunk_")]
    assert len(chunks) >= 4
    pieces = []
    for prim in chunks:
        m = UsdGeom.Mesh(prim)
        v = np.asarray(m.GetPointsAttr().Get(), np.float32)
        f = np.asarray(m.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        pieces.append(trimesh.Trimesh(v, f, process=False))
    # Welded seams: joined by exact vertex position, the chunks leave no open edge
    # (the surface is closed), like the unchunked polygonization on the same grid.
    whole = polygonize(load_scene(scene).field, 0.1)
    assert sum(len(p.faces) for p in pieces) == len(whole.faces)
    assert _edge_counts(pieces) == _edge_counts([whole]) and _edge_counts(pieces)[0] == 0
    assert _edge_counts(pieces[:1])[0] > 0  # one chunk alone is open along its seams
    # Instances: one PointInstancer for the three rocks, transforms preserved.
    inst = [UsdGeom.PointInstancer(p) for p in stage.Traverse() if p.IsA(UsdGeom.PointInstancer)]
    assert len(inst) == 1
    pos = np.asarray(inst[0].GetPositionsAttr().Get())
    assert np.allclose(pos, [[-1.0, 2.0, 0.0], [0.0, 2.0, 0.0], [1.5, 2.0, 0.0]], atol=1e-6)
    assert np.allclose(np.asarray(inst[0].GetScalesAttr().Get())[:, 0], [0.5, 0.75, 1.0], atol=1e-5)
    xf = inst[0].ComputeInstanceTransformsAtTime(Usd.TimeCode.Default(), Usd.TimeCode.Default())
    m = np.asarray(xf[1]).T
    assert np.allclose(m[:3, :3] @ [1, 0, 0], [0.75 * np.cos(np.radians(10)), 0.75 * np.sin(np.radians(10)), 0],
                       atol=1e-3)
    # Materials: a UsdPreviewSurface bound to the terrain.
    from pxr import UsdShade
    mat, _ = UsdShade.MaterialBindingAPI(chunks[0]).ComputeBoundMaterial()
    assert mat and mat.GetPath().pathString == "/World/Materials/stone"
    assert len(polygonize_chunks(load_scene(scene).field, 0.1, 1000)) == 1


def test_usd_with_baked_textures_and_binary(tmp_path):
    from pxr import Usd, UsdShade
    out = tmp_path / "stage.usdc"
    assert main(["mesh", str(_scene(tmp_path, "stone")), "-o", str(out), "--voxel", "0.15", "--bake",
                 "--texture-size", "64", "--chunk-cells", "16", "-q"]) == 0
    stage = Usd.Stage.Open(str(out))
    shaders = [UsdShade.Shader(p) for p in stage.Traverse() if p.GetName() == "Albedo"]
    assert shaders
    tex = shaders[0].GetInput("file").Get().path
    assert (tmp_path / tex).is_file()


def test_mesh_bad_format(tmp_path, capsys):
    assert main(["mesh", str(_scene(tmp_path)), "-o", str(tmp_path / "x.fbx")]) == 2
    err = capsys.readouterr().err
    assert ".usda" in err and "x.fbx" in err


PILE = """
[camera]
origin = [0.0, -9.0, 3.0]
target = [0.0, 0.0, 0.0]
[[lights]]
type = "constant"
[field]
root = { type = "sphere", center = [0.0, 0.0, -2.0], radius = 1.0 }
[[rock_piles]]
support = { shape = "sphere", center = [0.0, 0.0, 0.0], radius = 1.5 }
rock_size = 0.35
tiling = "periodic"
poisson_radius = 0.14
seed = 2
erosion = { steps = 4 }
preset = "basalt"
"""


def test_usd_rock_pile_is_a_point_instancer_of_its_stones(tmp_path, monkeypatch):
    from pxr import Usd, UsdGeom

    from arches_render.scene import load_scene
    monkeypatch.setenv("ARCHES_RENDER_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "pile.toml"
    scene.write_text(PILE)
    out = tmp_path / "pile.usd"
    assert main(["mesh", str(scene), "-o", str(out), "--voxel", "0.2", "-q"]) == 0
    stage = Usd.Stage.Open(str(out))
    pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Instances/rock_pile_0"))
    xfs = pi.ComputeInstanceTransformsAtTime(Usd.TimeCode.Default(), Usd.TimeCode.Default())
    protos = [UsdGeom.Mesh(stage.GetPrimAtPath(p)) for p in pi.GetPrototypesRel().GetTargets()]
    idx = np.asarray(pi.GetProtoIndicesAttr().Get())
    pts = []
    for k, xf in zip(idx, xfs):
        v = np.asarray(protos[k].GetPointsAttr().Get(), np.float64)
        m = np.asarray(xf)  # row-vector convention: p' = [p, 1] M
        pts.append(v @ m[:3, :3] + m[3, :3])
    pts = np.concatenate(pts)
    # The instanced rocks are the renderer's flat rock meshes, vertex for vertex.
    ref = np.concatenate([b["positions"] for b in load_scene(scene).rock_piles[0].buffers()])
    assert len(pts) == len(ref) > 0
    from scipy.spatial import cKDTree
    assert cKDTree(ref).query(pts)[0].max() < 1e-5 and cKDTree(pts).query(ref)[0].max() < 1e-5
