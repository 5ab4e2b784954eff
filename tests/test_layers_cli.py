"""``arches-render layers`` and the ``layers`` scene nodes as a user meets them."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from helpers import REPO, variant

SCENE = textwrap.dedent("""
    [camera]
    origin = [-10.0, -10.0, 6.0]
    target = [4.0, 4.0, 1.0]
    [[lights]]
    type = "constant"
    [materials.ground]
    type = "triplanar"
    preset = "sandstone"
    masks = [{ layer = "sand", node = { type = "layers_ratio", terrain = "land" }, lo = 0.2, hi = 0.6 }]
    [field]
    root = "land"
    material = "ground"
    [nodes.land]
    type = "layers"
    source = "flat"
    extent = [0.0, 0.0, 8.0, 8.0]
    cell = 0.5
    elevation = 1.0
    z_range = [-1.0, 5.0]
    dz = 0.01
    column = [{ material = "sand", thickness = 0.2 }, { material = "bedrock" }]
    seed = 2
    [[nodes.land.operations]]
    tool = "deposit"
    center = [4.0, 4.0]
    radius = 2.0
    amount = 1.5
    [[nodes.land.operations]]
    tool = "sweep"
    path = [[0.0, 4.0, 1.0], [8.0, 4.0, 1.0]]
    profile = [[-0.5, -0.3], [0.5, -0.3], [0.0, 0.5]]
    mode = "crack"
""")


def run_cli(*args, cwd=None):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run([sys.executable, "-m", "arches_render.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd or REPO, env=env, timeout=300)


def test_cli_saves_the_edited_stacks(tmp_path):
    from arches_render.generators.layers.material_stacks import SAND, MaterialStacks
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out" / "land.npz"
    out.parent.mkdir()  # an explicit -o needs its folder
    r = run_cli("layers", scene, "-o", out, "-q")
    assert r.returncode == 0, r.stderr
    assert "wrote" in r.stdout and "Traceback" not in r.stderr
    S = MaterialStacks.load(out)
    assert (S.nx, S.ny) == (16, 16)
    # Flat sand 0.2 m on 256 columns, plus the deposit, minus the crack's share.
    assert S.levels((SAND,)) > 256 * 20
    assert S.heights().max() > 1.5
    # The saved stacks load back as a source, and the scene builds the same terrain.
    variant()
    from arches_render.scene import load_scene
    desc = load_scene(scene)
    assert desc.field.stacks == S
    head = SCENE.split("[nodes.land]")[0]
    (tmp_path / "again.toml").write_text(head + '[nodes.land]\ntype = "layers"\nsource = "stacks"\n'
                                                'file = "out/land.npz"\n')
    assert load_scene(tmp_path / "again.toml").field.stacks == S


BAD = [
    ("cell = 0.5", "cell = -0.5", "nodes.land.cell", "> 0"),
    ("cell = 0.5", "cell = 0.3", "nodes.land.extent", "whole number of cells"),
    ("amount = 1.5", "amount = 1.5\n    colour = 2", "operations[0].colour", "unknown key"),
    ('tool = "deposit"', 'tool = "melt"', "operations[0].tool", "one of"),
    ('mode = "crack"', 'mode = "zigzag"', "operations[1].mode", "one of"),
    ('material = "sand", thickness = 0.2', 'material = "lava", thickness = 0.2', "column[0].material", "one of"),
    ("dz = 0.01", "dz = 0.00001", "nodes.land.dz", ">="),
    ('terrain = "land"', 'terrain = "nowhere"', "terrain", "unknown node"),
]


@pytest.mark.parametrize("old, new, key, hint", BAD)
def test_bad_scene_values_exit_2_with_one_line(tmp_path, capsys, old, new, key, hint):
    """Each bad value, through the CLI: `info` (reads the whole scene) and `layers` (builds the
    node): exit 2, one line naming the key and the allowed values, and no output file."""
    from arches_render.cli import main
    assert old in SCENE
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE.replace(old, new, 1))
    out = tmp_path / "x.npz"
    commands = [["info", str(scene)]]
    if "terrain" not in key:  # a mask of the material, which the layers command does not read
        commands.append(["layers", str(scene), "-o", str(out), "-q"])
    for argv in commands:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert err.startswith("arches-render: error:") and "\n" not in err, (argv, err)
        assert key in err and hint in err and str(scene) in err, (argv, err)
        assert not out.exists()


def test_cli_bad_scene_value_exits_2_without_output(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE.replace('tool = "deposit"', 'tool = "melt"'))
    out = tmp_path / "x.npz"
    r = run_cli("layers", scene, "-o", out, "-q")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "operations[0].tool" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_cli_usage_errors(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    r = run_cli("layers", scene, "-o", tmp_path / "x.exr")
    assert r.returncode == 2 and ".npz" in r.stderr and "Traceback" not in r.stderr
    r = run_cli("layers", tmp_path / "missing.toml", "-o", tmp_path / "x.npz")
    assert r.returncode == 2 and "no such scene file" in r.stderr
    assert not (tmp_path / "x.npz").exists()


def test_node_option_names_a_layers_node(tmp_path, capsys):
    from arches_render.cli import main
    from arches_render.generators.layers.material_stacks import MaterialStacks
    # Two layers nodes: the command needs --node, refuses a name that is not one of them, and
    # builds the one named.
    second = SCENE.split("[nodes.land]")[1].split("[[nodes.land.operations]]")[0]
    second = second.replace("extent = [0.0, 0.0, 8.0, 8.0]", "extent = [0.0, 0.0, 4.0, 6.0]")
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE + "\n[nodes.hill]\ntype = \"sphere\"\nradius = 1.0\n[nodes.small]" + second)
    out = tmp_path / "x.npz"
    assert main(["layers", str(scene), "-o", str(out), "-q"]) == 2
    assert "several layers nodes (land, small)" in capsys.readouterr().err
    assert main(["layers", str(scene), "-o", str(out), "--node", "hill", "-q"]) == 2
    err = capsys.readouterr().err
    assert "--node must name a layers node" in err and "(land, small; got 'hill')" in err
    assert not out.exists()
    assert main(["layers", str(scene), "-o", str(out), "--node", "small", "-q"]) == 0
    S = MaterialStacks.load(out)
    assert (S.nx, S.ny) == (8, 12)  # the 4 x 6 m node at 0.5 m cells, not the 8 x 8 m one
