"""The one registry of generator packages: what each paper's code adds to arches-render.

As Mitsuba's package ``__init__`` names its submodules and trimesh's
``exchange/load.py`` names its loaders, :data:`GENERATORS` names every generator
package; nothing scans folders. The scene loader, the CLI and ``benchmarks/run.py``
iterate this registry, and the core names no generator anywhere else.

A generator package ``arches_render.generators.NAME`` (folder ``generators/NAME/``)
declares in its ``extension.py`` (not its ``__init__.py``, which stays light so that
a worker process importing one module of the package imports no more than it needs):

``NODE_TYPES``     ``{type: build(table, builder) -> Node}``: node types of ``[nodes.*]``
                   tables. ``table`` is a :class:`~arches_render.scene.validate.Table`,
                   ``builder`` the scene's :class:`~arches_render.scene.nodes.NodeBuilder`
                   (operands, base folder, progress).
``SCENE_TABLES``   ``{name: parse(table, builder, field, materials, file, index) -> item}``:
                   top-level arrays of tables (``[[rock_piles]]``). ``field`` is the
                   scene's root node or ``None``, ``materials`` the scene's material
                   dicts (``parse`` may add one). An item renders as
                   ``item.shapes(bsdfs, progress=None)`` (Mitsuba shapes) and exports to
                   USD as ``item.point_instancer()`` (see
                   :func:`arches_render.mesh.usd_export.write_usd_stage`). An item whose
                   shapes surround the scene (a far field) may say where they lie,
                   ``item.ray_region() -> (hole, z0, z1)``: outside the open column over
                   the rectangle ``hole``, between heights ``z0`` and ``z1``; rays that
                   cannot reach there skip them (:mod:`arches_render.render.mesh_region`).
``COMMANDS``       names of the package's modules defining ``register(subparsers)``:
                   ``arches-render`` subcommands (see :mod:`arches_render.commands`).
                   Names, not modules: only the CLI imports them, so loading a scene
                   does not import what a command needs (``amplify`` alone imports
                   trimesh, scipy.optimize and numba: 0.56 s of every render process).
and in its ``benchmarks.py`` (imported by :func:`benchmarks` only: a render or a
worker process does not need them):

``BENCHMARKS``     ``{name: (fn(repeat) -> dict, default repeat)}``: figures of
                   ``benchmarks/run.py``.

A name defined twice (a node type, a table, a benchmark) is a bug and raises.
"""

from __future__ import annotations

import functools
import importlib
from dataclasses import dataclass
from types import ModuleType

__all__ = ["GENERATORS", "Extension", "extensions", "node_types", "scene_tables", "commands", "benchmarks"]

#: The generator packages, one per paper (see :mod:`arches_render.generators`).
GENERATORS = ("terrain", "rocks", "blocks", "layers", "gmaps")


@dataclass(frozen=True)
class Extension:
    """What one generator package declares (see the module docstring)."""

    name: str
    module: ModuleType
    node_types: dict
    scene_tables: dict
    commands: tuple


@functools.cache
def extensions() -> tuple[Extension, ...]:
    """The generator packages of :data:`GENERATORS`, imported once, in that order.

    Returns
    -------
    tuple of Extension
    """
    found = []
    for name in GENERATORS:
        module = importlib.import_module(f"arches_render.generators.{name}")
        declared = importlib.import_module(f"arches_render.generators.{name}.extension")
        found.append(Extension(name=name, module=module,
                               node_types=dict(getattr(declared, "NODE_TYPES", {})),
                               scene_tables=dict(getattr(declared, "SCENE_TABLES", {})),
                               commands=tuple(getattr(declared, "COMMANDS", ()))))
    return tuple(found)


def _merged(what: str, declared, taken=()) -> dict:
    """``{name: value}`` over ``(generator, {name: value})`` pairs; a name defined twice raises."""
    out = {}
    for generator, items in declared:
        for name, value in items.items():
            if name in out or name in taken:
                raise RuntimeError(f"{what} {name!r} of generators.{generator} is already defined")
            out[name] = value
    return out


def node_types(core=()) -> dict:
    """Node types of every generator; ``core`` names those the scene loader defines itself."""
    return _merged("node type", ((ext.name, ext.node_types) for ext in extensions()), core)


def scene_tables() -> dict:
    """Top-level scene tables of every generator, e.g. ``{'rock_piles': parse_rock_pile}``."""
    return _merged("scene table", ((ext.name, ext.scene_tables) for ext in extensions()))


def commands() -> list:
    """Command modules of every generator, in registry order (imported here, on first use)."""
    return [importlib.import_module(f"arches_render.generators.{ext.name}.{name}")
            for ext in extensions() for name in ext.commands]


def benchmarks(core=()) -> dict:
    """Benchmarks of every generator; ``core`` names those ``benchmarks/run.py`` defines itself."""
    return _merged("benchmark", ((ext.name, importlib.import_module(
        f"arches_render.generators.{ext.name}.benchmarks").BENCHMARKS) for ext in extensions()), core)
