"""Terrain amplification: from a DEM to a construction tree with 3-D landforms.

The pipeline of Paris et al. (2019, Fig. 2 and 12) for one *preset*:

1. Implicitization: the DEM becomes an ``implicit_heightfield`` (prism and
   sigmoid falloff, section 5.1), with falloff ``R = 4`` cells (less on tiny
   DEMs) and threshold ``T = R / 2``.
2. Geology: a resistance tree ``rho`` (section 4) made for the preset: soft layers
   where the landform should form (see each preset below).
3. Landform generation (section 6) with ``rho``: erosion processes produce
   carving primitives (negative energies) summed with the terrain (the paper's
   blend); hoodoos add positive primitives.

Presets (lengths in DEM cells ``c`` and relief ``Z``):

``sea``      Sea level at 0 when the DEM crosses it, else ``min + 0.12 Z``; a soft
             stratum at sea level and soft spots on the coast; three steps of sea
             erosion (section 6.1, Fig. 11), the second on the mesh of the terrain
             carved by the first, so caves deepen and thin headlands are pierced
             into arches. A water plane at sea level.
``river``    Stream power ``A^1/2 s`` on the filled DEM, riverbed and banks; walls
             carved up to ``max(4 c, Z / 4)`` above the water, more in the soft
             strata of a layered geology: undercut canyon walls (Fig. 15, 23).
``karst``    Invasion percolation from the deepest sinks through two soft
             horizontal strata (section 6.2, Fig. 14, 17): tunnel segments.
``hoodoos``  Placement by slope and drainage area, open grammar driven by
             alternating hard and soft strata (section 6.3, Fig. 18-20).
``strata``   The erosion node ``f - f_D (1 - rho)`` (section 6) over the steep
             faces, with folded and faulted strata: layered cliffs with overhangs
             (Fig. 4, 10).

Carving energies. A carving primitive of falloff ``R_i`` and energy ``-e_i`` in rock
of field value ``T`` removes the ball where ``e_i g(d / R_i) > T``. Each erosion
sample asks for a cavity of radius ``r_i`` (``e``-proportional); we set
``R_i = r_i / 0.6`` and ``e_i = T / g(0.6) / n_i`` where ``n_i = sum_j g(|c_i - c_j| / R_j)``
is the overlap of the samples at ``c_i``: the paper only says energies are
proportional to ``e``; without the ``1 / n_i`` a Poisson-dense set of overlapping
primitives would carve the *sum* of its neighbours (tens of times too deep).

The tree is written as scene-file tables (``[nodes.*]``) and built through the
scene loader's :class:`~arches_render.scene.nodes.NodeBuilder` from the very same
tables and data files, so the scene file holds exactly the tree that was generated.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .accessibility import heightfield_mesh
from .banded import polygonize_banded
from .falloff import g
from .shallow_erosion import ErosionPrimitives

__all__ = ["PRESETS", "Amplified", "amplify"]

PRESETS = {
    "sea": "sea cliffs, arches and caves (sea erosion with accessibility)",
    "river": "canyon with undercut walls (stream-power river erosion)",
    "karst": "cave network (invasion percolation)",
    "hoodoos": "hoodoos (open shape grammar)",
    "strata": "layered cliffs with folds and faults (erosion node)",
}

_CAVITY_AT = 0.6  # cavity radius / falloff radius of a carving primitive
SEA_STEPS = 3  # steps of sea erosion, as in the paper's Fig. 11


@dataclass
class Amplified:
    """The result of :func:`amplify`.

    Attributes
    ----------
    tables : dict
        ``[nodes.*]`` tables of the tree (root ``"world"``).
    files : list of str
        Data files written under the work folder, relative to the scene file.
    root : Node
        The tree, built from ``tables``.
    extent : tuple
        ``(x0, y0, x1, y1)`` of the terrain.
    heights : numpy.ndarray
        The DEM as stored (float32 precision).
    focus : numpy.ndarray or None
        ``(K, 3)`` positions of (up to 5000 of) the generated primitives (for the camera).
    sea_level : float or None
        Water level of the ``sea`` preset.
    stats : dict
        Primitive counts, node count, memory, timings per step.
    water_file : str or None
        The sea surface mesh (``sea`` preset; relative to the scene file).
    """

    tables: dict
    files: list
    root: object
    extent: tuple
    heights: np.ndarray
    focus: np.ndarray | None = None
    sea_level: float | None = None
    stats: dict = field(default_factory=dict)
    water_file: str | None = None


class _Tree:
    """Node tables and their data files, built by the scene loader's builder."""

    def __init__(self, work_dir: Path, prefix: str):
        from arches_render.scene.nodes import NodeBuilder
        self.dir, self.prefix = Path(work_dir), prefix
        self.tables: dict = {}
        self.files: list = []
        self.builder = NodeBuilder({"_": {}}, self.dir / "amplified.toml", self.dir)
        self.builder.defs = self.tables

    def file(self, suffix, write):
        """Write a data file ``PREFIX.SUFFIX`` with ``write(path)``; return its relative name."""
        rel = f"{self.prefix}.{suffix}"
        path = self.dir / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        write(path)
        self.files.append(rel)
        return rel

    def add(self, name, table):
        self.tables[name] = table
        return self.builder.named(name)


def _carving_arrays(prims: ErosionPrimitives, T, cell):
    """Arrays ``a, b, radius, energy`` of negative primitives carving the cavities of ``prims``."""
    from scipy.spatial import cKDTree
    keep = prims.radius >= 0.25 * cell  # smaller cavities are below the DEM's resolution
    a, b, r = prims.center[keep], prims.end[keep], prims.radius[keep]
    if len(r) == 0:
        return None
    R = r / _CAVITY_AT
    mid = 0.5 * (a + b)
    # n_i = sum_j g(|c_i - c_j| / R_j), the primitive itself included (g(0) = 1).
    pairs = cKDTree(mid).query_pairs(float(R.max()), output_type="ndarray")
    d = np.linalg.norm(mid[pairs[:, 0]] - mid[pairs[:, 1]], axis=1)
    overlap = (1.0 + np.bincount(pairs[:, 0], g(d, R[pairs[:, 1]]), minlength=len(r))
               + np.bincount(pairs[:, 1], g(d, R[pairs[:, 0]]), minlength=len(r)))
    return dict(a=a, b=b, radius=R, energy=-T / g(_CAVITY_AT, 1.0) / overlap)


def _carving(tree, name, arrays):
    """Write ``arrays`` (one dict or a list merged into one set) as a ``skeletal_set`` node."""
    from .skeletal_set import save_npz
    parts = [x for x in (arrays if isinstance(arrays, list) else [arrays]) if x is not None]
    if not parts:
        return None
    merged = {k: np.concatenate([x[k] for x in parts]) for k in ("a", "b", "radius", "energy")}
    rel = tree.file(f"{name}.npz", lambda p: save_npz(p, **merged))
    # One set for all steps (one grid, one loop per ray step). No star noise on carving
    # sets: the Poisson samples and rho already make the walls irregular, and the noise
    # would triple the cost of every ray step near the terrain.
    tree.add(name, {"type": "skeletal_set", "file": rel, "combine": "sum"})
    return name, int(len(merged["radius"])), 0.5 * (merged["a"] + merged["b"])


def water_mesh(H, extent, level, reach):
    """Sea surface at ``level`` with holes where the terrain rises above it.

    A plane through the whole tile would cut through the rock, where the implicit
    terrain's field is saturated (constant, no normal to shade): the water keeps only
    the grid cells whose four corners are under water, plus four quads reaching
    ``reach`` metres beyond the tile.

    Returns
    -------
    trimesh.Trimesh
    """
    import trimesh
    ny, nx = H.shape
    x0, y0, x1, y1 = extent
    xs, ys = np.linspace(x0, x1, nx), np.linspace(y0, y1, ny)
    X, Y = np.meshgrid(xs, ys)
    V = [np.stack([X.ravel(), Y.ravel(), np.full(X.size, level)], 1)]
    wet = H < level
    cell_wet = wet[:-1, :-1] & wet[1:, :-1] & wet[:-1, 1:] & wet[1:, 1:]
    j, i = np.nonzero(cell_wet)
    a, b, c, d = j * nx + i, j * nx + i + 1, (j + 1) * nx + i, (j + 1) * nx + i + 1
    F = [np.stack([a, b, d], 1), np.stack([a, d, c], 1)]
    # Four quads around the tile (corners shared with the tile's outer ring).
    X0, Y0, X1, Y1 = x0 - reach, y0 - reach, x1 + reach, y1 + reach
    k = nx * ny
    V.append(np.array([[X0, Y0, level], [X1, Y0, level], [X1, Y1, level], [X0, Y1, level],
                       [x0, y0, level], [x1, y0, level], [x1, y1, level], [x0, y1, level]]))
    outer, inner = k + np.arange(4), k + 4 + np.arange(4)
    for q in range(4):
        o0, o1, i0, i1 = outer[q], outer[(q + 1) % 4], inner[q], inner[(q + 1) % 4]
        F.append(np.array([[o0, o1, i1], [o0, i1, i0]]))
    return trimesh.Trimesh(np.concatenate(V), np.concatenate(F), process=False)


def _feature_size(cell, Z):
    """Cavity scale: a fifth of the relief, at least 3 cells, at most 30."""
    return float(np.clip(0.2 * Z, 3.0 * cell, 30.0 * cell))


def _karst_sizes(cell, Z):
    """Tunnel radius and percolation lattice spacing of the karst preset."""
    tunnel = max(1.6 * cell, 0.3 * _feature_size(cell, Z))
    return tunnel, max(3.0 * cell, 1.8 * tunnel)


def _resistance_fn(node):
    from .geology import resistance
    return lambda P: resistance(node, P)


def _band_mesh(root, extent, z0, z1, voxel, border):
    """Mesh of ``root`` inside the slab ``z0 <= z <= z1`` (faces off the tile's border only)."""
    import trimesh

    from arches_render import field as F
    x0, y0, x1, y1 = extent
    box = F.Box([(x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2], [(x1 - x0) / 2, (y1 - y0) / 2, (z1 - z0) / 2])
    m = polygonize_banded(F.Intersection(root, box), voxel)
    mesh = trimesh.Trimesh(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64), process=False)
    c = mesh.triangles_center
    inner = ((c[:, 0] > x0 + border) & (c[:, 0] < x1 - border) & (c[:, 1] > y0 + border)
             & (c[:, 1] < y1 - border) & (c[:, 2] > z0 + 0.5 * voxel) & (c[:, 2] < z1 - 0.5 * voxel))
    return mesh, inner


# -- geology per preset ------------------------------------------------------------------------
def _geology(tree, preset, H, extent, cell, rng, sea_level=None):
    zlo, zhi = float(H.min()), float(H.max())
    Z = max(zhi - zlo, 4 * cell)
    noise_seed = int(rng.integers(0, 2 ** 31))
    if preset == "sea":
        band = max(2.0 * cell, 0.2 * Z)
        # Less durable spots (the paper places them by hand): one on the thinnest headland,
        # where caves cut from both sides meet into an arch, and two on the cliff foot.
        from scipy.ndimage import distance_transform_edt, maximum_filter
        x0, y0, x1, y1 = extent
        ny, nx = H.shape
        land = H > sea_level
        width = distance_transform_edt(land) * cell  # half-width of the land at each cell
        ridge = land & (width == maximum_filter(width, size=3)) & (width >= 2 * cell)
        ridge &= width <= max(3 * cell, 0.5 * Z)
        picks = []
        if ridge.any():
            cand = np.flatnonzero(ridge)
            thin = cand[np.argsort(width.ravel()[cand], kind="stable")][:max(1, len(cand) // 5)]
            picks.append(int(rng.choice(thin)))
        gy, gx = np.gradient(H, cell)
        foot = (np.abs(H - sea_level) < band) & (np.hypot(gx, gy) > 0.5)
        cand = np.flatnonzero(foot) if foot.any() else np.arange(H.size)
        picks += [int(k) for k in rng.choice(cand, size=min(3 - len(picks), len(cand)), replace=False)]
        soft = [{"type": "resistance_skeleton",
                 "a": [float(x0 + (k % nx) * cell), float(y0 + (k // nx) * cell), float(sea_level)],
                 "R": float(max(6 * cell, 0.3 * Z)), "weight": -0.5} for k in picks]
        children = [{"type": "resistance_constant", "value": 0.72},
                    {"type": "resistance_plane", "point": [0.0, 0.0, float(sea_level + 0.3 * band)],
                     "normal": [0.0, 0.0, 1.0], "R": float(band), "weight": -0.25},
                    {"type": "resistance_turbulence", "wavelength": float(max(Z / 6, 2 * cell)),
                     "amplitude": 0.12, "offset": 0.0, "octaves": 3, "seed": noise_seed}] + soft
    elif preset == "river":
        spacing = max(3.0 * cell, Z / 8)
        children = [{"type": "resistance_constant", "value": 0.75},
                    {"type": "resistance_strata", "spacing": float(spacing), "R": float(0.3 * spacing),
                     "weight": -0.6, "phase": float(zlo)},
                    {"type": "resistance_turbulence", "wavelength": float(4 * cell), "amplitude": 0.1,
                     "offset": 0.0, "octaves": 3, "seed": noise_seed, "strata": False}]
    elif preset == "karst":
        children = [{"type": "resistance_constant", "value": 0.8},
                    {"type": "resistance_turbulence", "wavelength": float(6 * cell), "amplitude": 0.12,
                     "offset": 0.0, "octaves": 3, "seed": noise_seed, "strata": False}]
        # Two soft strata, each a few percolation sites thick (else the network dies out).
        _, spacing = _karst_sizes(cell, Z)
        for frac in (0.25, 0.65):
            children.append({"type": "resistance_plane", "point": [0.0, 0.0, float(zhi - frac * Z)],
                             "normal": [0.0, 0.0, 1.0], "R": float(2.0 * spacing), "weight": -0.6})
    elif preset == "hoodoos":
        spacing = max(2.0 * cell, 0.12 * Z)  # about one grammar symbol per layer
        children = [{"type": "resistance_constant", "value": 0.3},
                    {"type": "resistance_strata", "spacing": float(spacing), "R": float(0.45 * spacing),
                     "weight": 0.6, "phase": float(zlo)},
                    {"type": "resistance_turbulence", "wavelength": float(3 * cell), "amplitude": 0.1,
                     "offset": 0.0, "octaves": 2, "seed": noise_seed, "strata": False}]
    else:  # strata: folded, faulted layer cake
        spacing = max(2.0 * cell, Z / 7)
        x0, y0, x1, y1 = extent
        # No 3-D turbulence here: the erosion node evaluates rho at every ray step near the
        # cliffs, and the fold already makes the layers irregular.
        layers = {"type": "resistance_blend", "children": [
            {"type": "resistance_constant", "value": 0.25},
            {"type": "resistance_strata", "spacing": float(spacing), "R": float(0.49 * spacing), "weight": 0.75,
             "phase": float(zlo)}]}
        # Gentle folds and a wide fault gouge: rho's Lipschitz bound scales the erosion node's,
        # and with it the number of sphere-tracing steps near every cliff.
        folded = {"type": "resistance_fold", "child": layers, "amplitude": float(0.15 * spacing),
                  "wavelength": float(max(x1 - x0, y1 - y0) / 3), "octaves": 1, "seed": noise_seed + 1}
        ang = rng.uniform(0, np.pi)
        return tree.add("geology", {"type": "resistance_fault", "child": folded,
                                    "point": [float((x0 + x1) / 2), float((y0 + y1) / 2), 0.0],
                                    "normal": [float(np.cos(ang)), float(np.sin(ang)), 0.0],
                                    "slip": [0.0, 0.0, float(0.5 * spacing)], "width": float(0.5 * spacing)})
    return tree.add("geology", {"type": "resistance_blend", "children": children})


# -- the pipeline ------------------------------------------------------------------------------
def amplify(heights, cell_size, preset, seed, work_dir, prefix="amplified", progress=None, options=None):
    """Build the amplified construction tree of a DEM for a preset.

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` finite elevations in metres (``>= 2 x 2``).
    cell_size : float
        Metres between DEM samples.
    preset : str
        One of :data:`PRESETS`.
    seed : int
        Seed of every random choice (same seed, same tree).
    work_dir : Path
        Folder the data files are written to (the scene's folder, or a
        temporary one published later).
    prefix : str
        Relative path prefix of the data files (e.g. ``"data/terrain_sea"``).
    progress : callable, optional
        ``progress(done, total, label)`` after each generation step.
    options : dict, optional
        Overrides of the ``sea`` preset: ``steps`` (number of erosion steps, default
        3) and ``spacing`` (Poisson-disc distance of the samples, metres).

    Returns
    -------
    Amplified
    """
    from . import hoodoos as hd
    from . import karst as ks
    from .river_erosion import river_erosion
    from .sea_erosion import sea_erosion_step

    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; allowed: {', '.join(PRESETS)}")
    options = dict(options or {})
    sea_steps = int(options.pop("steps", SEA_STEPS))
    sea_spacing = options.pop("spacing", None)
    if options:
        raise ValueError(f"unknown amplify option(s): {', '.join(sorted(options))}")
    steps = {"sea": 3 + sea_steps, "river": 4, "karst": 4, "hoodoos": 4, "strata": 4}[preset]
    done = [0]
    timings = {}
    t_last = [time.perf_counter()]

    def step(label):
        now = time.perf_counter()
        timings[label] = round(now - t_last[0], 4)
        t_last[0] = now
        done[0] += 1
        if progress:
            progress(done[0], steps, label)

    rng = np.random.default_rng(seed)
    H = np.asarray(heights, dtype=np.float32).astype(np.float64)
    ny, nx = H.shape
    cell = float(cell_size)
    W, D = (nx - 1) * cell, (ny - 1) * cell
    extent = (-W / 2, -D / 2, W / 2, D / 2)
    zlo, zhi = float(H.min()), float(H.max())
    Z = max(zhi - zlo, 4 * cell)
    R = min(4.0 * cell, 0.45 * min(W, D))
    T = 0.5 * R
    tree = _Tree(work_dir, prefix)
    rel = tree.file("heights.npy", lambda p: np.save(p, H.astype(np.float32)))
    terrain = tree.add("terrain", {"type": "implicit_heightfield", "extent": [float(v) for v in extent],
                                   "source": "file", "file": rel, "R": float(R), "T": float(T)})
    flat = zhi - zlo < 0.5 * cell
    if flat:  # no cliff, valley, sink or talus: the processes have nothing to act on
        steps = 3
    step("implicitization")
    sea_level = None
    if preset == "sea":
        sea_level = zlo - cell if flat else (0.0 if zlo < 0.0 < zhi else zlo + 0.12 * Z)
    geology = _geology(tree, preset, H, extent, cell, rng, sea_level)
    rho = _resistance_fn(geology)
    step("geology")

    children = ["terrain"]
    stats = {"preset": preset, "seed": int(seed), "cells": int(H.size), "cell_size": cell}
    preset_run = None if flat else preset
    if flat:
        stats["note"] = "flat DEM: no landform generated"
    focus_pts = []
    mesh_step = max(1, int(math.ceil(max(nx, ny) / 1024)))

    feature = _feature_size(cell, Z)
    if preset_run == "sea":
        sea_range = max(2.0 * cell, 0.25 * Z)  # the paper: 8 m for its ~40 m cliffs
        max_r = 0.8 * feature  # per step: three steps cut about two feature sizes into soft rock
        mesh = heightfield_mesh(H, extent, mesh_step)
        weight = None
        steps_arrays = []
        for k in range(sea_steps):
            spacing = float(sea_spacing) if sea_spacing else max(1.5 * cell, max_r)
            prims = sea_erosion_step(mesh, rho, sea_level, sea_range, spacing=spacing,
                                     max_radius=max_r,
                                     beta=0.3, threshold=0.08, rays=16, seed=int(rng.integers(2 ** 31)),
                                     face_mask=weight)
            arr = _carving_arrays(prims, T, cell)
            stats[f"sea_step{k + 1}_primitives"] = 0 if arr is None else int(len(arr["radius"]))
            step(f"sea erosion step {k + 1}")
            if arr is None:  # nothing eroded: later steps would see the same terrain
                for j in range(k + 1, sea_steps):
                    step(f"sea erosion step {j + 1}")
                break
            steps_arrays.append(arr)
            if k == sea_steps - 1:
                break
            # The next step samples the carved terrain: mesh of the sea band of the tree so far
            # (sets given inline: only the final, merged set is written to a file).
            inline = [{"type": "skeletal_set", "combine": "sum", **{n: v for n, v in x.items()}}
                      for x in steps_arrays]
            current = tree.add(f"_sea_step{k + 1}", {"type": "sum", "children": ["terrain"] + inline})
            mesh, weight = _band_mesh(current, extent, sea_level - sea_range - 2 * max_r,
                                      sea_level + sea_range + 2 * max_r,
                                      # The band mesh only guides sampling and rays: at most ~384
                                      # voxels across a large tile (small tiles: one cell).
                                      max(cell, 0.25 * max_r, max(W, D) / 384.0), 2 * cell)
            del tree.tables[f"_sea_step{k + 1}"]
            tree.builder.built.pop(f"_sea_step{k + 1}", None)
        out = _carving(tree, "sea_erosion", steps_arrays)
        if out:
            children.append(out[0])
            # Frame the deepest erosion: the last step carves inside the notches and caves.
            last = steps_arrays[-1]
            focus_pts.append(0.5 * (last["a"] + last["b"]))
    elif preset_run == "river":
        mesh = heightfield_mesh(H, extent, mesh_step)
        flood = max(4.0 * cell, 0.25 * Z)
        prims = river_erosion(H, extent, mesh, rho, spacing=max(1.5 * cell, 0.8 * feature), max_radius=feature,
                              flood_height=flood, beta=0.15, threshold=0.08, seed=int(rng.integers(2 ** 31)))
        step("stream power and sampling")
        out = _carving(tree, "river_erosion", _carving_arrays(prims, T, cell))
        if out:
            children.append(out[0])
            stats["river_primitives"] = out[1]
            focus_pts.append(out[2])
    elif preset_run == "karst":
        seeds = ks.karst_seeds(H, extent, 6, rng)
        step("sinks")
        tunnel, spacing = _karst_sizes(cell, Z)
        prims = ks.karst_network(terrain.elevation_np, extent, (zlo - 0.1 * Z, zhi), rho, seeds,
                                 spacing=spacing, max_radius=tunnel, rho0=0.45, epsilon=0.1,
                                 beta=0.3, max_sites=max(2000, H.size // 8), seed=int(rng.integers(2 ** 31)))
        out = _carving(tree, "karst_tunnels", _carving_arrays(prims, T, cell))
        if out:
            children.append(out[0])
            stats["karst_primitives"] = out[1]
            focus_pts.append(out[2])
    elif preset_run == "hoodoos":
        s0 = max(2.0 * cell, 0.15 * Z)
        P = hd.hoodoo_probability(H, extent)
        step("placement probability")
        P = P / max(float(P.max()), 1e-12)  # the best sites grow a hoodoo for sure
        sym = hd.hoodoo_field(H, extent, terrain.elevation_np, rho, spacing=max(4.0 * cell, 1.6 * s0), s0=s0,
                              width0=0.7 * s0, probability=P, seed=int(rng.integers(2 ** 31)))
        if len(sym):
            from .skeletal_set import save_npz
            Rf = np.maximum(0.8 * sym.width, 0.5 * cell)
            x = math.sqrt(1.0 - 0.5 ** (1.0 / 3.0))  # g(x) = 1/2: the surface where 2T g = T
            core = np.maximum(sym.width - x * Rf, 0.0)
            rel = tree.file("hoodoos.npz", lambda p: save_npz(p, a=sym.a, b=sym.b, radius=Rf,
                                                               energy=np.full(len(Rf), 2.0 * T), core=core))
            tree.add("hoodoos", {"type": "skeletal_set", "file": rel, "combine": "max",
                                 "noise": {"amplitude": 0.12, "wavelength": float(max(s0 / 2, cell)),
                                           "octaves": 2, "seed": int(rng.integers(2 ** 31))}})
            children.append("hoodoos")
            stats["hoodoos"] = int(sym.hoodoo.max() + 1)
            stats["hoodoo_primitives"] = int(len(sym))
            focus_pts.append(0.5 * (sym.a + sym.b))
    elif preset_run == "strata":
        from .shallow_erosion import sample_mesh
        from .skeletal_set import save_npz
        mesh = heightfield_mesh(H, extent, mesh_step)
        steep = mesh.face_normals[:, 2] < math.cos(math.radians(40.0))
        c = mesh.triangles_center
        x0, y0, x1, y1 = extent
        inner = (c[:, 0] > x0 + 2 * R) & (c[:, 0] < x1 - 2 * R) & (c[:, 1] > y0 + 2 * R) & (c[:, 1] < y1 - 2 * R)
        pts, _ = sample_mesh(mesh, 3.0 * cell, (steep & inner).astype(float), rng)
        step("cliff sampling")
        if len(pts):
            Rd = 5.0 * cell
            rel = tree.file("strata_erosion.npz", lambda p: save_npz(p, a=pts, radius=np.full(len(pts), Rd),
                                                                      energy=np.full(len(pts), 2.0 * T)))
            tree.add("strata_field", {"type": "skeletal_set", "file": rel, "combine": "max"})
            tree.add("strata_eroded", {"type": "erosion", "child": "terrain", "field": "strata_field",
                                       "resistance": "geology"})
            children = ["strata_eroded"]
            stats["erosion_field_primitives"] = int(len(pts))
            focus_pts.append(pts)
    root = tree.add("world", {"type": "sum", "children": children} if len(children) > 1
                    else {"type": "union", "children": children})
    step("construction tree")
    if not any(n == "geology" for n in _referenced(tree.tables, "world")):
        # Geology unused by the final tree (no primitive kept): the loader rejects unused nodes.
        tree.tables.pop("geology", None)
    focus = np.concatenate(focus_pts)[::max(1, sum(len(f) for f in focus_pts) // 5000)] if focus_pts else None
    stats.update(nodes=int(root.count()), memory_bytes=int(root.tree_nbytes()),
                 primitives=int(sum(v for k, v in stats.items() if k.endswith("primitives"))),
                 timings_s=timings)
    result = Amplified(tree.tables, tree.files, root, extent, H, focus, sea_level, stats)
    if sea_level is not None:
        reach = 50.0 * max(W, D)
        result.water_file = tree.file("water.ply", lambda p: water_mesh(H, extent, sea_level, reach).export(p))
    return result


def _referenced(tables, name):
    """Names of the node tables reachable from ``name`` (named references only)."""
    seen, stack = set(), [name]
    while stack:
        n = stack.pop()
        if n in seen or n not in tables:
            continue
        seen.add(n)

        def refs(v):
            if isinstance(v, str) and v in tables:
                yield v
            elif isinstance(v, list):
                for x in v:
                    yield from refs(x)
            elif isinstance(v, dict):
                for x in v.values():
                    yield from refs(x)
        for k, v in tables[n].items():
            if k != "type":
                stack.extend(refs(v))
    return seen
