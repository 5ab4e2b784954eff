"""Scene-file node types of the layered terrain: ``layers`` and ``layers_ratio``.

=====================  ==================================================================
type                   keys
=====================  ==================================================================
layers                 [source = "flat" | "file" | "node" | "stacks"], cell (column side,
                       m), [extent = [x0, y0, x1, y1]] (a whole number of cells),
                       [z_range = [z0, z1]] (matter outside is cut off), [dz = (z1 - z0) / 4096] (vertical quantum),
                       [sigma = cell / 2] (kernel half-side, cell/4 .. 2 cell),
                       [column = [{material, [thickness]}, ...]] (from the surface down;
                       default bedrock), [angles = {sand = 33, rock = 42}] (repose,
                       degrees), [seed = 0], [operations = [{tool, ...}, ...]] (applied in
                       order, see generators/layers/operations.py);
                       flat: extent, [elevation = 0];
                       file: file (.npy, 16-bit .png, .tif DEM spanning extent),
                       extent, [height_scale = 1], [height_offset = 0];
                       node: node (name or inline table; a heightfield is sampled on the
                       column axes, any other field is voxelized), [extent = node's box];
                       stacks: file (.npz written by ``arches-render layers``)
layers_ratio           terrain (name of a layers node), [material = "sand"] or
                       materials = [...], [sigma = cell]: the local share of those
                       materials in the ground (0..1), for triplanar ``masks``
=====================  ==================================================================

Materials: air, bedrock, sand, rock, water, sandstone. Operation keys (``[ ]``
optional): ``sculpt``: at, radius, [mode = "add" | "remove"], [delta], [material];
``sweep``: path (>= 2 points), profile (>= 3 [u, v] points, or one list per path
point), [mode = "tunnel" | "crack"], [scale], [depth_offset], [roughness];
``deposit``: center = [x, y], radius, amount, [material = "sand"], [z];
``erode``: center, radius (number or 3), [rho = 0.5], [mode = "collapse" |
"surface"], [depth], [roughness]; ``stabilize``; and on every tool
``[stabilize = true]``.
"""

from __future__ import annotations

import math

import numpy as np

from arches_render.field import Heightfield
from arches_render.scene.errors import SceneError
from arches_render.scene.nodes import load_heights
from arches_render.resources import ResourceError, check_memory, heightmap_bytes
from arches_render.scene.paths import scene_file
from arches_render.scene.validate import Table

from .material_stacks import GRANULAR, MATERIALS, ROCK, SAND, MaterialStacks
from .operations import TOOLS, apply_operations

# The convolution surface (numba kernels: 0.14 s to import) is imported where a scene has
# a ``layers`` node, not by every process that reads the node types.


def _extent(t: Table, default=None):
    if default is not None and not t.has("extent"):
        return default
    x0, y0, x1, y1 = t.vector("extent", 4)
    if not (x1 > x0 and y1 > y0):
        raise t.error("extent", f"must be [x0, y0, x1, y1] with x1 > x0 and y1 > y0 (got {[x0, y0, x1, y1]})")
    return x0, y0, x1, y1


def _grid(t: Table, extent, cell):
    x0, y0, x1, y1 = extent
    nx, ny = (x1 - x0) / cell, (y1 - y0) / cell
    if abs(nx - round(nx)) > 1e-6 * max(1.0, nx) or abs(ny - round(ny)) > 1e-6 * max(1.0, ny):
        raise t.error("extent", f"must span a whole number of cells of {cell:g} m (got {nx:g} x {ny:g})")
    nx, ny = int(round(nx)), int(round(ny))
    if not (2 <= nx <= 8192 and 2 <= ny <= 8192):
        raise t.error("cell", f"must give between 2 and 8192 columns per axis (got {nx} x {ny})")
    try:  # the column heights and their stacks: the memory of a heightmap of the grid
        check_memory(heightmap_bytes(nx, ny), f"a {nx}x{ny} grid of material stacks")
    except ResourceError as exc:
        raise t.error("cell", str(exc)) from None
    return nx, ny


def _column(t: Table):
    items = t.tables("column")
    if not items:
        return (("bedrock", None),)
    out = []
    for k, c in enumerate(items):
        name = c.string("material", choices=set(MATERIALS) - {"air"})
        last = k == len(items) - 1
        th = c.number("thickness", None if last else math.nan, lo=0, lo_open=True)
        if th is not None and math.isnan(th):
            raise c.error("thickness", "is required (only the last entry may omit it)")
        c.finish()
        out.append((name, th))
    return tuple(out)


def _z_range(t: Table, lo, hi):
    if t.has("z_range"):
        z0, z1 = t.vector("z_range", 2)
        if not z1 > z0:
            raise t.error("z_range", f"must be [z0, z1] with z1 > z0 (got {[z0, z1]})")
        return z0, z1
    return lo - 1.0, hi + max(2.0, (hi - lo) / 3.0)


def _dz(t: Table, z0, z1):
    dz = t.number("dz", (z1 - z0) / 4096, lo=0, lo_open=True)
    if (z1 - z0) / dz > 65535:
        raise t.error("dz", f"must be >= {(z1 - z0) / 65535:.4g} m (at most 65535 levels in z_range)")
    return dz


def _from_heights(t: Table, H, extent, cell, column):
    z0, z1 = _z_range(t, float(H.min()), float(H.max()))
    dz = _dz(t, z0, z1)
    try:
        return MaterialStacks.from_heightfield(H, cell, extent[:2], z0, z1, dz, column)
    except ValueError as exc:
        raise t.error("column", str(exc)) from None


def _source(t: Table, ctx) -> MaterialStacks:
    kind = t.string("source", "flat", choices={"flat", "file", "node", "stacks"})
    if kind == "stacks":
        path = scene_file(t, "file", (".npz",), ctx.base_dir, what="stack file")
        try:
            return MaterialStacks.load(path)
        except ValueError as exc:
            raise t.error("file", str(exc)) from None
    cell = t.number("cell", lo=0, lo_open=True)
    column = _column(t)
    if kind == "node":
        node = ctx.build(t.raw("node"), t, "node")
        lo, hi = node.bounds()
        default = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        extent = _extent(t, default if np.all(np.isfinite(lo[:2]) & np.isfinite(hi[:2])) else None)
        nx, ny = _grid(t, extent, cell)
        xs = extent[0] + (np.arange(nx) + 0.5) * cell
        ys = extent[1] + (np.arange(ny) + 0.5) * cell
        if isinstance(node, Heightfield):
            X, Y = np.meshgrid(xs, ys)
            return _from_heights(t, _heightfield_heights(node, X, Y), extent, cell, column)
        if not (np.isfinite(lo[2]) and np.isfinite(hi[2])):
            raise t.error("node", "the field is unbounded in z: intersect it with a box")
        z0, z1 = _z_range(t, float(lo[2]), float(hi[2]))
        dz = _dz(t, z0, z1)
        try:
            return MaterialStacks.from_field(node, extent, cell, (z0, z1), dz, column=column)
        except ValueError as exc:
            raise t.error("node", str(exc)) from None
    extent = _extent(t)
    nx, ny = _grid(t, extent, cell)
    if kind == "flat":
        H = np.full((ny, nx), t.number("elevation", 0.0))
        return _from_heights(t, H, extent, cell, column)
    dem = load_heights(t, ctx.base_dir)
    hf = Heightfield(dem, extent)
    X, Y = np.meshgrid(extent[0] + (np.arange(nx) + 0.5) * cell, extent[1] + (np.arange(ny) + 0.5) * cell)
    return _from_heights(t, _heightfield_heights(hf, X, Y), extent, cell, column)


def _heightfield_heights(node, X, Y):
    """Bilinear heights of a :class:`~arches_render.field.Heightfield` at the column axes."""
    from scipy.interpolate import RegularGridInterpolator
    x0, y0, x1, y1 = node.extent
    xs = np.linspace(x0, x1, node.nx)
    ys = np.linspace(y0, y1, node.ny)
    f = RegularGridInterpolator((ys, xs), node.heights_np, method="linear")
    pts = np.stack([np.clip(Y.ravel(), y0, y1), np.clip(X.ravel(), x0, x1)], axis=1)
    return f(pts).reshape(X.shape)


def _points(t: Table, key, dim, minimum):
    v = t.raw(key)
    ok = (isinstance(v, list) and len(v) >= minimum
          and all(isinstance(p, list) and len(p) == dim
                  and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                          for x in p) for p in v))
    if not ok:
        raise t.error(key, f"must be an array of at least {minimum} [{', '.join('xyz'[:dim] if dim == 3 else 'uv')}] "
                           f"points (got {v!r})")
    return [[float(x) for x in p] for p in v]


def _profile(t: Table, n_path):
    v = t.raw("profile")
    if isinstance(v, list) and v and isinstance(v[0], list) and v[0] and isinstance(v[0][0], list):
        if len(v) != n_path:
            raise t.error("profile", f"must hold one profile per path point ({n_path}) or a single profile")
        profs = []
        for k in range(len(v)):
            sub = Table({"profile": v[k]}, t.file, t.key(f"profile[{k}]"))
            profs.append(_points(sub, "profile", 2, 3))
        if len({len(p) for p in profs}) != 1:
            raise t.error("profile", "all profiles must have the same number of points")
        return profs
    return _points(t, "profile", 2, 3)


def _operation(t: Table) -> dict:
    tool = t.string("tool", choices=set(TOOLS))
    op = {"tool": tool, "stabilize": t.boolean("stabilize", True)}
    if tool == "sculpt":
        op.update(at=t.vector("at"), radius=t.number("radius", lo=0, lo_open=True),
                  mode=t.string("mode", "add", choices={"add", "remove"}),
                  material=t.string("material", "bedrock", choices=set(MATERIALS) - {"air"}))
        if t.has("delta"):
            op["delta"] = t.number("delta", lo=0.0, hi=op["radius"])
    elif tool == "sweep":
        path = _points(t, "path", 3, 2)
        op.update(path=path, profile=_profile(t, len(path)),
                  mode=t.string("mode", "tunnel", choices={"tunnel", "crack"}),
                  depth_offset=t.number("depth_offset", 0.0),
                  roughness=t.number("roughness", 0.0, lo=0.0, hi=0.9))
        if t.has("scale"):
            op["scale"] = t.vector("scale", len(path), lo=1e-6)
    elif tool == "deposit":
        op.update(center=t.vector("center", 2), radius=t.number("radius", lo=0, lo_open=True),
                  amount=t.number("amount", lo=0, lo_open=True),
                  material=t.string("material", "sand", choices={"sand", "rock"}))
        if t.has("z"):
            op["z"] = t.number("z")
    elif tool == "erode":
        r = t.raw("radius")
        radius = t.vector("radius", 3, lo=1e-6) if isinstance(r, list) else t.number("radius", lo=0, lo_open=True)
        op.update(center=t.vector("center"), radius=radius, rho=t.number("rho", 0.5, lo=0.0, hi=1.0),
                  mode=t.string("mode", "collapse", choices={"collapse", "surface"}),
                  roughness=t.number("roughness", 0.0, lo=0.0, hi=0.9))
        if t.has("depth"):
            op["depth"] = t.number("depth", lo=0, lo_open=True)
    t.finish()
    return op


def build_stacks(t: Table, ctx):
    """The edited :class:`MaterialStacks` of a ``layers`` table, and its ``sigma``."""
    stacks = _source(t, ctx)
    sig = t.number("sigma", 0.5 * stacks.cell, lo=0.25 * stacks.cell, hi=2.0 * stacks.cell)
    seed = t.integer("seed", 0, lo=0, hi=2 ** 31 - 1)
    angles = {SAND: 33.0, ROCK: 42.0}
    at = t.table("angles", None)
    if at is not None:
        for name in ("sand", "rock"):
            angles[MATERIALS[name]] = at.number(name, angles[MATERIALS[name]], lo=1.0, hi=89.0)
        at.finish()
    ops = [_operation(o) for o in t.tables("operations")]
    progress = ctx.progress
    for k, op in enumerate(ops):
        try:
            stacks, _ = apply_operations(stacks, [op], seed=seed + k, angles=angles, sigma=sig)
        except ValueError as exc:
            raise SceneError(t.file, t.key(f"operations[{k}]"), str(exc)) from None
        if progress is not None:
            progress(k + 1, len(ops))
    assert all(m in angles for m in GRANULAR)
    return stacks, sig


def _layers(t: Table, ctx):
    from .convolution_surface import ConvolutionSurface
    stacks, sig = build_stacks(t, ctx)
    return ConvolutionSurface(stacks, sigma=sig)


def _layers_ratio(t: Table, ctx):
    from .convolution_surface import ConvolutionSurface, MaterialRatio
    name = t.string("terrain")
    terrain = ctx.named(name, t, "terrain")
    if not isinstance(terrain, ConvolutionSurface):
        raise t.error("terrain", f"must name a node of type layers (got {terrain.kind})")
    allowed = set(MATERIALS) - {"air"}
    if t.has("materials"):
        names = t.raw("materials")
        if not isinstance(names, list) or not names or not all(n in allowed for n in names):
            raise t.error("materials", f"must be a non-empty array of {', '.join(sorted(allowed))} (got {names!r})")
    else:
        names = [t.string("material", "sand", choices=allowed)]
    s = terrain.stacks.cell
    sigma = t.number("sigma", s, lo=0.25 * s, hi=2.0 * s)
    return MaterialRatio(terrain.stacks, [MATERIALS[n] for n in names], sigma=sigma)


NODE_TYPES = {"layers": _layers, "layers_ratio": _layers_ratio}
