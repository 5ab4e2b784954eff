"""Terrain amplification: from a DEM to a construction tree with 3-D landforms.

The pipeline of Paris et al. (2019, Fig. 2 and 12) for one *preset*
(:mod:`.presets`: each preset's geology, landform processes and steps):

1. Implicitization: the DEM becomes an ``implicit_heightfield`` (prism and
   sigmoid falloff, section 5.1), with falloff ``R = 4`` cells (less on tiny
   DEMs) and threshold ``T = R / 2``.
2. Geology: a resistance tree ``rho`` (section 4) made for the preset: soft layers
   where the landform should form.
3. Landform generation (section 6) with ``rho``: erosion processes produce
   carving primitives (negative energies) summed with the terrain (the paper's
   blend); hoodoos add positive primitives.

The tree is written as scene-file tables (``[nodes.*]``) and built through the
scene loader's :class:`~arches_render.scene.nodes.NodeBuilder` from the very same
tables and data files, so the scene file holds exactly the tree that was generated.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from .presets import PRESETS, SEA_STEPS, Amplification, NodeTables, StepTimer

__all__ = ["PRESETS", "Amplified", "amplify", "water_mesh"]


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
        One of :data:`~.presets.PRESETS`.
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
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; allowed: {', '.join(PRESETS)}")
    spec = PRESETS[preset]
    options = dict(options or {})
    sea_steps = int(options.pop("steps", SEA_STEPS))
    sea_spacing = options.pop("spacing", None)
    if options:
        raise ValueError(f"unknown amplify option(s): {', '.join(sorted(options))}")
    rng = np.random.default_rng(seed)
    H = np.asarray(heights, dtype=np.float32).astype(np.float64)
    ny, nx = H.shape
    cell = float(cell_size)
    W, D = (nx - 1) * cell, (ny - 1) * cell
    extent = (-W / 2, -D / 2, W / 2, D / 2)
    R = min(4.0 * cell, 0.45 * min(W, D))
    run = Amplification(NodeTables(work_dir, prefix), H, extent, cell, R, 0.5 * R, rng,
                        sea_steps=sea_steps, sea_spacing=sea_spacing)
    zlo, zhi, Z = run.relief
    flat = zhi - zlo < 0.5 * cell  # no cliff, valley, sink or talus: the processes have nothing to act on
    run.timer = StepTimer(["implicitization", "geology", *([] if flat else spec.steps(run)), "construction tree"],
                          progress)
    tree = run.tree
    rel = tree.file("heights.npy", lambda p: np.save(p, H.astype(np.float32)))
    run.terrain = tree.add("terrain", {"type": "implicit_heightfield", "extent": [float(v) for v in extent],
                                       "source": "file", "file": rel, "R": float(R), "T": float(run.T)})
    run.timer.step("implicitization")
    if preset == "sea":
        run.sea_level = zlo - cell if flat else (0.0 if zlo < 0.0 < zhi else zlo + 0.12 * Z)
    run.rho = spec.resistance(run)
    run.timer.step("geology")

    run.stats.update(preset=preset, seed=int(seed), cells=int(H.size), cell_size=cell)
    if flat:
        run.stats["note"] = "flat DEM: no landform generated"
    else:
        spec.landforms(run)
    children = run.children
    root = tree.add("world", {"type": "sum", "children": children} if len(children) > 1
                    else {"type": "union", "children": children})
    run.timer.step("construction tree")
    # The geology stays in the tables even where the final tree does not read it: the
    # scene's material colours the rock by its strata (lookdev, issue 15).
    focus_pts = run.focus
    focus = np.concatenate(focus_pts)[::max(1, sum(len(f) for f in focus_pts) // 5000)] if focus_pts else None
    stats = run.stats
    stats.update(nodes=int(root.count()), memory_bytes=int(root.tree_nbytes()),
                 primitives=int(sum(v for k, v in stats.items() if k.endswith("primitives"))),
                 timings_s=run.timer.timings)
    result = Amplified(tree.tables, tree.files, root, extent, H, focus, run.sea_level, stats)
    if run.sea_level is not None:
        reach = 50.0 * max(W, D)
        result.water_file = tree.file("water.ply", lambda p: water_mesh(H, extent, run.sea_level, reach).export(p))
    return result
