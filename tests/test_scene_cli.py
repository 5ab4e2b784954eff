"""Scene validation and the CLI as a user meets them: exit codes, one-line errors,
no traceback, no half-written output."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from helpers import REPO, SCENES

MINIMAL = textwrap.dedent("""
    [scene]
    name = "mini"
    [render]
    resolution = [24, 16]
    spp = 2
    [camera]
    origin = [0.0, -6.0, 2.0]
    target = [0.0, 0.0, 0.5]
    [[lights]]
    type = "constant"
    radiance = 1.0
    [field]
    root = "ball"
    [nodes.ball]
    type = "sphere"
    center = [0.0, 0.0, 0.5]
    radius = 1.0
""")


def run_cli(*args, cwd=None):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run([sys.executable, "-m", "arches_render.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd or REPO, env=env, timeout=300)


def write_scene(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


BAD = [
    ("radius = 1.0", "radius = -1.0", "nodes.ball.radius", "> 0"),
    ("spp = 2", "spp = 0", "render.spp", "in [1, "),
    ("resolution = [24, 16]", "resolution = [24]", "render.resolution", "[width, height]"),
    ('type = "constant"', 'type = "sun"', "lights[0].type", "one of"),
    ('type = "sphere"', 'type = "blob"', "nodes.ball.type", "one of"),
    ("radius = 1.0", "radius = 1.0\nradiuss = 2.0", "nodes.ball.radiuss", "unknown key"),
    ('root = "ball"', 'root = "rock"', "field.root", "unknown node 'rock'"),
    ("[camera]", "[camera]\nfov = 190.0", "camera.fov", "(0, 180)"),
    ("spp = 2", 'spp = 2\ngeometry = "voxels"', "render.geometry", "field, mesh"),
]


@pytest.mark.parametrize("old,new,key,allowed", BAD)
def test_bad_scene_exits_2_with_one_line(tmp_path, old, new, key, allowed):
    path = write_scene(tmp_path, MINIMAL.replace(old, new, 1))
    out = tmp_path / "out.exr"
    res = run_cli("render", path, "-o", out, "-q")
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert str(path) in lines[0] and key in lines[0] and allowed in lines[0], lines[0]
    assert not out.exists() and list(tmp_path.glob("*.exr")) == []


def test_cycle_and_syntax_errors(tmp_path):
    cyc = MINIMAL.replace('root = "ball"', 'root = "a"') + textwrap.dedent("""
        [nodes.a]
        type = "union"
        children = ["b"]
        [nodes.b]
        type = "translate"
        child = "a"
        offset = [0.0, 0.0, 1.0]
    """)
    res = run_cli("info", write_scene(tmp_path, cyc.replace("[nodes.ball]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.5]\nradius = 1.0\n", "")))
    assert res.returncode == 2 and "cycle" in res.stderr and "Traceback" not in res.stderr
    res = run_cli("info", write_scene(tmp_path, "[scene\nname=", "broken.toml"))
    assert res.returncode == 2 and "broken.toml" in res.stderr and "not valid TOML" in res.stderr
    res = run_cli("info", tmp_path / "missing.toml")
    assert res.returncode == 2 and "no such scene file" in res.stderr


def test_bad_arguments_exit_2(tmp_path):
    path = write_scene(tmp_path, MINIMAL)
    for args in (["--spp", "0"], ["--resolution", "12"], ["--geometry", "voxel"], ["-o", tmp_path / "x.png"]):
        res = run_cli("render", path, "-q", *args)
        assert res.returncode == 2, (args, res.stderr)
        assert "Traceback" not in res.stderr


def test_render_writes_exr_and_png_with_header(tmp_path):
    from arches_render.imaging.exr import read_exr
    path = write_scene(tmp_path, MINIMAL)
    out = tmp_path / "renders" / "mini.exr"
    out.parent.mkdir()  # an explicit -o needs its folder (only the default out/ is created)
    res = run_cli("render", path, "-o", out, "--spp", "3", "--seed", "5", "--resolution", "20x12")
    assert res.returncode == 0, res.stderr
    assert "render mini" in res.stderr  # progress over sample passes
    img = read_exr(out)
    assert img.rgb.shape == (12, 20, 3) and img.rgb.mean() > 0
    for key, value in (("scene_name", "mini"), ("seed", "5"), ("spp", "3"), ("geometry", "field")):
        assert img.header[key] == value
    assert "arches_render_version" in img.header
    assert out.with_suffix(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in out.parent.iterdir() if p.name.startswith(".")] == []


def _info_numbers(text):
    """Node count, bounds (lo, hi) and Lipschitz bound as `arches-render info` prints them."""
    import re
    nodes = int(re.search(r"^field\s+(\d+) nodes", text, re.M).group(1))
    b = re.search(r"^bounds\s+\[([^\]]+)\] \.\. \[([^\]]+)\] m", text, re.M)
    lo, hi = (np.array([float(v) for v in g.split(",")]) for g in b.groups())
    lip = float(re.search(r"^lipschitz\s+([0-9.]+)", text, re.M).group(1))
    return nodes, lo, hi, lip


def test_info_reports_tree_of_an_analytic_scene(tmp_path, capsys):
    from arches_render.cli import main
    # Union of a unit ball and a ball of radius 0.5: three nodes, a known box, Lipschitz 1.
    scene = MINIMAL.replace('root = "ball"', 'root = "both"') + textwrap.dedent("""
        [nodes.small]
        type = "sphere"
        center = [2.0, 0.0, 0.0]
        radius = 0.5
        [nodes.both]
        type = "union"
        children = ["ball", "small"]
    """)
    assert main(["info", str(write_scene(tmp_path, scene))]) == 0
    nodes, lo, hi, lip = _info_numbers(capsys.readouterr().out)
    assert nodes == 3 and lip == pytest.approx(1.0, abs=1e-3)
    np.testing.assert_allclose(lo, [-1.0, -1.0, -0.5], atol=0.006)
    np.testing.assert_allclose(hi, [2.5, 1.0, 1.5], atol=0.006)


def test_info_reports_tree(capsys):
    """The printed node count, bounds and Lipschitz bound of the default scene hold for its tree."""
    from arches_render import field as F
    from arches_render.cli import main
    from arches_render.scene import load_scene
    assert main(["info", str(SCENES / "default.toml")]) == 0
    nodes, lo, hi, lip = _info_numbers(capsys.readouterr().out)
    root = load_scene(SCENES / "default.toml").field

    def count(n):  # every node of the tree, counted by its children (not by Node.walk)
        return 1 + sum(count(c) for c in n.children)
    assert nodes == count(root) > 3
    # Bounds: the box holds all matter (f > 0 nowhere outside it) and is not loose (matter near each
    # face: within 20 % of the box; a blend grows its children's boxes by a margin, so not at the face).
    rng = np.random.default_rng(0)
    size = hi - lo
    inside = lo + rng.random((200_000, 3)) * size
    f_in = F.evaluate(root, inside)
    assert (f_in > 0).mean() > 0.01
    for axis in range(3):
        for side, face in ((0, lo[axis]), (1, hi[axis])):
            out = inside[:20_000].copy()
            out[:, axis] = face + (1 if side else -1) * rng.uniform(0.01, 0.5, len(out)) * size[axis]
            assert F.evaluate(root, out).max() <= 0, (axis, side)
            near = np.abs(inside[:, axis] - face) < 0.2 * size[axis]
            assert (f_in[near] > 0).any(), (axis, side)
    # Lipschitz: no pair of nearby points changes f faster than the printed bound.
    a = inside[:50_000]
    d = rng.normal(size=a.shape)
    d *= (0.05 * rng.random((len(a), 1))) / np.linalg.norm(d, axis=1, keepdims=True)
    slope = np.abs(F.evaluate(root, a + d) - f_in[:50_000]) / np.linalg.norm(d, axis=1)
    assert slope.max() <= lip * 1.0005 + 1e-3


def test_mesh_export(tmp_path):
    import trimesh
    path = write_scene(tmp_path, MINIMAL)
    out = tmp_path / "ball.ply"
    res = run_cli("mesh", path, "-o", out, "--voxel", "0.1", "-q")
    assert res.returncode == 0, res.stderr
    mesh = trimesh.load(out, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    # Volume of the unit ball within marching-cubes error.
    assert abs(mesh.volume - 4 / 3 * 3.14159265) < 0.05
    res = run_cli("mesh", path, "-o", tmp_path / "ball.stl")
    assert res.returncode == 2 and "ply, .obj or .glb" in res.stderr


def test_material_mask_errors(tmp_path):
    scene = MINIMAL.replace('[field]\nroot = "ball"', textwrap.dedent('''
        [materials.rock]
        type = "triplanar"
        preset = "terrain"
        masks = [{ layer = "moss", node = "patches" }]
        [nodes.patches]
        type = "noise"
        [field]
        root = "ball"
        material = "rock"'''))
    res = run_cli("info", write_scene(tmp_path, scene))
    assert res.returncode == 2 and "materials.rock.masks[0].layer" in res.stderr and "grass" in res.stderr
    res = run_cli("info", write_scene(tmp_path, scene.replace('"moss"', '"snow"')))
    assert res.returncode == 0, res.stderr


@pytest.mark.parametrize("voxel, says", [("5.0", ("no surface", "--voxel", "5 m")),
                                         # refused up front by its memory estimate (robust stream)
                                         ("0.0002", ("0.0002 m", "memory"))])
def test_mesh_and_mesh_render_refuse_a_voxel_that_cannot_polygonize(tmp_path, capsys, voxel, says):
    """A voxel far larger than the field's only feature (no surface sampled) or far too small (too
    many voxels): exit 2 and one line naming the voxel, no traceback, no output."""
    from arches_render.cli import main
    # A small ball: at 5 m voxels the grid straddles it without a sample inside.
    scene = write_scene(tmp_path, MINIMAL.replace("radius = 1.0", "radius = 0.3"))
    for argv in (["mesh", str(scene), "-o", str(tmp_path / "m.ply"), "--voxel", voxel, "-q"],
                 ["render", str(scene), "-o", str(tmp_path / "r.exr"), "--geometry", "mesh", "--voxel", voxel,
                  "-q"]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "Traceback" not in err and err.startswith("arches-render"), err
        assert all(w in err for w in says), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]


def test_a_fresh_process_loads_a_scene_with_meshes_first():
    """``load_scene`` as a script's first call, on a scene whose ground mesh is read before
    any field node selects the Mitsuba variant: it failed with "Cannot access
    'ScalarTransform4f' before setting a variant" (``examples/make_gallery.py
    blocks_limestone_scarp`` did)."""
    code = "from arches_render.scene import load_scene; print(len(load_scene(%r).meshes))" % (
        str(SCENES / "blocks_limestone_scarp.toml"))
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "1"
