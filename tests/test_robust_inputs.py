"""Every file a scene hands over, as another program might have written it (issue 17, "Bad input").

Mesh files (``[[meshes]]``, rock-pile supports), array files (``capsule_set``,
``skeletal_set``, block tiles, material stacks), textures and environment maps, and
requests too large for the machine: each bad one exits with status 2 and one line
naming the file, the key and what is allowed, no traceback, and nothing written. A
good one loads what was written: what ``info`` reports (node kinds, the field's
bounds, mesh count) and what the loader holds (arrays, mesh geometry) are compared
with the arrays and meshes the test wrote.
All run ``arches-render info`` in this process (loading only: milliseconds each).
"""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

from helpers import variant
from robust_helpers import BASE_SCENE, assert_one_line_error, cli, cli_out, write

#: The field bounds of BASE_SCENE's ball (centre (0, 0, 0.5), radius 1).
BALL = (np.array([-1.0, -1.0, -0.5]), np.array([1.0, 1.0, 1.5]))


@pytest.fixture(autouse=True)
def _variant():
    variant()


def _info(capsys, scene) -> dict:
    """``arches-render info SCENE`` (exit 0 asserted): ``meshes`` (int), ``kinds`` ({kind: count} of
    the field's nodes) and ``bounds`` ((lo, hi) of the field, as printed: centimetres)."""
    import re
    rc, out, err = cli_out(capsys, "info", scene)
    assert rc == 0, err
    lines = {ln[:11].strip(): ln[11:].strip() for ln in out.splitlines() if ln[:11].strip()}
    kinds = dict((k, int(v)) for k, v in re.findall(r"(\w+) (\d+)", lines["field"].split("(", 1)[1]))
    lo, hi = (np.array([float(v) for v in part.strip(" []m").split(",")]) for part in lines["bounds"].split(".."))
    return {"meshes": int(lines["meshes"]), "kinds": kinds, "bounds": (lo, hi)}


def _assert_bounds(info, lo, hi):
    """The field's bounds as ``info`` prints them (2 decimals) are ``lo .. hi``."""
    assert np.allclose(info["bounds"][0], lo, atol=0.005) and np.allclose(info["bounds"][1], hi, atol=0.005), (
        info["bounds"], lo, hi)


def _scene_with(tmp_path, nodes="", tables="", lights=None, material=""):
    """A scene whose field is ``ball`` united with node ``extra`` (when ``nodes`` defines it)."""
    text = BASE_SCENE
    if lights is not None:
        text = text.replace('[[lights]]\ntype = "constant"\nradiance = 1.0\n', lights)
    if nodes:
        text = text.replace('root = "ball"', 'root = { type = "union", children = ["ball", "extra"] }')
        text += nodes
    if material:
        text = text.replace('[field]\n', material + '\n[field]\nmaterial = "m"\n')
    return write(tmp_path, text + tables)


# ------------------------------------------------------------------------------------------- meshes
def _sphere(path, **kw):
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=1, radius=0.5)
    for k, v in kw.items():
        setattr(m, k, v)
    m.export(path)
    return m


def _bad_meshes(folder):
    """name -> (file, words the error must contain)."""
    import trimesh
    ok = folder / "ok.ply"
    m = _sphere(ok)
    data = ok.read_bytes()
    (folder / "empty.ply").write_bytes(b"")
    (folder / "garbage.ply").write_bytes(b"solid nonsense\n" * 20)
    (folder / "trunc.ply").write_bytes(data[: len(data) * 2 // 3])
    v = m.vertices.copy()
    v[5] = np.nan
    trimesh.Trimesh(v, m.faces, process=False).export(folder / "nan.ply")
    flat = np.zeros((3, 3))
    trimesh.Trimesh(flat, [[0, 1, 2]], process=False).export(folder / "flat.ply")
    (folder / "index.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
    (folder / "index.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                      "property float y\nproperty float z\nelement face 1\n"
                                      "property list uchar int vertex_indices\nend_header\n"
                                      "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
    (folder / "mesh.stl").write_bytes(b"")
    (folder / "notes.txt").write_text("v 0 0 0\n")
    return {
        "empty": ("empty.ply", ["empty"]),
        "garbage": ("garbage.ply", ["cannot read the mesh", "PLY"]),
        "truncated": ("trunc.ply", ["cannot read the mesh"]),
        "nan": ("nan.ply", ["NaN", "vertex 5"]),
        "degenerate": ("flat.ply", ["zero area"]),
        "index": ("index.ply", ["vertex 7", "indices must be in [0, 2]"]),
        "index-obj": ("index.obj", ["cannot read the mesh", "out of bounds"]),
        "extension": ("notes.txt", [".ply or .obj"]),
        "stl-for-mitsuba": ("mesh.stl", [".ply or .obj"]),
    }


@pytest.mark.parametrize("case", ["empty", "garbage", "truncated", "nan", "degenerate", "index", "index-obj",
                                  "extension", "stl-for-mitsuba"])
def test_bad_scene_mesh_files_exit_2_naming_file_and_key(tmp_path, capsys, case):
    name, words = _bad_meshes(tmp_path)[case]
    scene = _scene_with(tmp_path, tables=f'\n[[meshes]]\nfile = "{name}"\n')
    rc, err = cli(capsys, "info", scene)
    assert_one_line_error(rc, err, str(scene), "meshes[0].file", *words)


def _assert_mesh_loaded(desc, index, mesh):
    """Scene mesh ``index`` holds ``mesh``: its vertex and face counts, and its bounding box."""
    import mitsuba as mi
    shape = mi.load_dict({k: v for k, v in desc.meshes[index].items() if k != "bsdf"})
    assert (shape.vertex_count(), shape.face_count()) == (len(mesh.vertices), len(mesh.faces))
    box = shape.bbox()
    # Mitsuba holds vertices in float32: the box agrees to float32 rounding of metre-sized values.
    assert np.allclose([box.min, box.max], mesh.bounds, atol=1e-6), ([box.min, box.max], mesh.bounds)


def test_good_scene_mesh_file_loads(tmp_path, capsys):
    from arches_render.scene import load_scene
    mesh = _sphere(tmp_path / "ok.ply")
    scene = _scene_with(tmp_path, tables='\n[[meshes]]\nfile = "ok.ply"\n')
    assert _info(capsys, scene)["meshes"] == 1
    _assert_mesh_loaded(load_scene(scene), 0, mesh)


PILE = '\n[[rock_piles]]\nsupport = {{ mesh = "{name}" }}\nrock_size = 0.3\n'


@pytest.mark.parametrize("case", ["empty", "garbage", "nan", "degenerate", "extension"])
def test_bad_rock_support_meshes_exit_2(tmp_path, capsys, case):
    name, words = _bad_meshes(tmp_path)[case]
    scene = _scene_with(tmp_path, tables=PILE.format(name=name))
    rc, err = cli(capsys, "info", scene)
    words = [w for w in words if w != ".ply or .obj"] + ([".ply, .obj or .stl"] if case == "extension" else [])
    assert_one_line_error(rc, err, "rock_piles[0].support.mesh", *words)


def test_open_rock_support_is_refused_but_an_open_scene_mesh_is_fine(tmp_path, capsys):
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=1)
    trimesh.Trimesh(m.vertices, m.faces[1:], process=False).export(tmp_path / "open.ply")
    rc, err = cli(capsys, "info", _scene_with(tmp_path, tables=PILE.format(name="open.ply")))
    assert_one_line_error(rc, err, "open.ply", "closed (watertight)")
    from arches_render.scene import load_scene
    scene = _scene_with(tmp_path, tables='\n[[meshes]]\nfile = "open.ply"\n')
    assert _info(capsys, scene)["meshes"] == 1
    _assert_mesh_loaded(load_scene(scene), 0, trimesh.load(tmp_path / "open.ply", process=False))


# ------------------------------------------------------------------------------------------- arrays
def _npz(path, **arrays):
    np.savez(path, **arrays)
    return path.name


def _huge_header_npz(path, n=10 ** 11):
    """An .npz whose members' headers claim ``n`` primitives but hold no data (a decompression bomb's size)."""
    with zipfile.ZipFile(path, "w") as z:
        for name, shape in (("a", (n, 3)), ("radius", (n,))):
            buf = io.BytesIO()
            np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": shape})
            z.writestr(f"{name}.npy", buf.getvalue())
    return path.name


A = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _capsule_cases(folder):
    ok = dict(a=A, b=A + 0.1, radius=np.full(3, 0.2))
    cases = {
        "missing": (_npz(folder / "missing.npz", a=A, b=A), ["missing array 'radius'"]),
        "shape": (_npz(folder / "shape.npz", **dict(ok, a=A[:, :2])), ["'a'", "shape (3, 2)", "(n, 3)"]),
        "rows": (_npz(folder / "rows.npz", **dict(ok, radius=np.ones(4))), ["'radius' has 4 rows", "'a' has 3"]),
        "dtype": (_npz(folder / "dtype.npz", **dict(ok, radius=np.array(["x", "y", "z"]))), ["dtype <U1"]),
        "nan": (_npz(folder / "nan.npz", **dict(ok, radius=np.array([0.2, np.nan, 0.2]))), ["NaN", "index [1]"]),
        "negative": (_npz(folder / "neg.npz", **dict(ok, radius=np.array([0.2, 0.2, -1.0]))),
                     ["'radius' is out of range", "index [2]", "> 0"]),
        "unknown": (_npz(folder / "extra.npz", **dict(ok, colour=np.ones(3))), ["unknown array 'colour'"]),
        "huge": (_huge_header_npz(folder / "huge.npz"), ["needs about", "of memory"]),
        "garbage": ("garbage.npz", ["not an .npz archive"]),
        "truncated": ("trunc.npz", ["damaged or truncated"]),
    }
    (folder / "garbage.npz").write_bytes(b"PK\x03\x04 not really a zip")
    data = io.BytesIO()
    np.savez_compressed(data, a=np.random.default_rng(0).normal(size=(4000, 3)), b=np.zeros((4000, 3)),
                        radius=np.ones(4000))
    raw = data.getvalue()
    # Keep the central directory (at the end), cut out the middle of the data: a bad CRC / short read.
    (folder / "trunc.npz").write_bytes(raw[:2000] + bytes(len(raw) - 4000) + raw[-2000:])
    return cases


@pytest.mark.parametrize("case", ["missing", "shape", "rows", "dtype", "nan", "negative", "unknown", "huge",
                                  "garbage", "truncated"])
def test_bad_capsule_arrays_exit_2_naming_the_array(tmp_path, capsys, case):
    name, words = _capsule_cases(tmp_path)[case]
    scene = _scene_with(tmp_path, nodes=f'\n[nodes.extra]\ntype = "capsule_set"\nfile = "{name}"\n')
    rc, err = cli(capsys, "info", scene)
    assert_one_line_error(rc, err, str(scene), "nodes.extra.file", name, *words)


def test_a_capsule_array_file_loads_what_was_written(tmp_path, capsys):
    """Capsules reaching beyond the ball: ``info``'s bounds are those of the written arrays
    (``min(a, b) - r .. max(a, b) + r`` per capsule, united with the ball's)."""
    from arches_render.scene import load_scene
    a = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 3.0, 0.0]])
    b = a + [0.0, 0.0, 2.0]
    r = np.array([0.2, 0.3, 0.5])
    name = _npz(tmp_path / "caps.npz", a=a, b=b, radius=r)
    scene = _scene_with(tmp_path, nodes=f'\n[nodes.extra]\ntype = "capsule_set"\nfile = "{name}"\n')
    info = _info(capsys, scene)
    assert info["kinds"] == {"capsule_set": 1, "sphere": 1, "union": 1}, info
    lo = (np.minimum(a, b) - r[:, None]).min(axis=0)
    hi = (np.maximum(a, b) + r[:, None]).max(axis=0)
    _assert_bounds(info, np.minimum(lo, BALL[0]), np.maximum(hi, BALL[1]))
    (node,) = [n for n in load_scene(scene).field.walk() if n.kind == "capsule_set"]
    assert node.n == 3 and np.allclose([node.prim_lo, node.prim_hi], [lo, hi])


def test_object_arrays_are_never_unpickled(tmp_path, capsys):
    np.savez(tmp_path / "obj.npz", a=np.array([{"x": 1}], dtype=object), radius=np.ones(1))
    scene = _scene_with(tmp_path, nodes='\n[nodes.extra]\ntype = "skeletal_set"\nfile = "obj.npz"\n')
    rc, err = cli(capsys, "info", scene)
    assert_one_line_error(rc, err, "nodes.extra.file", "dtype object", "Python objects")


def test_bad_skeletal_arrays_exit_2(tmp_path, capsys):
    np.savez(tmp_path / "core.npz", a=A, radius=np.ones(3), core=np.array([0.0, -1.0, 0.0]))
    scene = _scene_with(tmp_path, nodes='\n[nodes.extra]\ntype = "skeletal_set"\nfile = "core.npz"\n')
    rc, err = cli(capsys, "info", scene)
    assert_one_line_error(rc, err, "nodes.extra.file", "'core' is out of range", ">= 0")


BLOCKS = """
[nodes.extra]
type = "blocks"
host = { type = "box", center = [0.0, 0.0, 0.5], size = [2.0, 2.0, 1.0] }
tile = "t.npz"
"""


def _tile(path, **change):
    eye = np.vstack([np.eye(3), -np.eye(3)]).astype(np.float32)
    arrays = dict(normals=eye, offsets=np.full(6, 0.5, np.float32), start=np.array([0], np.uint32),
                  count=np.array([6], np.uint32), anchors=np.zeros((1, 4, 3), np.float32),
                  centroid=np.full((1, 3), 0.5, np.float32),
                  meta=np.array(json.dumps({"version": _tile_version(), "size": 1.0, "params": {}, "stats": {}})))
    arrays.update(change)
    np.savez(path, **arrays)


def _tile_version():
    from arches_render.generators.blocks.tile_cache import FORMAT_VERSION
    return FORMAT_VERSION


@pytest.mark.parametrize("change, words", [
    (dict(count=np.array([60], np.uint32)), ["start + count must lie in [0, 6]"]),
    (dict(start=np.array([-1], np.int64)), ["'start' is out of range", ">= 0"]),
    (dict(normals=np.full((6, 3), np.inf, np.float32)), ["'normals'", "NaN or infinite"]),
    (dict(meta=np.array('{"version": -7, "size": 1.0}')), ["tile format -7"]),
    (dict(meta=np.array("not json")), ["not a block tile"]),
])
def test_bad_block_tiles_exit_2(tmp_path, capsys, change, words):
    _tile(tmp_path / "t.npz", **change)
    rc, err = cli(capsys, "info", _scene_with(tmp_path, nodes=BLOCKS))
    assert_one_line_error(rc, err, "nodes.extra.tile", "t.npz", *words)


def test_a_hand_made_block_tile_loads(tmp_path, capsys):
    from arches_render.scene import load_scene
    _tile(tmp_path / "t.npz")
    scene = _scene_with(tmp_path, nodes=BLOCKS)
    assert _info(capsys, scene)["kinds"] == {"blocks_field": 1, "box": 1, "sphere": 1, "union": 2}
    (node,) = [n for n in load_scene(scene).field.walk() if n.kind == "blocks_field"]
    with np.load(tmp_path / "t.npz", allow_pickle=False) as z:
        for key in ("normals", "offsets", "start", "count", "anchors", "centroid"):
            assert np.array_equal(getattr(node.tile, key), z[key]), key
    assert node.tile.n_blocks == 1 and node.tile.size == 1.0


STACKS = """
[nodes.extra]
type = "layers"
source = "stacks"
file = "s.npz"
"""


def _stacks(path, **change):
    from arches_render.generators.layers.material_stacks import MaterialStacks
    s = MaterialStacks.from_heightfield(np.ones((4, 4)), 0.5, (0.0, 0.0), 0.0, 2.0, 0.01, (("bedrock", None),))
    s.save(path)
    if change:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        arrays.update(change)
        np.savez(path, **arrays)
    return s


@pytest.mark.parametrize("change, words", [
    (dict(offsets=np.array([0, 2, 1] + [1] * 14, np.uint32)), ["offsets must rise"]),
    (dict(material=np.full(16, 9, np.uint8)), ["unknown material id 9"]),
    (dict(grid=np.array([4, 4], np.int64)), ["'grid' has shape (2,)", "(3)"]),
    (dict(geometry=np.array([0.5, 0.0, 0.0, np.nan, 0.01])), ["'geometry'", "NaN"]),
])
def test_bad_stack_files_exit_2(tmp_path, capsys, change, words):
    _stacks(tmp_path / "s.npz", **change)
    rc, err = cli(capsys, "info", _scene_with(tmp_path, nodes=STACKS))
    assert_one_line_error(rc, err, "nodes.extra.file", *words)


def test_a_saved_stack_file_loads_back(tmp_path, capsys):
    """The stacks' grid (4 x 4 cells of 0.5 m from the origin) is the field's extent in ``info``'s
    bounds (padded by the surface's smoothing radius), and the loaded columns are those written."""
    from arches_render.scene import load_scene
    written = _stacks(tmp_path / "s.npz")
    scene = _scene_with(tmp_path, nodes=STACKS)
    info = _info(capsys, scene)
    assert info["kinds"] == {"layers": 1, "sphere": 1, "union": 1}, info
    (node,) = [n for n in load_scene(scene).field.walk() if n.kind == "layers"]
    far = np.asarray(written.origin, float)[:2] + np.array([written.nx, written.ny]) * written.cell + node.sigma
    assert (written.nx, written.ny, written.cell) == (4, 4, 0.5)
    # info prints bounds with 2 decimals: half a unit of the last digit.
    assert np.allclose(info["bounds"][1][:2], np.maximum(far, BALL[1][:2]), atol=0.005), (info, far)
    for key in ("nx", "ny", "cell", "dz", "n_levels"):
        assert getattr(node.stacks, key) == getattr(written, key), key
    for key in ("origin", "offsets", "material", "count"):
        assert np.array_equal(getattr(node.stacks, key), getattr(written, key)), key


# ------------------------------------------------------------------------------------------ textures
MATERIAL = '[materials.m]\ntype = "triplanar"\npreset = "terrain"\noverrides = {{ "rock.texture" = "{name}" }}\n'


def _images(folder):
    import mitsuba as mi
    from PIL import Image
    rng = np.random.default_rng(1)
    rgb = (rng.random((16, 16, 3)) * 255).astype(np.uint8)
    Image.fromarray(rgb).save(folder / "rgb.png")
    Image.fromarray(rgb[..., 0]).save(folder / "grey.png")
    Image.fromarray(rgb).convert("CMYK").save(folder / "cmyk.jpg")
    mi.Bitmap((rng.random((16, 16, 3)) * 65535).astype(np.uint16), mi.Bitmap.PixelFormat.RGB).write(
        str(folder / "rgb16.png"))
    data = (folder / "rgb.png").read_bytes()
    (folder / "trunc.png").write_bytes(data[: len(data) // 2])
    (folder / "garbage.png").write_bytes(b"\x89PNG but no" * 10)


@pytest.mark.parametrize("name, words", [
    ("nope.png", ["no such file"]),
    ("garbage.png", ["cannot read the image"]),
    ("trunc.png", ["cannot read the image", "read"]),
    ("cmyk.jpg", ["cannot read the image", "components"]),
])
def test_bad_textures_exit_2(tmp_path, capsys, name, words):
    _images(tmp_path)
    scene = _scene_with(tmp_path, material=MATERIAL.format(name=name))
    rc, err = cli(capsys, "info", scene)
    assert_one_line_error(rc, err, "materials.m.overrides.rock.texture", *words)


@pytest.mark.parametrize("name, said", [
    ("rgb.png", None),
    ("grey.png", "greyscale where colour is expected, converted"),
    ("rgb16.png", "16-bit samples, converted to float"),
])
def test_textures_that_convert_say_so(tmp_path, capsys, name, said):
    _images(tmp_path)
    scene = _scene_with(tmp_path, material=MATERIAL.format(name=name))
    rc, err = cli(capsys, "info", scene)
    assert rc == 0, err
    notes = [ln for ln in err.splitlines() if ln.startswith("arches-render: note:")]
    if said is None:
        assert not notes, err
    else:
        assert len(notes) == 1 and said in notes[0] and name in notes[0], err
    # The scene renders with the texture the loader resolved (an absolute path inside the scene's folder).
    from arches_render.scene import load_scene
    desc = load_scene(scene)
    assert desc.materials["m"]["layer0_texture"] == str((tmp_path / name).resolve())


def test_bundled_texture_names_still_work(tmp_path, capsys):
    from arches_render.scene import load_scene
    scene = _scene_with(tmp_path, material=MATERIAL.format(name="sand.png"))
    rc, err = cli(capsys, "info", scene)
    assert rc == 0, err
    # Not a file of the scene's folder: the name stays the bundled texture's, for the material to find.
    assert load_scene(scene).materials["m"]["layer0_texture"] == "sand.png"


def test_bad_envmap_exits_2(tmp_path, capsys):
    _images(tmp_path)
    scene = _scene_with(tmp_path, lights='[[lights]]\ntype = "envmap"\nfile = "trunc.png"\n')
    rc, err = cli(capsys, "info", scene)
    assert_one_line_error(rc, err, "lights[0].file", "cannot read the image")


# ------------------------------------------------------------------------------------------ memory
def test_requests_that_do_not_fit_are_refused_up_front(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("ARCHES_RENDER_MEMORY", "1G")
    scene = write(tmp_path, BASE_SCENE)
    out = tmp_path / "big.exr"
    rc, err = cli(capsys, "render", scene, "-o", out, "--resolution", "8000x8000", "-q")
    line = assert_one_line_error(rc, err, "rendering 8000x8000", "needs about", "GB of memory",
                                 "available", "ARCHES_RENDER_MEMORY")
    assert "1.1 GB available" in line
    rc, err = cli(capsys, "mesh", scene, "-o", tmp_path / "m.ply", "--voxel", "0.004")
    assert_one_line_error(rc, err, "polygonizing", "voxels of 0.004 m", "needs about")
    rc, err = cli(capsys, "turntable", scene, "-o", tmp_path / "frames", "--resolution", "9000x9000")
    assert_one_line_error(rc, err, "rendering 9000x9000")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]  # nothing written, no folder made
    hf = BASE_SCENE.replace('root = "ball"', 'root = "hf"') + (
        '[nodes.hf]\ntype = "heightfield"\nextent = [-5.0, -5.0, 5.0, 5.0]\nresolution = [8192, 8192]\n')
    hf = hf.replace('[nodes.ball]\ntype = "sphere"\ncenter = [0.0, 0.0, 0.5]\nradius = 1.0\n', "")
    rc, err = cli(capsys, "info", write(tmp_path, hf, "hf.toml"))
    assert_one_line_error(rc, err, "nodes.hf.resolution", "8192x8192 fBm heightmap", "needs about 5.4 GB")


def test_memory_cap_must_be_a_size(monkeypatch):
    from arches_render.resources import ResourceError, available_bytes
    monkeypatch.setenv("ARCHES_RENDER_MEMORY", "lots")
    with pytest.raises(ResourceError, match="must be a size"):
        available_bytes()
    monkeypatch.setenv("ARCHES_RENDER_MEMORY", "512M")
    assert available_bytes() <= 512 << 20
