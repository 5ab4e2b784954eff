"""The presets of terrain amplification: geology, landform processes and their steps, as data.

A preset (:class:`Preset`) is a geology function (the resistance tree ``rho`` it
builds for a DEM, section 4), a landform function (the erosion processes of
section 6 that add primitives to the tree) and the labels of the steps the
landform function reports, side by side in :data:`PRESETS`.
:func:`.amplify.amplify` runs them on an :class:`.amplification.Amplification`,
whose :class:`.amplification.StepTimer` checks each reported step against the
preset's list.

Landform sizes are metres, never DEM cells (issue 14): the same place from a 90 m
and from a 1 m DEM gets caves of the same size. They come from
:func:`.preset_choice.landform_scales`, measured on an analysis grid whose cell
follows the tile's extent: the feature size ``F`` (``feature_m``: sea caves 0.2 x the
coastal cliff ``C``, river undercuts 0.25 x the valley depth, karst tunnels a quarter
of a stratum, hoodoos 0.6 x the cliff; at least twice the precision ``p``), the
relief ``Z``, the valley depth, the cliff height and the strata thickness ``S``. DEM
cells ``c`` only say what the DEM resolves (a headland must be two cells wide to
be seen). A run makes at most :data:`MAX_PRIMITIVES` primitives per process: on
a large tile the Poisson spacing grows until the expected count fits (the sizes
stay), and the note says so.

``sea``      Sea level ``--sea-level`` (0); a soft stratum ``max(1.5 F, 0.2 C)`` thick at
             sea level and soft spots on the coast; three steps of sea erosion
             (section 6.1, Fig. 11) on the cliffs (faces steeper than 30 deg, or than
             ``atan(C / 3 c)`` on coarse DEMs) over a sea range
             ``max(F, 0.2 C)`` (the paper: 8 m on ~40 m cliffs), cavities up to
             ``0.8 F``, the second step on the
             mesh of the terrain carved by the first, so caves deepen and thin
             headlands are pierced into arches.
``river``    Stream power ``A^1/2 s`` on the filled DEM, riverbed and banks; walls
             carved on the walls (>= 30 deg) up to half the valley depth (at least
             ``F``) above the water, its stress spread over the floor (0.6 x the
             valley width), more in the soft strata (``S`` apart) of a layered geology:
             undercut canyon walls (Fig. 15, 23).
``karst``    Invasion percolation from the deepest sinks through two soft
             horizontal strata (section 6.2, Fig. 14, 17): tunnels of radius ``F``
             on a lattice of ``1.8 F``.
``hoodoos``  Placement by slope and drainage area, open grammar driven by
             alternating hard and soft strata one symbol (``F / 3``) thick
             (section 6.3, Fig. 18-20).
``strata``   The erosion node ``f - f_D (1 - rho)`` (section 6) over the steep
             faces, with folded and faulted strata ``min(S, cliff / 2)`` apart:
             layered cliffs with overhangs (Fig. 4, 10). ``f_D`` blends (sums) its
             spheres, their energy divided by their typical overlap: as a maximum
             it dipped between the spheres, and the soft beds receded most at each
             centre, in rows of round pockets (a caldera's walls read polka-dotted).

Carving energies: see :mod:`.amplification` (``Amplification.carving_arrays``).

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.ndimage import distance_transform_edt, maximum_filter

from . import hoodoos as hd, karst as ks
from .accessibility import heightfield_mesh
from .amplification import MAX_PRIMITIVES, SEA_STEPS, Amplification, NodeTables, StepTimer
from .banded import slab_mesh
from .falloff import g as falloff
from .geology import resistance
from .river_erosion import river_erosion
from .sea_erosion import sea_erosion_step
from .shallow_erosion import sample_mesh
from .skeletal_files import save_npz
from .talus import STEEP_DEG, add_talus

__all__ = ["PRESETS", "Preset", "Amplification", "NodeTables", "StepTimer", "SEA_STEPS", "MAX_PRIMITIVES"]

#: Lowest coastal cliff (m) the sea preset carves: below, a cave would be under the
#: smallest feature (1 m = 0.2 C) and the "cliff" is a beach or a dune.
MIN_COAST_CLIFF = 5.0


#: Most sites of a percolation lattice (the lattice spacing grows beyond).
MAX_LATTICE_SITES = 8_000_000


def _karst_sizes(run):
    """Tunnel radius and percolation lattice spacing of the karst preset (metres)."""
    W, D = run.size
    _, _, Z = run.relief
    tunnel = run.feature
    spacing = 1.8 * tunnel
    sites = W * D * 1.1 * Z / spacing ** 3
    if sites > MAX_LATTICE_SITES:
        spacing *= (sites / MAX_LATTICE_SITES) ** (1.0 / 3.0)
        tunnel = spacing / 1.8
        run.stats["sparse_note"] = f"karst lattice widened to {spacing:.3g} m (at most {MAX_LATTICE_SITES} sites)"
    return tunnel, spacing


def _turbulence(seed, wavelength, amplitude, octaves, **extra):
    """A ``resistance_turbulence`` table (fBm resistance variations)."""
    return {"type": "resistance_turbulence", "wavelength": float(wavelength), "amplitude": amplitude,
            "offset": 0.0, "octaves": octaves, "seed": seed, **extra}


# -- sea --------------------------------------------------------------------------------------
def sea_geology(run: Amplification, noise_seed: int) -> dict:
    """A soft stratum at sea level, soft spots on the thinnest headland and the cliff foot."""
    H, cell, rng, sea_level = run.heights, run.cell, run.rng, run.sea_level
    F, C = run.feature, run.scale("coast_cliff_m", 0.25 * run.relief[2])
    band = max(1.5 * F, 0.2 * C)
    # Less durable spots (the paper places them by hand): one on the thinnest headland,
    # where caves cut from both sides meet into an arch, and two on the cliff foot.
    x0, y0, x1, y1 = run.extent
    ny, nx = H.shape
    land = H > sea_level
    width = distance_transform_edt(land) * cell  # half-width of the land at each cell
    ridge = land & (width == maximum_filter(width, size=3)) & (width >= 2 * cell)
    ridge &= width <= max(3 * cell, 4.0 * F)
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
             "R": float(max(3.0 * F, 0.3 * C)), "weight": -0.5} for k in picks]
    return {"type": "resistance_blend", "children": [
        {"type": "resistance_constant", "value": 0.72},
        {"type": "resistance_plane", "point": [0.0, 0.0, float(sea_level + 0.3 * band)],
         "normal": [0.0, 0.0, 1.0], "R": float(band), "weight": -0.25},
        _turbulence(noise_seed, max(C / 6, 2 * F), 0.12, 3)] + soft}


def sea_steps(run: Amplification) -> list:
    """One step per sea-erosion step (``options["steps"]`` of amplify, default 3)."""
    return [f"sea erosion step {k + 1}" for k in range(run.sea_steps)]


def sea(run: Amplification) -> None:
    """Sea erosion with accessibility, each step on the mesh of the terrain carved so far."""
    H, extent, cell, tree = run.heights, run.extent, run.cell, run.tree
    W, D = run.size
    F, C = run.feature, run.scale("coast_cliff_m", 0.25 * run.relief[2])
    sea_range = max(F, 0.2 * C)  # the paper: 8 m for its ~40 m cliffs
    max_r = 0.8 * F  # per step: three steps cut about two feature sizes into soft rock
    # Waves undercut cliffs, not a wave-cut platform or a beach (a cavity carved in a
    # gentle shore is a crater): faces of at least 30 deg, or less where the DEM's cells
    # are too coarse to show the coastal cliff that steep (a cliff C high over 3 cells).
    cos_cliff = math.cos(min(math.radians(30.0), math.atan(C / (3.0 * cell))))
    coast = run.scales.get("coast_cliff_m")
    if coast is not None and coast < MIN_COAST_CLIFF:  # a beach or a shelf: no cliff to undercut
        run.stats["nothing"] = (f"no coastal cliff: the land by the sea rises {coast:.2g} m "
                                f"(sea caves need a cliff of {MIN_COAST_CLIFF:g} m)")
        for k in range(run.sea_steps):
            run.timer.step(f"sea erosion step {k + 1}")
        return
    mesh = heightfield_mesh(H, extent, run.mesh_step)
    weight = None
    steps_arrays = []
    for k in range(run.sea_steps):
        if run.sea_spacing:
            spacing = float(run.sea_spacing)
        else:  # the sea band's area on the DEM mesh bounds the sample count
            z = mesh.triangles_center[:, 2]
            steep = mesh.face_normals[:, 2] < cos_cliff
            area = float(mesh.area_faces[(np.abs(z - run.sea_level) < sea_range) & steep].sum())
            spacing = run.spacing_for(area, max_r)
        cliff = mesh.face_normals[:, 2] < cos_cliff
        prims = sea_erosion_step(mesh, run.rho, run.sea_level, sea_range, spacing=spacing, max_radius=max_r,
                                 beta=0.3, threshold=0.08, rays=16, seed=int(run.rng.integers(2 ** 31)),
                                 face_mask=cliff if weight is None else cliff & weight)
        arr = run.carving_arrays(prims)
        run.stats[f"sea_step{k + 1}_primitives"] = 0 if arr is None else int(len(arr["radius"]))
        run.timer.step(f"sea erosion step {k + 1}")
        if arr is None:  # nothing eroded: later steps would see the same terrain
            for j in range(k + 1, run.sea_steps):
                run.timer.step(f"sea erosion step {j + 1}")
            break
        steps_arrays.append(arr)
        if k == run.sea_steps - 1:
            break
        # The next step samples the carved terrain: mesh of the sea band of the tree so far
        # (sets given inline: only the final, merged set is written to a file).
        inline = [{"type": "skeletal_set", "combine": "sum", **{n: v for n, v in x.items()}}
                  for x in steps_arrays]
        current = tree.add(f"_sea_step{k + 1}", {"type": "sum", "children": ["terrain"] + inline})
        # The band mesh only guides sampling and rays: at most ~384 voxels across a large
        # tile. Its slab is at least 4 voxels thick: a thinner one can fall between two rows
        # of grid vertices and hold no surface (a large tile of a low coast).
        voxel = max(0.25 * max_r, max(W, D) / 384.0)
        half = max(sea_range + 2 * max_r, 2.0 * voxel)
        band = slab_mesh(current, extent, run.sea_level - half, run.sea_level + half, voxel, 2 * cell)
        tree.builder.forget(f"_sea_step{k + 1}")
        if band is None:  # no surface left in the band: keep the steps made
            run.stats["nothing"] = f"sea erosion stopped after step {k + 1}: no coast left in the sea band"
            for j in range(k + 1, run.sea_steps):
                run.timer.step(f"sea erosion step {j + 1}")
            break
        mesh, weight = band
    out = run.carve("sea_erosion", steps_arrays)
    if out:
        run.children.append(out[0])
        # Frame the deepest erosion: the last step carves inside the notches and caves.
        last = steps_arrays[-1]
        run.focus.append(0.5 * (last["a"] + last["b"]))


# -- river ------------------------------------------------------------------------------------
def river_geology(run: Amplification, noise_seed: int) -> dict:
    """Soft horizontal beds in a hard rock, each of its own depth, thickness and softness:
    undercuts where the river meets the soft ones.

    The paper builds its geology trees by "blending multiple plane primitives with a
    turbulence primitive" (Paris et al. 2019, Sec. 4.2). Periodic beds (one
    ``resistance_strata``) repeated one hardness profile up every wall: each soft bed
    was undercut alike and the strata colours (levels of the resistance) read as a
    uniform stripe, even with the turbulence over elevation (Sec. 4.1) varying each
    bed's peak. So the beds are plane primitives placed by :func:`bed_planes`: gaps of
    half to one and a half times the mean spacing, half-thicknesses of 0.15 to 0.45 of
    it and weights -0.3 to -0.85 (mean -0.575, the periodic beds' was -0.6), so a thin
    bed barely softer than the rock beside it reaches only the middle colours while a
    thick, soft one is undercut deeply and shows the darkest. The 3-D turbulence (joints)
    and the one over elevation stay.
    """
    zlo, zhi, Z = run.relief
    F = run.feature
    spacing = float(np.clip(run.scale("strata_thickness_m", Z / 8), 2.0 * F, max(2.0 * F, Z / 3)))
    return {"type": "resistance_blend", "children": [
        {"type": "resistance_constant", "value": 0.75},
        *bed_planes(zlo, zhi, spacing, np.random.default_rng(noise_seed + 2)),
        _turbulence(noise_seed, 2.0 * F, 0.1, 3, strata=False),
        _turbulence(noise_seed + 1, 3.0 * spacing, 0.25, 3, strata=True)]}


#: Most soft beds :func:`bed_planes` places (each is a node of the geology tree,
#: evaluated wherever the strata colour is shaded).
MAX_BEDS = 24


def bed_planes(zlo: float, zhi: float, spacing: float, rng: np.random.Generator) -> list[dict]:
    """Soft horizontal beds from below ``zlo`` to above ``zhi``, irregularly spaced.

    Parameters
    ----------
    zlo, zhi : float
        The relief's lowest and highest elevation (metres).
    spacing : float
        The mean distance between beds (metres). Widened to at least
        ``2 (zhi - zlo) / (MAX_BEDS - 5)`` so that beds at the smallest gap (half a
        spacing) from up to one spacing below ``zlo`` to the first at or above ``zhi``
        number fewer than :data:`MAX_BEDS`.
    rng : numpy.random.Generator
        Draws the beds (the same generator state, the same beds).

    Returns
    -------
    list of dict
        ``resistance_plane`` tables: point on the bed's mid-plane, normal +Z, ``R``
        (the falloff radius: the bed's half-thickness) in ``[0.15, 0.45] spacing``,
        ``weight`` in ``[-0.85, -0.3]``; consecutive beds ``[0.5, 1.5] spacing`` apart.

    References
    ----------
    Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
    38(5), Sec. 4.2 (plane primitives blended into a geology tree).
    """
    spacing = max(float(spacing), 2.0 * (zhi - zlo) / (MAX_BEDS - 5))
    beds, z = [], zlo - spacing * rng.uniform(0.0, 1.0)
    while True:
        beds.append({"type": "resistance_plane", "point": [0.0, 0.0, float(z)], "normal": [0.0, 0.0, 1.0],
                     "R": float(spacing * rng.uniform(0.15, 0.45)), "weight": float(-rng.uniform(0.3, 0.85))})
        if z >= zhi:
            return beds
        z += spacing * rng.uniform(0.5, 1.5)


def river(run: Amplification) -> None:
    """Stream-power river erosion of the canyon walls."""
    H, F = run.heights, run.feature
    _, _, Z = run.relief
    mesh = heightfield_mesh(H, run.extent, run.mesh_step)
    # Floods reach half the valley's depth: on a 10 m DEM a canyon's walls stand back
    # from the river behind talus, their feet tens of metres above the water.
    flood = max(F, 0.5 * run.scale("valley_depth_m", run.scale("cliff_height_m", 0.25 * Z)))
    W, D = run.size
    # Walls up to the flood height along the rivers: a fraction of the tile at most.
    spacing = run.spacing_for(0.25 * W * D, 0.8 * F)
    # The river floods its whole floor: its stress reaches the walls of a flat-floored
    # canyon (half the valley width), and only the walls (>= 30 deg) are undercut.
    bank = max(3.0 * run.cell, 0.6 * run.scale("valley_width_m", 0.0))
    prims = river_erosion(H, run.extent, mesh, run.rho, spacing=spacing, bank_width=bank, min_slope_deg=30.0,
                          max_radius=F, flood_height=flood, beta=0.15, threshold=0.08,
                          seed=int(run.rng.integers(2 ** 31)))
    run.timer.step("stream power and sampling")
    run.add_carving("river_erosion", prims, "river_primitives")


# -- karst ------------------------------------------------------------------------------------
def karst_geology(run: Amplification, noise_seed: int) -> dict:
    """Two soft strata, each a few percolation sites thick (else the network dies out)."""
    _, zhi, Z = run.relief
    children = [{"type": "resistance_constant", "value": 0.8},
                _turbulence(noise_seed, 4.0 * run.feature, 0.12, 3, strata=False)]
    _, spacing = _karst_sizes(run)
    for frac in (0.25, 0.65):
        children.append({"type": "resistance_plane", "point": [0.0, 0.0, float(zhi - frac * Z)],
                         "normal": [0.0, 0.0, 1.0], "R": float(2.0 * spacing), "weight": -0.6})
    return {"type": "resistance_blend", "children": children}


def karst(run: Amplification) -> None:
    """Invasion percolation from the deepest sinks: a network of tunnels."""
    H, extent = run.heights, run.extent
    zlo, zhi, Z = run.relief
    seeds = ks.karst_seeds(H, extent, 6, run.rng)
    run.timer.step("sinks")
    tunnel, spacing = _karst_sizes(run)
    W, D = run.size
    sites = W * D * 1.1 * Z / spacing ** 3
    prims = ks.karst_network(run.terrain.elevation_np, extent, (zlo - 0.1 * Z, zhi), run.rho, seeds,
                             spacing=spacing, max_radius=tunnel, rho0=0.45, epsilon=0.1, beta=0.3,
                             max_sites=int(min(MAX_PRIMITIVES, max(2000, sites // 8))),
                             seed=int(run.rng.integers(2 ** 31)))
    run.add_carving("karst_tunnels", prims, "karst_primitives")


# -- hoodoos ----------------------------------------------------------------------------------
def hoodoos_geology(run: Amplification, noise_seed: int) -> dict:
    """Alternating hard and soft strata, about one grammar symbol per layer, each bed of
    its own hardness.

    The periodic beds alone made every bed the same: one hardness profile repeated up
    the whole relief, so the hoodoos grew the same stack of symbols and the strata
    colours (levels between hard and soft rock) were a uniform stripe. The paper's
    turbulence primitive over elevation, ``rho = t(p_z / lambda0)`` (Paris et al. 2019,
    Sec. 4.1), added to the beds gives each bed its own peak hardness: some beds
    reach the hardest colour and stand out as ledges and caps, others stay soft and
    thin; ``lambda0`` of three beds varies it from one bed to the next few.
    """
    zlo, _, Z = run.relief
    spacing = run.feature / 3.0  # one grammar symbol per layer
    return {"type": "resistance_blend", "children": [
        {"type": "resistance_constant", "value": 0.3},
        {"type": "resistance_strata", "spacing": float(spacing), "R": float(0.45 * spacing),
         "weight": 0.6, "phase": float(zlo)},
        _turbulence(noise_seed, 1.5 * spacing, 0.1, 2, strata=False),
        _turbulence(noise_seed + 1, 3.0 * spacing, 0.25, 3, strata=True)]}


def hoodoos(run: Amplification) -> None:
    """Hoodoos placed by slope and drainage area, grown by the open shape grammar."""
    H, extent, T = run.heights, run.extent, run.T
    s0 = run.feature / 3.0  # symbol height: hoodoos of about F (three symbols or more)
    W, D = run.size
    P = hd.hoodoo_probability(H, extent)
    run.timer.step("placement probability")
    P = P / max(float(P.max()), 1e-12)  # the best sites grow a hoodoo for sure
    sym = hd.hoodoo_field(H, extent, run.terrain.elevation_np, run.rho, spacing=run.spacing_for(W * D, 1.6 * s0, 6.0), s0=s0,
                          width0=0.7 * s0, probability=P, seed=int(run.rng.integers(2 ** 31)))
    if not len(sym):
        return
    Rf = np.maximum(0.8 * sym.width, run.precision)
    x = math.sqrt(1.0 - 0.5 ** (1.0 / 3.0))  # g(x) = 1/2: the surface where 2T g = T
    core = np.maximum(sym.width - x * Rf, 0.0)
    rel = run.tree.file("hoodoos.npz", lambda p: save_npz(p, a=sym.a, b=sym.b, radius=Rf,
                                                           energy=np.full(len(Rf), 2.0 * T), core=core))
    run.tree.add("hoodoos", {"type": "skeletal_set", "file": rel, "combine": "max",
                             "noise": {"amplitude": 0.12, "wavelength": float(max(s0 / 2, 2.0 * run.precision)),
                                       "octaves": 2, "seed": int(run.rng.integers(2 ** 31))}})
    run.children.append("hoodoos")
    run.stats["hoodoos"] = int(sym.hoodoo.max() + 1)
    run.stats["hoodoo_primitives"] = int(len(sym))
    run.focus.append(0.5 * (sym.a + sym.b))


# -- strata -----------------------------------------------------------------------------------
def strata_geology(run: Amplification, noise_seed: int) -> dict:
    """A folded, faulted layer cake."""
    zlo, _, Z = run.relief
    spacing = _bed_pair(run)
    x0, y0, x1, y1 = run.extent
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
    ang = run.rng.uniform(0, np.pi)
    return {"type": "resistance_fault", "child": folded,
            "point": [float((x0 + x1) / 2), float((y0 + y1) / 2), 0.0],
            "normal": [float(np.cos(ang)), float(np.sin(ang)), 0.0],
            "slip": [0.0, 0.0, float(0.5 * spacing)], "width": float(0.5 * spacing)}


def _bed_pair(run: Amplification) -> float:
    """Thickness of a hard + soft bed pair: the measured period, at least two pairs per cliff."""
    _, _, Z = run.relief
    cliff = run.scale("cliff_height_m", 0.25 * Z)
    return float(max(min(run.scale("strata_thickness_m", Z / 7), 0.5 * cliff), 2.0 * run.feature / 3.0,
                     4.0 * run.precision))


def _median_overlap(points, radius) -> float:
    """Median over ``points`` of the sum at each of the falloffs (radius ``radius``) of all
    of them, itself included (1 where no other lies within ``radius``)."""
    from scipy.spatial import cKDTree
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    share = falloff(np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1), radius)
    n = len(points)
    return float(np.median(1.0 + np.bincount(pairs[:, 0], share, n) + np.bincount(pairs[:, 1], share, n)))


def strata(run: Amplification) -> None:
    """The erosion node over the steep faces of the DEM."""
    H, extent, R, T = run.heights, run.extent, run.R, run.T
    mesh = heightfield_mesh(H, extent, run.mesh_step)
    steep = mesh.face_normals[:, 2] < math.cos(math.radians(STEEP_DEG))
    c = mesh.triangles_center
    x0, y0, x1, y1 = extent
    inner = (c[:, 0] > x0 + 2 * R) & (c[:, 0] < x1 - 2 * R) & (c[:, 1] > y0 + 2 * R) & (c[:, 1] < y1 - 2 * R)
    # Erosion spheres of half a bed pair (soft beds recede by about that much).
    Rd = max(0.5 * _bed_pair(run), 2.0 * run.precision)
    area = float(mesh.area_faces[steep & inner].sum())
    pts, _ = sample_mesh(mesh, run.spacing_for(area, 0.6 * Rd), (steep & inner).astype(float), run.rng)
    run.timer.step("cliff sampling")
    if not len(pts):
        if run.fallen_blocks:  # no cliff, no block
            run.timer.step("fallen blocks")
        return
    # The paper's blend, f_D summed over the spheres, each of energy 2T over their median
    # overlap (the sum of the falloffs at a sphere's centre): a recess along the soft beds
    # about as deep as one sphere of 2T carved, without a pocket at every centre.
    energy = 2.0 * T / _median_overlap(pts, Rd)
    rel = run.tree.file("strata_erosion.npz", lambda p: save_npz(p, a=pts, radius=np.full(len(pts), Rd),
                                                                  energy=np.full(len(pts), energy)))
    run.tree.add("strata_field", {"type": "skeletal_set", "file": rel, "combine": "sum"})
    run.tree.add("strata_eroded", {"type": "erosion", "child": "terrain", "field": "strata_field",
                                   "resistance": "geology"})
    run.children = ["strata_eroded"]
    if run.fallen_blocks:
        run.children = [add_talus(run, "strata_eroded", run.scale("cliff_height_m", 0.25 * run.relief[2]))]
        run.timer.step("fallen blocks")
    run.stats["erosion_field_primitives"] = int(len(pts))
    run.focus.append(pts)


# -- the table ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Preset:
    """One preset: what it makes, its geology, its landforms and the steps they report.

    Attributes
    ----------
    description : str
        One line for ``arches-render amplify --help``.
    geology : callable
        ``geology(run, noise_seed) -> table``: the resistance tree (a ``resistance_*``
        node table).
    landforms : callable
        ``landforms(run)``: adds the preset's primitives to the tree through ``run``.
    steps : callable
        ``steps(run) -> labels`` of the steps ``landforms`` reports, in order.
    """

    description: str
    geology: Callable
    landforms: Callable
    steps: Callable

    def resistance(self, run: Amplification) -> Callable:
        """Build the geology as node ``geology`` of the tree; return ``rho(P)`` on numpy points."""
        noise_seed = int(run.rng.integers(0, 2 ** 31))
        node = run.tree.add("geology", self.geology(run, noise_seed))
        return lambda P: resistance(node, P)


PRESETS = {
    "sea": Preset("sea cliffs, arches and caves (sea erosion with accessibility)",
                  sea_geology, sea, sea_steps),
    "river": Preset("canyon with undercut walls (stream-power river erosion)",
                    river_geology, river, lambda run: ["stream power and sampling"]),
    "karst": Preset("cave network (invasion percolation)",
                    karst_geology, karst, lambda run: ["sinks"]),
    "hoodoos": Preset("hoodoos (open shape grammar)",
                      hoodoos_geology, hoodoos, lambda run: ["placement probability"]),
    "strata": Preset("layered cliffs with folds and faults (erosion node)",
                     strata_geology, strata,
                     lambda run: ["cliff sampling"] + (["fallen blocks"] if run.fallen_blocks else [])),
}
