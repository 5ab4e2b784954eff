"""Scene files are data and stay in their folder (issue 17).

Every key of a scene that names a file goes through one resolver
(:mod:`arches_render.scene.paths`): relative to the scene file, refused when it
leaves the scene's folder (absolute path, ``..``, a symbolic link pointing out)
unless ``--allow-path`` or ``$ARCHES_RENDER_PATH`` allows the folder; and nothing
in the code unpickles or executes what a scene names.
"""

from __future__ import annotations

import ast
import json
import os

import numpy as np
import pytest

from helpers import REPO, SCENES, variant
from robust_helpers import BASE_SCENE, assert_one_line_error, cli, write


@pytest.fixture(autouse=True)
def _variant():
    variant()


def _files(folder):
    """Valid files of every kind a scene may name, in ``folder``."""
    import trimesh
    from PIL import Image

    from arches_render.generators.layers.material_stacks import MaterialStacks
    folder.mkdir(parents=True, exist_ok=True)
    trimesh.creation.icosphere(subdivisions=1, radius=0.5).export(folder / "m.ply")
    a = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    np.savez(folder / "caps.npz", a=a, b=a + 0.1, radius=np.full(2, 0.2))
    np.save(folder / "dem.npy", np.random.default_rng(0).random((9, 9)).astype(np.float32))
    MaterialStacks.from_heightfield(np.ones((4, 4)), 0.5, (0.0, 0.0), 0.0, 2.0, 0.01,
                                    (("bedrock", None),)).save(folder / "s.npz")
    Image.fromarray((np.random.default_rng(1).random((8, 8, 3)) * 255).astype(np.uint8)).save(folder / "t.png")


# Each kind of file key, as a scene fragment; {p} is the path the scene gives.
KINDS = {
    "mesh": ('\n[[meshes]]\nfile = "{p}/m.ply"\n', "meshes[0].file"),
    "support": ('\n[[rock_piles]]\nsupport = {{ mesh = "{p}/m.ply" }}\nrock_size = 0.3\n',
                "rock_piles[0].support.mesh"),
    "capsules": ('\n[nodes.extra]\ntype = "capsule_set"\nfile = "{p}/caps.npz"\n', "nodes.extra.file"),
    "skeletal": ('\n[nodes.extra]\ntype = "skeletal_set"\nfile = "{p}/caps.npz"\n', "nodes.extra.file"),
    "dem": ('\n[nodes.extra]\ntype = "heightfield"\nsource = "file"\nfile = "{p}/dem.npy"\n'
            'extent = [-2.0, -2.0, 2.0, 2.0]\n', "nodes.extra.file"),
    "stacks": ('\n[nodes.extra]\ntype = "layers"\nsource = "stacks"\nfile = "{p}/s.npz"\n', "nodes.extra.file"),
    "texture": ("", "materials.m.overrides.rock.texture"),
    "envmap": ("", "lights[0].file"),
}


def _scene(folder, kind, p):
    frag, _ = KINDS[kind]
    text = BASE_SCENE
    if kind == "texture":
        text = text.replace("[field]\n", '[materials.m]\ntype = "triplanar"\npreset = "terrain"\n'
                                         f'overrides = {{ "rock.texture" = "{p}/t.png" }}\n'
                                         '[field]\nmaterial = "m"\n')
    elif kind == "envmap":
        text = text.replace('type = "constant"\nradiance = 1.0', f'type = "envmap"\nfile = "{p}/t.png"')
    elif "[nodes.extra]" in frag:
        text = text.replace('root = "ball"', 'root = { type = "union", children = ["ball", "extra"] }')
    return write(folder, text + frag.format(p=p))


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_every_file_key_is_refused_outside_the_scene_folder_and_allowed_on_request(tmp_path, capsys,
                                                                                   monkeypatch, kind):
    monkeypatch.delenv("ARCHES_RENDER_PATH", raising=False)
    outside = tmp_path / "elsewhere"
    _files(outside)
    scenes = tmp_path / "scenes"
    _, key = KINDS[kind]
    for p in (str(outside), "../elsewhere"):          # absolute, and .. above the scene's folder
        scene = _scene(scenes, kind, p)
        rc, err = cli(capsys, "info", scene)
        line = assert_one_line_error(rc, err, str(scene), key, "refused", "outside the scene's folder",
                                     "--allow-path", "ARCHES_RENDER_PATH")
        assert str(outside) in line
        rc, err = cli(capsys, "info", scene, "--allow-path", outside)
        assert rc == 0, err
    monkeypatch.setenv("ARCHES_RENDER_PATH", os.pathsep.join(["/nonexistent", str(outside)]))
    rc, err = cli(capsys, "info", scene)
    assert rc == 0, err


def test_links_pointing_out_of_the_folder_are_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ARCHES_RENDER_PATH", raising=False)
    _files(tmp_path / "elsewhere")
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    (scenes / "data").symlink_to(tmp_path / "elsewhere")
    scene = _scene(scenes, "capsules", "data")
    rc, err = cli(capsys, "info", scene)
    assert_one_line_error(rc, err, "nodes.extra.file", "refused", str(tmp_path / "elsewhere"))
    # Inside the folder, sub-folders and links that stay inside are fine.
    _files(scenes / "own")
    (scenes / "alias").symlink_to(scenes / "own")
    for p in ("own", "alias", "./own/../own", str(scenes / "own")):
        rc, err = cli(capsys, "info", _scene(scenes, "capsules", p))
        assert rc == 0, (p, err)


def test_allow_path_travels_with_render_jobs(tmp_path, monkeypatch):
    """Tiles and frames render in other processes: the job carries the folders allowed where it was made."""
    from arches_render.render.jobs import RenderJob
    from arches_render.scene import paths
    monkeypatch.setenv("ARCHES_RENDER_PATH", str(tmp_path / "env"))
    with paths.allowed([tmp_path / "cli"]):
        job = RenderJob(scene="s.toml", width=4, height=4, spp=1)
    assert job.allow == (str((tmp_path / "cli").resolve()), str((tmp_path / "env").resolve()))
    assert paths.extra_folders() == (str((tmp_path / "env").resolve()),)  # the block's folders are gone again


def test_every_subcommand_that_reads_scenes_has_allow_path():
    from arches_render.cli import build_parser
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    for name in ("render", "turntable", "mesh", "info", "rocks", "blocks", "layers"):
        dests = {a.dest for a in sub[name]._actions}
        assert {"scene", "allow_path"} <= dests, name


def test_shipped_scenes_read_only_inside_their_folder(monkeypatch):
    """No shipped scene needs --allow-path (they keep their data under scenes/)."""
    from arches_render.scene import load_scene
    monkeypatch.delenv("ARCHES_RENDER_PATH", raising=False)
    for path in sorted(SCENES.rglob("*.toml")):
        load_scene(path)


# ------------------------------------------------------------------------ nothing unpickled, nothing run
def _calls(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            if isinstance(f, ast.Name):
                yield node, "", f.id
            elif isinstance(f, ast.Attribute):
                yield node, f.value.id if isinstance(f.value, ast.Name) else "?", f.attr


def _sources():
    for top in ("arches_render", "generators", "materials", "examples", "benchmarks", "tests"):
        yield from sorted((REPO / top).rglob("*.py"))


def test_every_np_load_refuses_pickles():
    """``np.load`` / ``numpy.load`` always with ``allow_pickle=False`` (a literal), everywhere in the repository."""
    bad, seen = [], 0
    for path in _sources():
        tree = ast.parse(path.read_text(), str(path))
        for node, base, name in _calls(tree):
            if name == "load" and base in ("np", "numpy"):
                seen += 1
                kw = {k.arg: k.value for k in node.keywords}
                v = kw.get("allow_pickle")
                if not (isinstance(v, ast.Constant) and v.value is False):
                    bad.append(f"{path.relative_to(REPO)}:{node.lineno}")
    assert seen >= 5  # the scan sees the calls (a broken scan would pass vacuously)
    assert not bad, f"np.load without allow_pickle=False: {bad}"


def test_no_code_path_unpickles_or_executes_data():
    """No pickle/marshal/shelve loads, eval, exec or dynamic imports of names from data in the package."""
    bad = []
    for path in _sources():
        if path.parts[-2] == "tests" and path.name == "test_robust_paths.py":
            continue
        tree = ast.parse(path.read_text(), str(path))
        for node, base, name in _calls(tree):
            hit = ((base in ("pickle", "marshal", "shelve", "dill", "cloudpickle") and name.startswith("load"))
                   or (base == "" and name in ("eval", "exec", "__import__"))
                   or (base == "yaml" and name in ("load", "unsafe_load")))
            if base == "importlib" and name == "import_module":
                # The registry imports the generator packages it names itself (extensions.GENERATORS).
                hit = not str(path).endswith(os.path.join("arches_render", "extensions.py"))
            if hit:
                bad.append(f"{path.relative_to(REPO)}:{node.lineno} {base + '.' if base else ''}{name}")
    assert not bad, bad


def test_array_reader_refuses_object_arrays_without_unpickling(tmp_path):
    """The .npz reader reads headers first: an object array is refused before any pickle is touched."""
    import pickle

    from arches_render.scene.array_files import ArrayFileError, Spec, read_arrays

    class Boom:
        def __reduce__(self):
            return (os.system, ("touch " + str(tmp_path / "pwned"),))

    np.savez(tmp_path / "evil.npz", a=np.array([Boom()], dtype=object))
    assert pickle  # the payload above is a real pickle
    with pytest.raises(ArrayFileError, match="Python objects"):
        read_arrays(tmp_path / "evil.npz", {"a": Spec((None,))})
    assert not (tmp_path / "pwned").exists()
    json.dumps(str(tmp_path))  # noqa: the folder name is plain text
