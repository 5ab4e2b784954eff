"""Terrain amplification: from a DEM to a construction tree with 3-D landforms.

The pipeline of Paris et al. (2019, Fig. 2 and 12) for one *preset*
(:mod:`.presets`: each preset's geology, landform processes and steps):

0. Analysis (issue 14): ``auto`` picks the preset from the DEM
   (:func:`.preset_choice.choose_preset`); landform sizes come from its relief in
   metres (:func:`.preset_choice.landform_scales`); the sea and the lakes from its
   elevations (:mod:`.water`); the sub-cell detail from its spectrum (:mod:`.detail`).
   Heights quantized on a lattice whose terraces show (whole metres on gentle
   slopes) are first smoothed within half a step
   (:mod:`arches_render.field.dequantize`).
1. Implicitization: the DEM becomes an ``implicit_heightfield`` (prism and
   sigmoid falloff, section 5.1) with fBm octaves continuing its spectrum down to
   the precision. Falloff ``R = min(4 cells, 2 F)`` (``F`` the landform size; less
   on tiny DEMs) and threshold ``T = R / 2``: carving energies are relative to
   ``T``, so ``R`` follows the landforms, not the DEM's cell.
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

import math
from dataclasses import dataclass, field

import numpy as np

from arches_render.field.dequantize import dequantize, quantization_step

from .detail import default_precision, detail_amplification
from .preset_choice import choose_preset, landform_scales
from .presets import PRESETS, SEA_STEPS, Amplification, NodeTables, StepTimer
from .sea_floor import DEPTH_AT_SHORE, SLOPE, flat_sea, lay_sea_floor
from .water import WaterBodies, find_water, water_mesh

__all__ = ["PRESETS", "PRESET_NAMES", "Amplified", "amplify"]

#: What ``--preset`` accepts: ``auto`` and the presets.
PRESET_NAMES = ("auto", *PRESETS)


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
    preset : str
        The preset run (``auto`` resolved).
    reason : str
        Why: the rule of :func:`.preset_choice.choose_preset`, or "chosen by the user".
    scales : dict
        Landform sizes in metres (:func:`.preset_choice.landform_scales`).
    precision : float
        Smallest detail (metres).
    detail : dict or None
        The terrain's ``amplification`` table (fBm continuing the DEM's spectrum).
    water : WaterBodies
        Sea and lakes.
    focus : numpy.ndarray or None
        ``(K, 3)`` positions of (up to 5000 of) the generated primitives (for the camera).
    sea_level : float or None
        Level of the sea (when the tile has one).
    stats : dict
        Primitive counts, node count, memory, timings per step, notes.
    water_file : str or None
        The water surfaces (relative to the scene file).
    landforms : Node or None
        The tree without its accessories (fallen blocks): what close shots frame and
        measure (None: ``root``).
    context : (numpy.ndarray, tuple) or None
        ``(heights, extent)`` of the DEM the tile is a refined crop of, in the tile's
        frame (:mod:`.refined_crop`): the ground around the tile.
    """

    tables: dict
    files: list
    root: object
    extent: tuple
    heights: np.ndarray
    preset: str = ""
    reason: str = ""
    scales: dict = field(default_factory=dict)
    precision: float = 0.1
    detail: dict | None = None
    water: WaterBodies | None = None
    focus: np.ndarray | None = None
    sea_level: float | None = None
    stats: dict = field(default_factory=dict)
    water_file: str | None = None
    landforms: object = None
    context: tuple | None = None

    @property
    def terrain(self):
        """The ``implicit_heightfield`` node (the DEM), without landforms."""
        return next(n for n in self.root.walk() if n.kind == "implicit_heightfield")

    @property
    def feature(self) -> float:
        """Landform size ``F`` (m) the amplification used (:func:`landform_size`)."""
        return landform_size(self.scales, self.stats["cell_size"], self.precision)


def landform_size(scales, cell, precision) -> float:
    """Landform size ``F`` in metres: :func:`.preset_choice.landform_scales`' ``feature_m``
    (4 cells without one), at least two precisions."""
    return max(float(scales.get("feature_m", 4 * cell)), 2.0 * precision)


# -- the pipeline ------------------------------------------------------------------------------
def amplify(heights, cell_size, preset, seed, work_dir, prefix="amplified", progress=None, options=None,
            sea_level=0.0, precision=None, detail=True, lake_levels=None):
    """Build the amplified construction tree of a DEM for a preset.

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` finite elevations in metres (``>= 2 x 2``).
    cell_size : float
        Metres between DEM samples.
    preset : str
        ``"auto"`` or one of :data:`~.presets.PRESETS`.
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
        3) and ``spacing`` (Poisson-disc distance of the samples, metres); of the
        ``strata`` preset: ``fallen_blocks`` (blocks at the feet of the cliffs,
        :mod:`.talus`; default on: a shot that sees them renders 30-45 % slower, one
        that does not 3-15 %).
    sea_level : float or None
        Sea level (m, default 0): the sea is the cells below it connected to the
        border (:mod:`.water`); ``None``: no sea. The ``sea`` preset on a DEM with no
        sea below it puts its sea at the lowest 12 % of the relief (noted).
    precision : float, optional
        Smallest detail in metres (default :func:`.detail.default_precision`).
    detail : bool
        Add the sub-cell fBm octaves (:mod:`.detail`); ``False``: the DEM alone.
    lake_levels : numpy.ndarray, optional
        Where ``heights`` are a refined crop, the levels of the lakes its DEM holds
        (:attr:`.refined_crop.RefinedCrop.lake_levels`; :func:`.water.find_water`).

    Returns
    -------
    Amplified
    """
    if preset not in PRESET_NAMES:
        raise ValueError(f"unknown preset {preset!r}; allowed: {', '.join(PRESET_NAMES)}")
    options = dict(options or {})
    sea_steps = int(options.pop("steps", SEA_STEPS))
    sea_spacing = options.pop("spacing", None)
    fallen_blocks = bool(options.pop("fallen_blocks", True))
    if options:
        raise ValueError(f"unknown amplify option(s): {', '.join(sorted(options))}")
    rng = np.random.default_rng(seed)
    H = np.asarray(heights, dtype=np.float32).astype(np.float64)
    notes = []
    cell = float(cell_size)
    sheet = flat_sea(H, sea_level)  # found before the smoothing below moves its cells
    step = quantization_step(H)
    if step is not None:
        # Whole-metre DEMs are staircases where the ground rises less than a step a cell.
        H = dequantize(H, step, sea_level)
        notes.append(f"heights on a {step:g} m lattice: terraces smoothed away, each height moved by at "
                     f"most {0.5 * step:g} m")
    if sheet is not None:
        H, deepest = lay_sea_floor(H, sheet, cell, sea_level)
        notes.append(f"the sea is a flat sheet at {sea_level:g} m on {100 * sheet.mean():.0f} % of the tile (no "
                     f"bathymetry): a sea floor was laid under it, {DEPTH_AT_SHORE:g} m deep at the shore, "
                     f"{100 * SLOPE:g} % deeper a metre out, at most {deepest:.3g} m")
    ny, nx = H.shape
    W, D = (nx - 1) * cell, (ny - 1) * cell
    extent = (-W / 2, -D / 2, W / 2, D / 2)  # centred: float32 keeps its precision at the corners
    precision = float(precision) if precision else default_precision(cell)
    level = 0.0 if sea_level is None else float(sea_level)
    if preset == "auto":
        preset, reason, _ = choose_preset(H, cell, level)
    else:
        reason = "chosen by the user"
    spec = PRESETS[preset]
    zlo, zhi = float(H.min()), float(H.max())
    flat = zhi - zlo < 0.5 * cell  # no cliff, valley, sink or talus: the processes have nothing to act on
    water = find_water(H, sea_level, lakes=preset != "karst", lake_levels=lake_levels)  # dolines drain underground
    if preset == "sea" and water.sea_level is None:
        fallback = zlo - cell if flat else zlo + 0.12 * max(zhi - zlo, 4 * cell)
        notes.append(f"no sea below {level:g} m: the sea preset sets its sea at {fallback:.4g} m "
                     f"(lowest 12 % of the relief; --sea-level to choose)")
        level = fallback
        water = find_water(H, level, lakes=True, lake_levels=lake_levels)
        if water.sea_level is None:  # a closed basin: its floor is not at the border
            water = WaterBodies(np.where(H <= level, level, np.nan), H <= level, level, water.lakes, heights=H)
    scales = landform_scales(H, cell, preset, level) if not flat else {}
    feature = landform_size(scales, cell, precision)
    R = min(4.0 * cell, 2.0 * feature, 0.45 * min(W, D))
    run = Amplification(NodeTables(work_dir, prefix), H, extent, cell, R, 0.5 * R, rng, scales=scales,
                        precision=precision, sea_steps=sea_steps, sea_spacing=sea_spacing,
                        fallen_blocks=fallen_blocks)
    run.timer = StepTimer(["implicitization", "geology", *([] if flat else spec.steps(run)), "construction tree"],
                          progress)
    tree = run.tree
    rel = tree.file("heights.npy", lambda p: np.save(p, H.astype(np.float32)))
    table = {"type": "implicit_heightfield", "extent": [float(v) for v in extent], "source": "file", "file": rel,
             "R": float(R), "T": float(run.T)}
    amp, fit = (detail_amplification(H, cell, precision, seed=int(rng.integers(2 ** 31))) if detail
                else (None, {}))
    if amp is not None:
        # Detail fades out before the seam where the far field's frame takes over (see .far_field).
        amp.update(border=float(R + 1.01 * cell), taper=float(min(4.0 * cell, 0.2 * min(W, D))))
        table["amplification"] = amp
    run.terrain = tree.add("terrain", table)
    run.timer.step("implicitization")
    if preset == "sea":
        # A flat DEM under the fallback level has no wet cell: the sea still has its level.
        run.sea_level = water.sea_level if water.sea_level is not None else level
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
    if "sparse_note" in stats:
        notes.append(stats.pop("sparse_note"))
    notes += stats.pop("notes", [])  # what the landforms noted (e.g. the fallen blocks)
    stats.update(nodes=int(root.count()), memory_bytes=int(root.tree_nbytes()),
                 primitives=int(sum(v for k, v in stats.items() if k.endswith("primitives"))),
                 timings_s=run.timer.timings, notes=notes, detail_fit=fit)
    result = Amplified(tree.tables, tree.files, root, extent, H, preset, reason, scales, precision, amp, water,
                       focus, water.sea_level, stats)
    if len(children) == 1 and children[0] in run.bare:
        result.landforms = tree.builder.named(run.bare[children[0]])
    mesh = water_mesh(water, extent, sea_reach_cells=int(math.ceil(2.5 * feature / cell)) + 1)
    if mesh is not None:
        result.water_file = tree.file("water.ply", lambda p: mesh.export(p))
    return result
