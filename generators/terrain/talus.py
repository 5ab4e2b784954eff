"""Fallen blocks at the feet of cliffs: where the ``strata`` preset's walls shed rock (issue 34).

A cliff of layered rock does not end in clean ground: blocks broken from its beds
lie at its foot, most of them close to the wall, fewer farther out (a talus
apron). The terrain-amplification paper carves the walls but leaves their feet
bare; here the blocks of implicit-blocks-2020 are replicated over the carved
terrain (``host``) on the apron only:

Apron (from the DEM, in metres)
    Cells steeper than ``STEEP_DEG`` are cliff. A cell of gentler ground belongs to
    the apron when it lies within ``reach`` of the nearest cliff cell and below it
    (ground above the nearest cliff cell is the plateau behind a cliff's edge). Its
    density, the probability that a block copy centred there is kept, falls from
    ``PEAK`` at the wall to 0 at ``reach`` as ``PEAK (1 - d / reach)^2``.
Blocks
    A ``blocks`` node (:mod:`arches_render.generators.blocks.scene_nodes`) over the
    carved terrain: equidimensional blocks ``b`` across, a block copy kept when most
    of its anchors lie within ``[-0.8 b, 0.15 b]`` of the ground (resting on it,
    partly buried), on ground facing up and gentler than ``REST_DEG`` (the angle of
    repose of coarse scree, not a wall or a roof), resting on it (three anchors within
    ``CONTACT b`` of the ground or in it: without, blocks hung over the apron's
    hollows), and its draw falls below the apron's density at its centroid.

Colour
    A block carries the beds of the cliff it broke from. The material paints the
    rock by the geology's strata at the shading point, which on a block at the foot
    is the cliff's lowest bed: under a banded wall every block came out in that one
    colour. On the blocks (the bare-rock gate, :func:`bare_rock_masks`) the material
    reads the geology lifted into the cliff band instead,
    ``rho(p + (a + a W(p / h)) z)`` with ``a = LIFT h`` (``h`` the DEM's cliff height,
    ``W`` one octave of fBm, seeded from the blocks' seed): about ``h / 4 .. 3 h / 4``
    above the block, so a block shows a bed of the wall above it; the lift changes
    over ``h``, so neighbouring blocks often share a bed (one fall) and a block
    straddling two beds shows their contact as tilted bedding. Built of the
    geology's own nodes: a ``resistance_fault`` whose plane lies under the whole
    tile (everything slipped up by ``a``) in a ``resistance_fold``.

Sizes. ``b`` is a twentieth of the cliff height, at least three precisions (a
block narrower than that would be noise) and at most ``MAX_BLOCK_M``; ``reach`` is
half the cliff height, at least two DEM cells. Both are chosen by eye on the
eroded mesas and a caldera, not measured from real talus.

References
----------
Paris, A., Peytavie, A., Guerin, E., Dischler, J.-M., Galin, E. (2020). Modeling
rocky scenery using implicit blocks. The Visual Computer 36(10) (section 5:
replication with presence criteria; the density and ``max_slope`` are additions).
Statham, I. (1976). A scree slope rockfall model. Earth Surface Processes 1(1)
(fall distance grows with block size: most blocks stop near the wall's foot).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from arches_render.atomic import atomic_write
from arches_render.npzfile import write_npz

__all__ = ["Apron", "talus_apron", "add_talus", "bare_rock_masks", "blocks_strata"]

#: DEM slope (degrees) from which a cell is cliff (also the strata preset's cliff sampling).
STEEP_DEG = 40.0
#: Steepest ground (degrees) a fallen block rests on.
REST_DEG = 35.0
#: Probability of keeping a block copy at the wall's foot (0.3 before blocks had to rest
#: on the ground, which drops about half of the copies: 0.6 keeps the apron as dense,
#: 4188 blocks on the eroded mesas against 4592 with the hovering ones).
PEAK = 0.6
#: How close to the ground (in block sizes) a resting block's three lowest anchors lie
#: (the blocks' ``contact``): its rounded edges (``smoothness`` 0.08 b) stand off the
#: hull's vertices by about that much.
CONTACT = 0.1
#: Largest block (m).
MAX_BLOCK_M = 40.0
#: Mean lift of the fallen blocks' beds, and its spread, in cliff heights (see Colour): on
#: the eroded mesas the blocks' beds then fall in the proportions of the beds within a
#: cliff height above them (36/19/17/28 % against 37/18/18/27 %), and a third of the
#: blocks straddle two beds, as many as at their own height.
LIFT = 0.5
#: Side of the density grid at most (cells; a larger DEM's apron is max-pooled).
MAX_GRID = 1024


@dataclass(frozen=True)
class Apron:
    """Where blocks may lie: a density grid over a box of the tile.

    Attributes
    ----------
    density : numpy.ndarray
        ``(ny, nx)`` probabilities, row 0 south, spanning ``box``'s ``x, y``.
    box : tuple
        ``(x0, y0, z0, x1, y1, z1)``: the region of the block copies' centroids.
    area_m2 : float
        Area of ground with a positive density.
    """

    density: np.ndarray
    box: tuple
    area_m2: float


def talus_apron(H, extent, cell, reach, block, border):
    """The apron at the feet of a DEM's cliffs, or ``None`` where it has none.

    Parameters
    ----------
    H : numpy.ndarray
        ``(ny, nx)`` heights (m), row 0 south; sample ``(j, i)`` at ``(x0 + i cell,
        y0 + j cell)``.
    extent : tuple
        ``(x0, y0, x1, y1)``, the first and last samples.
    cell : float
        DEM cell (m).
    reach : float
        Farthest a block lies from the cliff (m).
    block : float
        Block size (m): the region reaches ``2 block`` above and below the apron.
    border : float
        Width of the tile's border band left bare (m).

    Returns
    -------
    Apron or None
    """
    H = np.asarray(H, dtype=np.float64)
    gy, gx = np.gradient(H, cell)
    steep = np.hypot(gx, gy) > math.tan(math.radians(STEEP_DEG))
    if not steep.any():
        return None
    d, (jj, ii) = distance_transform_edt(~steep, sampling=cell, return_indices=True)
    ny, nx = H.shape
    J, I = np.mgrid[0:ny, 0:nx]
    inner = np.minimum(np.minimum(I, nx - 1 - I), np.minimum(J, ny - 1 - J)) * cell > border
    apron = ~steep & inner & (d <= reach) & (H < H[jj, ii])
    if not apron.any():
        return None
    density = np.where(apron, PEAK * (1.0 - d / reach) ** 2, 0.0)
    rows, cols = np.nonzero(apron)
    j0, j1, i0, i1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    crop = density[j0:j1, i0:i1]
    f = max(1, math.ceil(max(crop.shape) / MAX_GRID))
    if f > 1:  # max-pooled: a narrow foot keeps its blocks
        py, px = -crop.shape[0] % f, -crop.shape[1] % f
        crop = np.pad(crop, ((0, py), (0, px))).reshape(crop.shape[0] // f + (py > 0), f, -1, f).max((1, 3))
    x0, y0 = extent[0], extent[1]
    z = H[apron]
    box = (x0 + (i0 - 0.5) * cell, y0 + (j0 - 0.5) * cell, float(z.min()) - 2 * block - cell,
           x0 + (i0 - 0.5 + crop.shape[1] * f) * cell, y0 + (j0 - 0.5 + crop.shape[0] * f) * cell,
           float(z.max()) + 2 * block + cell)
    return Apron(crop.astype(np.float32), tuple(float(v) for v in box), float(apron.sum()) * cell * cell)


def bare_rock_masks(gate: str, block: float) -> list:
    """Material masks that keep grass and sand off the blocks' faces.

    The landscape material grows grass and sand on gentle ground; a block's flat top
    would read as a grassy platform. The mask's field, the node ``gate``, is
    ``min(f_host, -f_talus)`` (``difference`` of the carved terrain and the blocks):
    at a hit on a block it is the host's value there, minus the point's height above
    the ground, and at a hit on the ground about 0 (within the tracer's tolerance, a
    few decimetres at kilometres). The layers keep their coverage above ``-0.12 b``
    and lose it below ``-0.25 b``: a block's top is bare, its foot may be grown round.

    Parameters
    ----------
    gate : str
        The node ``difference(host, talus)`` (``talus`` the blocks over ``host``).
    block : float
        Block size (m).

    Returns
    -------
    list
        ``masks`` entries of a ``triplanar`` material.
    """
    return [{"layer": layer, "node": gate, "lo": -0.25 * block, "hi": -0.12 * block}
            for layer in ("grass", "sand")]


def blocks_strata(gate: str, block: float, cliff_height: float, floor: float, seed: int) -> dict:
    """The ``blocks`` key of the material's ``strata``: the geology lifted into the cliff band
    (see Colour in the module docstring) where the gate (the bare-rock masks' node) is on a
    block, with the masks' ramp inverted.

    Parameters
    ----------
    gate : str
        The bare-rock masks' node.
    block, cliff_height : float
        Block size and the DEM's cliff height (m).
    floor : float
        A height (m) below every block (the apron's lowest ground less a cliff height):
        the plane of the lifting fault, which slips everything above it.
    seed : int

    Returns
    -------
    dict
    """
    a = LIFT * cliff_height
    lift = {"type": "resistance_fault", "child": "geology", "point": [0.0, 0.0, floor],
            "normal": [0.0, 0.0, 1.0], "slip": [0.0, 0.0, a], "width": 1.0}
    return {"node": {"type": "resistance_fold", "child": lift, "amplitude": a, "wavelength": cliff_height,
                     "octaves": 1, "seed": seed},
            "gate": gate, "lo": -0.12 * block, "hi": -0.25 * block}


def _clamp_margin(run):
    """The blocks field's clamp ``m`` (its value wherever no block is near): deeper than
    the tracer's hit tolerance anywhere in the scene (``eps t`` up to ``eps`` times the
    scene's diagonal, :class:`arches_render.render.sphere_tracer.SphereTracer`), else
    a distant ray stops on the clamp level of the blocks' whole region: a box of
    ground floating in the sky (seen on a 5.7 km tile at 1.3 km with the default 25 cm)."""
    W, D = run.size
    return float(max(0.25, 4e-4 * math.hypot(W, D, run.relief[2])))


def _save_density(path, density):
    with atomic_write(path) as f:
        write_npz(f, {"density": density})


def add_talus(run, host: str, cliff_height: float) -> str:
    """Add fallen blocks at the feet of the DEM's cliffs over node ``host``; return the
    name of the node to use in its place (``host`` itself where no cliff has a foot).

    Parameters
    ----------
    run : Amplification
        The amplify run (its DEM, tree, precision, random state and stats).
    host : str
        The carved terrain's node.
    cliff_height : float
        The DEM's cliff height (m).

    Returns
    -------
    str
    """
    block = float(min(max(cliff_height / 20.0, 3.0 * run.precision), MAX_BLOCK_M))
    reach = float(max(0.5 * cliff_height, 2.0 * run.cell))
    apron = talus_apron(run.heights, run.extent, run.cell, reach, block, 2.0 * run.R)
    seed = int(run.rng.integers(0, 2 ** 31))
    if apron is None:
        return host
    rel = run.tree.file("talus.npz", lambda p: _save_density(p, apron.density))
    node = run.tree.add("talus", {
        "type": "blocks", "host": host, "structure": "equidimensional",
        "tile_size": 4.0 * block, "spacing": block, "seed": seed,
        "smoothness": 0.08 * block, "warp": 0.02 * block, "warp_wavelength": 0.3 * block,
        "region": list(apron.box), "distance_range": [-0.8 * block, 0.15 * block],
        "min_slope": 0.0, "max_slope": REST_DEG, "contact": CONTACT * block, "density": rel,
        "margin": _clamp_margin(run)})
    n = int(node.children[1].n_present)
    run.stats["fallen_blocks"] = n
    # The material's cavity term samples the field in the air around a point as a
    # distance; the blocks' clamp (-m wherever no block is near) made the air over
    # the whole apron read as rock and darkened every shot by 10 % (a caldera's walls
    # at 150 m cells): it samples the carved terrain instead.
    # One named gate for the masks and the strata: the material evaluates it once.
    run.tree.add("talus_bare", {"type": "difference", "children": [host, "talus"]})
    look = {"masks": bare_rock_masks("talus_bare", block), "cavity_node": host}
    if "geology" in run.tree.tables:
        look["strata_blocks"] = blocks_strata("talus_bare", block, cliff_height,
                                              apron.box[2] - cliff_height, seed + 1)
    run.stats["fallen_blocks_look"] = look
    run.bare["talus"] = host  # close shots frame the cliffs, not the blocks
    run.stats.setdefault("notes", []).append(
        f"fallen blocks: {n} blocks about {block:.3g} m across at the feet of the cliffs, "
        f"on {apron.area_m2 / 1e6:.3g} km2 within {reach:.3g} m of them")
    return "talus"
