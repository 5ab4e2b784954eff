"""The ``[[rock_piles]]`` table of scene files and its rendering as flat Mitsuba meshes.

Keys (lengths in metres; ``[ ]`` marks an optional key and its default):

=====================  ==================================================================
key                    meaning
=====================  ==================================================================
support                ``"field"`` (the scene's ``[field]``), the name of a node under
                       ``[nodes]``, or an inline table with one of
                       ``node = {...}`` (a field node), ``shape = "sphere" | "box" |
                       "cylinder" | "torus"`` with center, [radius = 1], [size],
                       [height = 1], [thickness = 0.25], or ``mesh = "file.ply"``
                       (closed PLY/OBJ/STL, [translate], [scale])
extent                 [x0, y0, z0, x1, y1, z1]; default: the support's bounds (required
                       when they are infinite)
rock_size > 0          metres per cell (a rock is about one cell across)
[tiling = "aperiodic"] "aperiodic" (corner cubes) or "periodic" (the Arches tile)
[n = 5]                cells per corner cube edge, 4..12
[seed = 0]             tiles and lattice colouring
[seeds_per_cell]       [min, max] = [1, 1]
[g_max = 4]            g_k uniform in [1, g_max]
[alpha, beta, gamma]   intervals of the metric coefficients, [1, 1] each
[voxels_per_cell = 10] the paper's n_G / n
[mesh_step = 1]        marching-cubes step in voxels (2: about 4x fewer triangles)
[poisson_radius = 0.1] periodic tile: Poisson sphere radius in tile units
[erosion]              {steps = 10, rate = 0.5, contact_radius = 0.12, blend_radius
                       = 0.35, smoothing = 0.8}; radii in cells, smoothing in voxels
[min_inside = 0.5]     fraction of a rock's anchors inside the support to keep it
[offset = [0, 0, 0]]   world position of the lattice origin (shifts the tiling)
[material = "NAME"]    a ``[materials.NAME]`` of the scene, or
[preset = "basalt"]    a triplanar preset, forced to object space, with [overrides]
=====================  ==================================================================

Tiles are built on first use and cached (:mod:`.tile_cache`, in the project's
cache: :mod:`arches_render.cache`); the rocks become one Mitsuba mesh per tile
(or group of tiles) with baked transforms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field as dc_field
from pathlib import Path

import numpy as np

from arches_render.field.node import finite_box
from arches_render.materials import presets
from arches_render.scene.errors import SceneError
from arches_render.scene.mesh_files import read_mesh
from arches_render.scene.paths import scene_file

from . import instancing as ins
from .instancing import instance_buffers
from .mitsuba_meshes import rock_meshes_mitsuba
from .seed_points import SeedParams
from .tile_cache import load_or_build
from .tile_params import TILINGS, ErosionParams, TileParams

__all__ = ["RockPile", "parse_rock_pile"]


@dataclass
class RockPile:
    """A validated ``[[rock_piles]]`` entry; :meth:`shapes` builds its meshes (cached).

    An item of a scene table (:mod:`arches_render.extensions`): :attr:`name` prefixes
    the ids of its Mitsuba shapes, :meth:`shapes` renders it, :meth:`point_instancer`
    exports it.
    """

    index: int
    params: TileParams
    support: object
    extent: tuple
    rock_size: float
    offset: np.ndarray
    min_inside: float
    material: str
    stats: dict = dc_field(default_factory=dict)
    _buffers: list | None = None

    @property
    def name(self) -> str:
        """``rock_pile<index>``: prefix of its shape ids (and of its preset material)."""
        return f"rock_pile{self.index}"

    def instances(self, progress=None):
        """The selected rocks (:class:`.instancing.RockInstances`), building or loading tiles."""
        store, source = load_or_build(self.params, progress=progress)
        lo, hi = (np.asarray(e, float) for e in self.extent)
        ids, offs = ins.candidate_rocks(store, (lo - self.offset) / self.rock_size,
                                        (hi - self.offset) / self.rock_size, self.params.seed)
        keep, stats = ins.select_rocks(store, ids, offs, self.support, self.rock_size, self.offset,
                                       self.min_inside)
        self.stats = dict(stats, tiles=source, stones_in_set=len(store))
        return ins.RockInstances(store, ids[keep], offs[keep], self.rock_size, self.offset)

    def buffers(self, progress=None) -> list:
        """World-space vertex buffers merged per tile (computed once)."""
        if self._buffers is None:
            self._buffers = instance_buffers(self.instances(progress))
        return self._buffers

    def shapes(self, bsdfs: dict, progress=None) -> list:
        """Mitsuba meshes of the pile with the pile's BSDF from ``bsdfs``."""
        return rock_meshes_mitsuba(self.buffers(progress), bsdfs[self.material])

    def point_instancer(self) -> dict | None:
        """The pile as instances of the stones of its tile set (for a USD PointInstancer).

        A rock is ``origin + (stone vertex + slot offset) * cell``: the prototypes are
        the stones used, in tile-cell units, placed at ``origin + offset * cell`` and
        scaled by ``cell``.

        Returns
        -------
        dict or None
            ``name`` (of the prim, ``rock_pile_<index>``), ``prototypes``
            ``[(name, vertices, faces, normals)]``, ``proto_index`` ``(K,)``,
            ``positions`` ``(K, 3)`` and ``scales`` ``(K, 3)``; ``None`` when no rock is
            kept.
        """
        inst = self.instances()
        if len(inst) == 0:
            return None
        st = inst.store
        used, proto_index = np.unique(inst.ids, return_inverse=True)
        prototypes = [(f"stone_{int(r)}", st.vertices[st.vstart[r]:st.vstart[r + 1]],
                       st.faces[st.fstart[r]:st.fstart[r + 1]], st.normals[st.vstart[r]:st.vstart[r + 1]])
                      for r in used]
        pos = np.asarray(inst.origin, np.float64) + np.asarray(inst.offsets, np.float64) * inst.cell
        return dict(name=f"rock_pile_{self.index}", prototypes=prototypes, proto_index=proto_index.astype(np.int32).ravel(),
                    positions=pos.astype(np.float32), scales=np.full((len(inst), 3), inst.cell, np.float32))


def _interval(t, key, lo, hi):
    v = t.raw(key, [1.0, 1.0])
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        v = [v, v]
    if (not isinstance(v, list) or len(v) != 2
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
            or not lo <= v[0] <= v[1] <= hi):
        raise t.error(key, f"must be [min, max] with {lo} <= min <= max <= {hi} (got {v!r})")
    return (float(v[0]), float(v[1]))


def _support(t, builder, field_node, base_dir: Path):
    item = t.raw("support")
    if isinstance(item, str):
        if item == "field":
            if field_node is None:
                raise t.error("support", "is \"field\" but the scene has no [field]")
            return ins.FieldSupport(field_node)
        return ins.FieldSupport(builder.named(item, t, "support"))
    s = t.table("support")
    kinds = [k for k in ("node", "shape", "mesh") if s.has(k)]
    if len(kinds) != 1:
        raise t.error("support", 'must be "field", a node name, or a table with exactly one of '
                                 f"node, shape, mesh (got {sorted(s.data)})")
    if kinds[0] == "node":
        sup = ins.FieldSupport(builder.build(s.raw("node"), s, "node"))
    elif kinds[0] == "shape":
        shape = s.string("shape", choices=set(ins.SHAPES))
        sup = ins.ShapeSupport(shape, s.vector("center"),
                               radius=s.number("radius", 1.0, lo=0, lo_open=True),
                               size=s.vector("size", default=[1.0, 1.0, 1.0], lo=1e-9),
                               height=s.number("height", 1.0, lo=0, lo_open=True),
                               thickness=s.number("thickness", 0.25, lo=0, lo_open=True))
    else:
        path = scene_file(s, "mesh", (".ply", ".obj", ".stl"), base_dir, what="mesh")
        mesh = read_mesh(path, s, "mesh", closed=True, process=True).mesh
        mesh.apply_scale(s.number("scale", 1.0, lo=0, lo_open=True))
        mesh.apply_translation(s.vector("translate", default=[0.0, 0.0, 0.0]))
        try:
            sup = ins.MeshSupport(mesh)
        except ValueError as exc:
            raise s.error("mesh", f"{path.name}: {exc}") from None
    s.finish()
    return sup


def parse_rock_pile(t, builder, field_node, materials: dict, scene_file, index: int):
    """Validate one ``[[rock_piles]]`` table.

    Parameters
    ----------
    t : arches_render.scene.validate.Table
    builder : arches_render.scene.nodes.NodeBuilder
    field_node : Node or None
        The scene's ``[field]`` root.
    materials : dict
        The scene's materials; a ``preset`` adds ``rock_pile<index>`` to it.
    scene_file : Path
    index : int

    Returns
    -------
    RockPile

    Raises
    ------
    SceneError
        Naming the file, the key and the allowed range.
    """
    scene_file = Path(scene_file)
    support = _support(t, builder, field_node, scene_file.parent)
    rock_size = t.number("rock_size", lo=0, lo_open=True)
    er = t.table("erosion", {})
    try:
        erosion = ErosionParams(steps=er.integer("steps", 10, lo=0, hi=200),
                                rate=er.number("rate", 0.5, lo=0, hi=1, lo_open=True),
                                contact_radius=er.number("contact_radius", 0.12, lo=0, hi=2),
                                blend_radius=er.number("blend_radius", 0.35, lo=0, hi=2, lo_open=True),
                                smoothing=er.number("smoothing", 0.8, lo=0, hi=3))
    except ValueError as exc:
        raise er.error("blend_radius", str(exc)) from None
    er.finish()
    spc = t.raw("seeds_per_cell", [1, 1])
    if (not isinstance(spc, list) or len(spc) != 2 or not all(isinstance(v, int) and not isinstance(v, bool)
                                                              for v in spc) or not 1 <= spc[0] <= spc[1] <= 64):
        raise t.error("seeds_per_cell", f"must be [min, max] integers with 1 <= min <= max <= 64 (got {spc!r})")
    vpc = t.integer("voxels_per_cell", 10, lo=4, hi=24)
    if vpc % 2:
        raise t.error("voxels_per_cell", f"must be an even integer in [4, 24] (got {vpc})")
    params = TileParams(
        tiling=t.string("tiling", "aperiodic", choices=set(TILINGS)),
        n=t.integer("n", 5, lo=4, hi=12), voxels_per_cell=vpc,
        seed=t.integer("seed", 0, lo=0, hi=2 ** 31 - 1),
        seeds=SeedParams(seeds_per_cell=tuple(spc), g_max=t.number("g_max", 4.0, lo=1.0, hi=16.0),
                         alpha=_interval(t, "alpha", 0.05, 20), beta=_interval(t, "beta", 0.05, 20),
                         gamma=_interval(t, "gamma", 0.05, 20)),
        erosion=erosion, poisson_radius=t.number("poisson_radius", 0.1, lo=0.04, hi=0.3),
        mesh_step=t.integer("mesh_step", 1, lo=1, hi=3))
    min_inside = t.number("min_inside", 0.5, lo=0, hi=1, lo_open=True)
    offset = np.asarray(t.vector("offset", default=[0.0, 0.0, 0.0]), float)

    if t.has("extent"):
        ext = t.vector("extent", 6)
        lo, hi = np.asarray(ext[:3]), np.asarray(ext[3:])
        if not np.all(hi > lo):
            raise t.error("extent", f"must be [x0, y0, z0, x1, y1, z1] with x1 > x0, y1 > y0, z1 > z0 (got {ext})")
    else:
        box = finite_box(support)
        if box is None:
            raise t.error("extent", "is required: the support is unbounded")
        lo, hi = box
        pad = 2 * rock_size
        lo, hi = lo - pad, hi + pad
    cells = float(np.prod((hi - lo) / rock_size))
    if not math.isfinite(cells) or cells > 4e6:
        raise t.error("rock_size", f"is too small for the extent: {cells:.3g} cells (at most 4e6)")

    if t.has("material") and t.has("preset"):
        raise t.error("preset", "give either material or preset, not both")
    if t.has("preset"):
        over = t.raw("overrides", {})
        if not isinstance(over, dict):
            raise t.error("overrides", "must be a table")
        try:
            material = f"rock_pile{index}"
            materials[material] = presets.preset_dict(t.string("preset"), dict(over, space="object"))
        except ValueError as exc:
            raise t.error("overrides" if over else "preset", str(exc)) from None
    else:
        material = t.string("material", "default")
        if material not in materials:
            raise t.error("material", f"unknown material '{material}' (defined: {', '.join(sorted(materials))})")
    t.finish()
    try:
        return RockPile(index=index, params=params, support=support, extent=(lo, hi),
                        rock_size=rock_size, offset=offset,
                        min_inside=min_inside, material=material)
    except ValueError as exc:  # pragma: no cover - every value is range-checked above
        raise SceneError(scene_file, t.path, str(exc)) from None
