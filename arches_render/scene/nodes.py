"""Build field nodes from the ``[field]`` and ``[nodes.*]`` tables of a scene file.

A node is a table with a ``type``; operands are given by ``child`` / ``children``,
each either the name of a table under ``[nodes]`` or an inline table. Lengths are
metres, angles degrees; ``[ ]`` marks an optional key and its default.

=====================  ==================================================================
type                   keys
=====================  ==================================================================
sphere                 center, radius > 0
box                    center, size (3 numbers >= 0), [rounding = 0]
capsule                a, b, radius > 0
plane                  normal (non-zero), [point = origin]  (unbounded: intersect it)
heightfield            extent = [x0, y0, x1, y1], [base], [source = "fbm" | "file"];
                       fbm: [resolution = [256, 256]], amplitude, wavelength, octaves,
                       lacunarity, gain, seed, [ridged], [power = 1], [offset = 0],
                       [edge_falloff = 0]; file: file (.npy, 16-bit .png, .tif),
                       [height_scale = 1], [height_offset = 0], [dequantize = false]
                       (heights on a visible lattice, whole metres on gentle slopes or an
                       8-bit image, smoothed within half a step:
                       :mod:`arches_render.field.dequantize`; amplify always does it)
union, intersection    children (>= 1)
difference             children (>= 2): the first minus the others
blend                  children, radius > 0 (smooth union)
smooth_intersection    children, radius > 0
translate              child, offset
rotate                 child, axis, angle, [pivot]
scale                  child, factor (number or 3 numbers > 0), [pivot]
noise                  [amplitude = 1], [wavelength = 1], [octaves = 4], [lacunarity = 2],
                       [gain = 0.5], [seed = 0]
displace               child + the noise keys: child's field plus fBm
warp                   child + the noise keys (octaves = 3): domain warp
capsule_set            file (.npz with a, b, radius) or inline a, [b = a], radius
=====================  ==================================================================

Generators add node types of their own: a generator package declares
``NODE_TYPES = {name: build(table, builder) -> Node}`` in the registry
(:mod:`arches_render.extensions`; by convention built in its ``scene_nodes.py``,
which documents the keys in the same kind of table); :func:`node_types` merges
them with the ones above.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from .. import extensions, field as F
from ..field.heightmaps import DEMError, fbm_heightmap, read_dem
from ..resources import ResourceError, check_memory, heightmap_bytes
from .array_files import Spec, read_arrays
from .errors import SceneError
from .paths import scene_file
from .validate import Table


#: Deepest nesting of node tables (inline or named) a scene may use.
MAX_NESTING = 100


def fbm_args(t: Table, amplitude=1.0, wavelength=1.0, octaves=4):
    """The fBm keys (amplitude, wavelength, octaves, lacunarity, gain, seed) of a node table.

    Shared by every node with noise, core or generator's, so the keys and ranges agree.
    """
    return dict(amplitude=t.number("amplitude", amplitude),
                wavelength=t.number("wavelength", wavelength, lo=0, lo_open=True),
                octaves=t.integer("octaves", octaves, lo=1, hi=12),
                lacunarity=t.number("lacunarity", 2.0, lo=1.0, hi=4.0),
                gain=t.number("gain", 0.5, lo=0.0, hi=1.0),
                seed=t.integer("seed", 0, lo=0, hi=2 ** 32 - 1))


def load_heights(t: Table, base_dir: Path) -> np.ndarray:
    """Heights (metres) of the table's ``file``, scaled by ``height_scale`` and offset, and
    with ``dequantize`` smoothed within half their lattice's step where it shows.

    One DEM reader for scenes and ``amplify`` (:func:`arches_render.field.heightmaps.read_dem`:
    formats, no-data filling, size limits). Not smoothed by default: it costs a second
    or more a million samples at every load, and a scene's heights are what its file says.
    """
    try:
        H = read_dem(scene_file(t, "file", base_dir=base_dir, what="DEM"), max_samples=8192 * 8192).heights
    except DEMError as exc:
        raise t.error("file", str(exc)) from None
    H = H * t.number("height_scale", 1.0) + t.number("height_offset", 0.0)
    if t.boolean("dequantize", False):
        from ..field.dequantize import dequantize, quantization_step
        step = quantization_step(H)
        if step is not None:
            H = dequantize(H, step)
    return H


def heightfield_node(t: Table, ctx):
    """A ``heightfield`` node from its table (also the core of ``implicit_heightfield``)."""
    x0, y0, x1, y1 = t.vector("extent", 4)
    if not (x1 > x0 and y1 > y0):
        raise t.error("extent", f"must be [x0, y0, x1, y1] with x1 > x0 and y1 > y0 (got {[x0, y0, x1, y1]})")
    base = t.number("base", None)
    source = t.string("source", "fbm", choices={"fbm", "file"})
    if source == "file":
        H = load_heights(t, ctx.base_dir)
    else:
        res = t.raw("resolution", [256, 256])
        if (not isinstance(res, list) or len(res) != 2
                or not all(isinstance(v, int) and 2 <= v <= 8192 for v in res)):
            raise t.error("resolution", f"must be [nx, ny] with integers in [2, 8192] (got {res!r})")
        try:
            check_memory(heightmap_bytes(*res), f"the {res[0]}x{res[1]} fBm heightmap")
        except ResourceError as exc:
            raise t.error("resolution", str(exc)) from None
        H = fbm_heightmap((x0, y0, x1, y1), res, ridged=t.boolean("ridged", False),
                          power=t.number("power", 1.0, lo=0.1, hi=8.0),
                          offset=t.number("offset", 0.0),
                          edge_falloff=t.number("edge_falloff", 0.0, lo=0.0),
                          **fbm_args(t, amplitude=30.0, wavelength=80.0, octaves=6))
    return F.Heightfield(H, (x0, y0, x1, y1), base=base)


def children(t: Table, ctx, minimum):
    """The operand nodes of ``children`` (at least ``minimum``)."""
    items = t.raw("children")
    if not isinstance(items, list) or len(items) < minimum:
        raise t.error("children", f"must be an array of at least {minimum} node names or tables")
    return [ctx.build(item, t, f"children[{i}]") for i, item in enumerate(items)]


def child(t: Table, ctx):
    """The operand node of ``child``."""
    return ctx.build(t.raw("child"), t, "child")


#: The arrays of a ``capsule_set`` file.
CAPSULE_SPECS = {"a": Spec(("n", 3)), "b": Spec(("n", 3), required=False),
                 "radius": Spec(("n",), scalar=True, lo=0.0, lo_open=True)}


def _capsule_set(t: Table, ctx):
    if t.has("file"):
        path = scene_file(t, "file", (".npz",), ctx.base_dir, what="capsule file")
        try:
            data = read_arrays(path, CAPSULE_SPECS, "capsule arrays")
        except ValueError as exc:
            raise t.error("file", f"cannot read arrays a, b, radius from {path.name}: {exc}") from None
        a, r = data["a"], data["radius"]
        b = data.get("b", a)
    else:
        a = np.asarray(t.raw("a"), dtype=np.float64)
        b = np.asarray(t.raw("b", t.data.get("a")), dtype=np.float64)
        r = np.asarray(t.raw("radius"), dtype=np.float64)
    try:
        return F.CapsuleSet(a, b, r)
    except ValueError as exc:
        raise t.error("a", str(exc)) from None


NODE_TYPES = {
    "sphere": lambda t, c: F.Sphere(t.vector("center"), t.number("radius", lo=0, lo_open=True)),
    "box": lambda t, c: F.Box(t.vector("center"), np.asarray(t.vector("size", lo=0)) / 2,
                              t.number("rounding", 0.0, lo=0.0)),
    "capsule": lambda t, c: F.Capsule(t.vector("a"), t.vector("b"), t.number("radius", lo=0, lo_open=True)),
    "plane": lambda t, c: F.Plane(t.vector("normal", nonzero=True), t.vector("point", default=[0, 0, 0])),
    "heightfield": heightfield_node,
    "union": lambda t, c: F.Union(*children(t, c, 1)),
    "intersection": lambda t, c: F.Intersection(*children(t, c, 1)),
    "difference": lambda t, c: F.Difference(*children(t, c, 2)),
    "blend": lambda t, c: F.Blend(*children(t, c, 1), radius=t.number("radius", lo=0, lo_open=True)),
    "smooth_intersection": lambda t, c: F.SmoothIntersection(
        *children(t, c, 1), radius=t.number("radius", lo=0, lo_open=True)),
    "translate": lambda t, c: F.Transform.translate(child(t, c), t.vector("offset")),
    "rotate": lambda t, c: F.Transform.rotate(child(t, c), t.vector("axis", nonzero=True),
                                              t.number("angle"), t.vector("pivot", default=[0, 0, 0])),
    "scale": lambda t, c: F.Transform.scale(child(t, c), _scale_factor(t),
                                            t.vector("pivot", default=[0, 0, 0])),
    "noise": lambda t, c: F.Noise(**fbm_args(t)),
    "displace": lambda t, c: F.Displace(child(t, c), **fbm_args(t)),
    "warp": lambda t, c: F.DomainWarp(child(t, c), **fbm_args(t, octaves=3)),
    "capsule_set": _capsule_set,
}


@functools.cache
def node_types() -> dict:
    """All node types: the core ones of this module and those of the generators.

    The generators' come from the registry (:func:`arches_render.extensions.node_types`),
    read once; a type defined twice raises.
    """
    return {**NODE_TYPES, **extensions.node_types(core=NODE_TYPES)}


def _scale_factor(t: Table):
    v = t.raw("factor")
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return t.number("factor", lo=0, lo_open=True)
    return t.vector("factor", lo=1e-9)


class NodeBuilder:
    """Resolves node names and inline tables into field nodes, once each.

    The context a node type's ``build(table, builder)`` receives (the scene-plugin
    API of the generators).

    Parameters
    ----------
    nodes_table : dict
        The ``[nodes]`` tables by name.
    file : str or Path
        The scene file, for messages.
    base_dir : Path
        Folder that relative paths of the tables start from.
    progress : callable, optional
        ``progress(done, total)`` for a long build step of a node (a command's bar);
        node types that report progress call it, others ignore it.
    """

    def __init__(self, nodes_table: dict, file, base_dir: Path, progress=None):
        self.defs = nodes_table or {}
        self.file = file
        self.base_dir = base_dir
        self.progress = progress
        self.built: dict[str, F.Node] = {}
        self.stack: list[str] = []
        self.depth = 0

    def define(self, name: str, table: dict) -> None:
        """Add the named node table ``name`` (as if under ``[nodes]``); it is built on first use.

        Raises
        ------
        ValueError
            When ``name`` is already defined.
        """
        if name in self.defs:
            raise ValueError(f"node {name!r} is already defined")
        self.defs[name] = table

    def forget(self, name: str) -> None:
        """Remove the named table ``name`` and the node built from it (a generator's temporary node)."""
        del self.defs[name]
        self.built.pop(name, None)

    def build(self, item, parent: Table, key: str) -> F.Node:
        if isinstance(item, str):
            return self.named(item, parent, key)
        if isinstance(item, dict):
            return self.node(Table(item, self.file, parent.key(key)))
        raise parent.error(key, f"must be a node name or an inline table (got {item!r})")

    def named(self, name: str, parent: Table | None = None, key: str = "") -> F.Node:
        if name in self.built:
            return self.built[name]
        if name not in self.defs:
            known = ", ".join(sorted(self.defs)) or "none defined"
            msg = f"refers to unknown node '{name}' (nodes: {known})"
            raise parent.error(key, msg) if parent else SceneError(self.file, "field.root", msg)
        if name in self.stack:
            raise SceneError(self.file, f"nodes.{name}", f"is part of a cycle: {' -> '.join(self.stack + [name])}")
        self.stack.append(name)
        node = self.node(Table(self.defs[name], self.file, f"nodes.{name}"))
        self.stack.pop()
        self.built[name] = node
        return node

    def node(self, t: Table) -> F.Node:
        types = node_types()
        kind = t.string("type", choices=set(types))
        if self.depth >= MAX_NESTING:
            # Building, bounding and evaluating a tree recurse once per level: a
            # deeper tree would end in Python's RecursionError, not in a clear error.
            raise SceneError(self.file, t.path, f"nodes are nested deeper than {MAX_NESTING} levels")
        self.depth += 1
        try:
            node = types[kind](t, self)
        except SceneError:
            raise
        except ValueError as exc:  # a constructor's own check: name the node
            raise SceneError(self.file, t.path, str(exc)) from None
        finally:
            self.depth -= 1
        t.finish()
        return node
