"""The extension registry: every generator package is listed, and everything it declares
(node types, scene tables, commands, benchmarks) is reachable from a scene file, the CLI
or ``benchmarks/run.py``. Cheap: nothing here builds a tile or renders."""

from __future__ import annotations

import argparse
import importlib.util
import sys

import pytest

from helpers import REPO, variant

from arches_render import extensions
from arches_render.scene import SceneError, parse_scene
from arches_render.scene.nodes import NodeBuilder, node_types

SCENE = {"camera": {"origin": [0.0, -10.0, 2.0], "target": [0.0, 0.0, 0.0]},
         "lights": [{"type": "constant"}]}


def _declared(kind):
    return [(ext.name, name, value) for ext in extensions.extensions() for name, value in getattr(ext, kind).items()]


def test_registry_lists_every_generator_package():
    on_disk = sorted(p.parent.name for p in (REPO / "generators").glob("*/__init__.py"))
    assert sorted(extensions.GENERATORS) == on_disk
    assert [ext.name for ext in extensions.extensions()] == list(extensions.GENERATORS)
    for ext in extensions.extensions():
        assert ext.module.__name__ == f"arches_render.generators.{ext.name}"
        # Every package brings something: a command at least.
        assert ext.commands, ext.name


@pytest.mark.parametrize("generator, kind", [(g, k) for g, k, _ in _declared("node_types")])
def test_every_node_type_is_built_from_a_scene_table(tmp_path, generator, kind):
    """The loader dispatches the type to the generator's builder: an empty table of that
    type fails on one of the builder's own keys (never on ``type``) with a SceneError."""
    variant()
    builder = NodeBuilder({"n": {"type": kind}}, tmp_path / "s.toml", tmp_path)
    with pytest.raises(SceneError) as err:
        builder.named("n")
    assert err.value.key.startswith("nodes.n.") and err.value.key != "nodes.n.type", str(err.value)


def test_node_types_come_from_the_registry_once():
    types = node_types()
    for generator, kind, build in _declared("node_types"):
        assert types[kind] is build, (generator, kind)
    assert "sphere" in types and "heightfield" in types  # the core's own


@pytest.mark.parametrize("generator, table", [(g, t) for g, t, _ in _declared("scene_tables")])
def test_every_scene_table_is_read_from_a_scene_file(tmp_path, generator, table):
    variant()
    # An empty entry is refused with the table's own key path...
    with pytest.raises(SceneError) as err:
        parse_scene({**SCENE, table: [{}]}, tmp_path / "s.toml")
    assert err.value.key.startswith(f"{table}[0].")
    # ... and the registry's tables are what a scene without them holds.
    desc = parse_scene({**SCENE, "meshes": [{"shape": "sphere"}]}, tmp_path / "s.toml")
    assert getattr(desc, table) == [] and desc.tables[table] == []


def test_rock_pile_table_parses_into_a_renderable_item(tmp_path):
    variant()
    desc = parse_scene({**SCENE, "rock_piles": [{"support": {"shape": "sphere", "center": [0.0, 0.0, 0.0]},
                                                 "rock_size": 0.5}]}, tmp_path / "s.toml")
    (pile,) = desc.rock_piles
    assert desc.tables["rock_piles"] == [pile]
    assert pile.name == "rock_pile0" and callable(pile.shapes) and callable(pile.point_instancer)


def _names(module):
    sub = argparse.ArgumentParser().add_subparsers()
    module.register(sub)
    return set(sub.choices)


@pytest.mark.parametrize("module", extensions.commands(), ids=lambda m: m.__name__)
def test_every_command_is_a_cli_subcommand(module, capsys):
    from arches_render.cli import build_parser, main
    names = _names(module)
    assert names
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert names <= set(sub.choices)
    for name in names:
        with pytest.raises(SystemExit) as exc:
            main([name, "--help"])
        assert exc.value.code == 0
        assert name in capsys.readouterr().out


def test_every_benchmark_is_listed_by_run_py(monkeypatch):
    monkeypatch.syspath_prepend(str(REPO / "benchmarks"))
    spec = importlib.util.spec_from_file_location("benchmarks_run", REPO / "benchmarks" / "run.py")
    run = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "benchmarks_run", run)
    spec.loader.exec_module(run)
    listed = run.all_benchmarks()
    declared = extensions.benchmarks()
    assert declared
    for name, entry in declared.items():
        assert listed[name] is entry, name
        fn, repeat = entry
        assert callable(fn) and repeat >= 1
