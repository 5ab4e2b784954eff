"""Scene files for amplified terrains: TOML text, cameras, sun, material, water and far field.

``arches-render amplify`` writes the construction tree it built as ``[nodes.*]``
tables of a scene file (TOML data, never code), with the arrays of primitive sets
in ``.npz`` files and the heights in a ``.npy`` beside it. This module turns those
tables into TOML text and chooses what a first render needs
(:func:`scene_document`):

Cameras
    Close shots of the landforms (:mod:`.shots`), named after the preset's
    landform (``sea_cave_1``, ...), then ``overview`` (:func:`.overview.frame_camera`):
    aimed at the features (the centroid of the generated primitives, else the
    terrain's centre) from *downhill* (the sea, the valley), so that cliffs, caves
    and canyon walls face the camera, low, with sky over the relief; an isolated
    landform (a volcanic cone, a butte) is the subject, framed whole.
Sun
    ``sunsky`` at 35 degrees, 55 degrees round from the first camera's azimuth:
    grazing enough to model overhangs with shadow, bright enough to see into caves.
Ground and water
    The far field (``[[far_field]]``, :mod:`.far_field`) continues the terrain to
    the horizon in the same material (without the terms that read the tile's fallen
    blocks: :func:`far_material`), and the sea with it where the sea reaches
    the tile's border; the water surfaces of the tile (:mod:`.water`) are a mesh, in
    :data:`WATER`, a dark base under a dielectric coat that mirrors the sky.
    Every tile gets an ``[atmosphere]``: distance reads as haze, and the far field
    fades into the sky at the horizon; the air is
    thinned on tiles wider than a third of :data:`HAZE_RANGE_M` so that the air's
    meteorological range is :data:`HAZE_WIDTHS` tile widths (default air, turbidity 3,
    sees about 20 km: a 220 km tile's overview was a fog bank).
Material
    The ``terrain`` triplanar preset (rock, sand, grass, snow) with its layer
    heights rescaled to the DEM's elevation range, so that a 6 km DEM is not all
    snow and a 100 m one not all sand; the rock coloured by the preset's own
    geology (strata palette, cavity, wetness at sea level:
    :func:`arches_render.materials.masks.terrain_look`).
Preview
    The PNG beside the EXR goes through ACES 2.0's view (:data:`VIEW`), as a camera's
    picture goes through a tone curve: the sky and sunlit ground keep their detail
    beside shaded rock.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np

from arches_render.materials.masks import PALETTES, terrain_look

from .far_field import surrounding_ground
from .overview import frame_camera
from .presets import PRESETS

__all__ = ["landscape_material", "sun_for", "scene_document", "LANDFORM_NAMES"]

#: Meteorological range of the default air (turbidity 3; :mod:`arches_render.render.atmosphere`),
#: metres: tiles wider than a third of it get thinner air (``density = HAZE_RANGE_M /
#: (HAZE_WIDTHS width)``).
HAZE_RANGE_M = 20000.0

#: The air's range in tile widths: the overview looks across the whole tile from near its
#: edge, low (:func:`frame_camera`). At one width (the aerial overview's rule) a 32 km
#: tile seen that way was a blue-grey murk; at three its hills read to the far side.
HAZE_WIDTHS = 3.0

#: The water's material: a dark blue-green base under water's dielectric coat (GGX,
#: ``ior`` 1.333), as the gallery's sea scenes have it. Water mirrors the sky, dark
#: looking down and bright towards the horizon (Fresnel). A diffuse blue-green
#: (the first material) lit the sea pale cyan wherever the sun fell on it, with the
#: cliffs' shadows cut out of it as hard dark shapes (Devil's Slide's sea caves).
WATER = {"type": "glossy", "color": [0.02, 0.05, 0.06], "roughness": 0.05, "ior": 1.333}

#: The previews' view transform (:mod:`arches_render.imaging.colour`): ACES 2.0's, whose
#: shoulder rolls the highlights off. A landscape's close shot puts a shaded wall, a
#: sunlit floor and the sky in one frame, and the metered exposure that reads the wall
#: clipped the rest: NM's canyon floor a featureless pale tan and its sky white,
#: Devil's Slide's sky and sea one white band. The EXR keeps the linear numbers.
VIEW = "aces"

#: Camera names of the close shots, per preset.
LANDFORM_NAMES = {"sea": "sea_cave", "river": "undercut", "karst": "tunnel", "hoodoos": "hoodoos",
                  "strata": "cliff"}

def sun_for(views, elevation=35.0, turn=55.0):
    """A ``[[lights]]`` sunsky table lighting the faces the cameras see.

    Parameters
    ----------
    views : dict or list of dict
        Camera tables with ``azimuth``, the direction each looks in (degrees
        counter-clockwise from +x); the first matters most.
    elevation : float
        The sun's elevation (degrees).
    turn : float
        How far the sun is turned aside from straight behind a camera (degrees).

    Returns
    -------
    dict
        ``type = "sunsky"`` with ``azimuth`` the direction *towards* the sun.

    Notes
    -----
    The sun sits behind the first view, turned aside by ``turn``: the faces it sees
    are lit and their relief casts shadows sideways. The other views must not look
    into it: where one would (within :data:`SUN_CLEAR` of the sun's azimuth: the
    overview of a small volcano looked 7 degrees from a sun 35 degrees up and its sky
    came out white), the sun moves to the azimuth, among a 1-degree circle and the
    directions where two views' angles balance, that keeps every view that far from
    it and the first view's angle nearest its ideal ``180 - turn``; when no azimuth
    clears every view, the worst view is kept nearest the ideal.
    Keeping the worst view nearest the ideal instead (max-min) lit the NM canyon's
    first close shot from its side (98 degrees): a quarter of what it saw was lit, and
    its shadow rays took 23.9 steps against 16.0; clearing 90 degrees moved that sun to
    the other side of the shot (25.2 steps) for an overview 71 degrees from it, lit
    from the side and back, with the sun well out of its frame.
    """
    views = [views] if isinstance(views, dict) else list(views)
    wrap = lambda a: (a + 180.0) % 360.0 - 180.0  # noqa: E731
    ideal = 180.0 - turn
    own = wrap(views[0]["azimuth"] + 180.0 + turn)  # behind the first view, turned aside
    # The 1-degree circle, and exactly the directions where two views' angles balance (their
    # bisectors and the perpendiculars): near-opposite views have their only clear ones there.
    mids = [v["azimuth"] + 0.5 * wrap(w["azimuth"] - v["azimuth"]) for v in views for w in views]
    candidates = ([own] + [float(a) for a in range(-180, 180)]
                  + [wrap(m + k) for m in mids for k in (90.0, -90.0, 180.0)])
    first = lambda az: abs(abs(wrap(az - views[0]["azimuth"])) - ideal)  # noqa: E731
    fine = [a for a in candidates if all(abs(wrap(a - v["azimuth"])) >= SUN_CLEAR for v in views)]
    if fine:
        az = min(fine, key=first)  # (min keeps the first of equals: the first view's own sun)
    else:
        az = min(candidates, key=lambda a: max(abs(abs(wrap(a - v["azimuth"])) - ideal) for v in views))
    return {"type": "sunsky", "elevation": float(elevation), "azimuth": float(az), "turbidity": 3.0}


# -- lookdev (issue 15): the rock's strata palette per preset ----------------------------------
#: Chalk and limestone coasts and karst, sandstone canyons and layer cakes, banded badlands.
STRATA_PALETTE = {"sea": "limestone", "river": "sandstone", "karst": "limestone", "hoodoos": "badlands",
                  "strata": "sandstone"}


#: Degrees between a camera's view azimuth and the sun's under which it looks into the
#: sun (:func:`sun_for`).
SUN_CLEAR = 60.0
#: A relief (m) from which a DEM is dressed as high mountains (:func:`landscape_material`).
ALPINE_RELIEF = 1500.0
#: A rise of the land (m) from which its top is snowed on (:func:`landscape_material`): below
#: it, hills, mesas and coastal ranges (the eroded mesas' 330 m caprock came out as white
#: sheets of snow, Montara Mountain's 590 m above the Pacific with a snow cap).
SNOW_RELIEF = 1000.0

#: The rock texture's tile (m) per metre of the DEM's cliff height on sea cliffs, and
#: its range (:func:`landscape_material`). The ``terrain`` preset's 6 m tile, made for a
#: 200 m scene, drew 1-2 m cobbles on sea cliffs 30-100 m high, seen from the sea-cave
#: shots 20-50 m away: a dry-stone wall. At a fifth of the cliff's height the same
#: texture reads as a jointed rock face (Devil's Slide, 98 m: 20 m; the eroded coast,
#: 80 m: 16 m). Not for the other presets: their shots stand farther from the walls,
#: where the 6 m tile averages out, and a larger one showed its gravel (the eroded
#: mesas' sandstone at 22 m read as conglomerate, Aletsch's blobs at 30 m as pebbles).
ROCK_TILE_PER_CLIFF = 0.2
ROCK_TILE_RANGE = (6.0, 30.0)


#: Slope (degrees) below which ground holds soil, and the share of a relief's top quarter
#: that must be that flat for grass to cover its top (:func:`flat_topped`).
FLAT_SLOPE = 5.0
FLAT_TOP_SHARE = 0.5


def flat_topped(heights, cell) -> bool:
    """Whether a relief is flat-topped: at least :data:`FLAT_TOP_SHARE` of the ground above
    three quarters of its relief slopes less than :data:`FLAT_SLOPE` degrees (mesas and
    canyon plateaus: 0.54-0.81 of the shipped DEMs; a volcanic cone, ridges, mountains:
    0.02-0.10)."""
    H = np.asarray(heights, dtype=np.float64)
    zlo, zhi = float(H.min()), float(H.max())
    if not zhi > zlo or min(H.shape) < 2:
        return False
    gy, gx = np.gradient(H, float(cell))
    top = H >= zlo + 0.75 * (zhi - zlo)
    flat = np.hypot(gx, gy)[top] < math.tan(math.radians(FLAT_SLOPE))
    return bool(flat.mean() >= FLAT_TOP_SHARE)


def landscape_material(zlo, zhi, sea_level=None, geology=None, box=None, preset=None, cell=1.0,
                       cliff_height=None, flat_top=False):
    """The ``terrain`` triplanar preset with layer heights fitted to ``[zlo, zhi]``.

    Sand covers low flats (up to 12 % of the relief, or a little above sea level),
    grass gentle slopes from 10 % to 75 % (bare rock above: a cone's rim, ridges and peaks),
    or to the top of a ``flat_top`` relief without snow (:func:`flat_topped`: mesas and
    canyon plateaus, whose bare tops crossed their beds in camouflage blotches), and
    snow only the top 5 % of land rising
    :data:`SNOW_RELIEF` or more above the DEM's floor or the sea (a 300 m island over a
    2 km deep sea floor was snowed on its top 115 m; with 300 m, desert mesas were
    capped with snow). High mountains (land rising
    :data:`ALPINE_RELIEF` or more: the Aletsch DEM's 3.7 km came out as orange
    sandstone bands under 200 m of snow) get snow on the top quarter of that rise and
    grey rock (the ``limestone`` palette) whatever the preset. With ``geology`` (the
    built resistance node of the scene's ``[nodes.geology]``) and ``box`` (the rock's
    volume), the rock takes the strata colours of the preset's palette
    (:data:`STRATA_PALETTE`), the cavity term (reach two cells) and, with
    ``sea_level``, a wet band; above the grass (not on high mountains), gentle ground
    is scree in the palette's mean colour (the sand layer, which keeps to slopes under
    18-26 degrees, up to the snow line; low flats take that colour too: sand is the
    local rock weathered). With ``cliff_height`` (m) and the ``sea`` preset the
    rock texture's tile is :data:`ROCK_TILE_PER_CLIFF` of it, within
    :data:`ROCK_TILE_RANGE`.
    """
    relief = max(zhi - zlo, 1e-3)
    # (the relief of the land: a deep sea floor makes no mountain)
    land = zhi - (zlo if sea_level is None else max(zlo, sea_level))
    alpine = land >= ALPINE_RELIEF
    sand_top = zlo + 0.12 * relief if sea_level is None else sea_level + 0.06 * relief
    snowy = land >= SNOW_RELIEF
    grass_top = zhi + relief if flat_top and not snowy else zlo + 0.75 * relief
    over = {
        "sand.height_max": sand_top, "sand.height_soft": 0.04 * relief,
        "grass.height_min": zlo + 0.10 * relief, "grass.height_max": grass_top,
        "grass.height_soft": 0.05 * relief,
        "snow.height_min": zhi - (0.25 if alpine else 0.05) * land if snowy else zhi + relief,
        "snow.height_soft": 0.02 * relief,
    }
    if cliff_height and preset == "sea":
        lo, hi = ROCK_TILE_RANGE
        over["rock.scale"] = float(min(max(ROCK_TILE_PER_CLIFF * cliff_height, lo), hi))
    # Tiling without repetition and the detail layer come with the preset (issue 24).
    mat = {"type": "triplanar", "preset": "terrain", "overrides": over}
    if geology is not None:
        palette = "limestone" if alpine else STRATA_PALETTE.get(preset, "sandstone")
        mat.update(terrain_look(geology, box, palette, "geology", sea_level,
                                cavity_radius=2.0 * cell))
        if not alpine and grass_top < zhi:
            # Scree: gentle ground above the grass is covered by the rock's own debris,
            # its beds mixed (the sand layer, gentle slopes only, in the palette's mean
            # colour): bare, a volcano's upper flanks showed its horizontal beds as a
            # bullseye of rings; beds show where the rock stands steep.
            over["sand.height_max"] = over["snow.height_min"]
            over["sand.tint"] = [round(float(c), 4) for c in np.mean(PALETTES[palette], axis=0)]
    return mat


def far_material(material):
    """The far field's material: ``material`` (the tile's, before the fallen blocks' terms)
    without its occlusion. The blocks' bare-rock masks and occlusion read nodes of the
    tile (its talus, its eroded strata) that the far field's continued relief does not
    follow: there the masks read bare rock everywhere, and the eroded mesas' overview
    showed a green tile ringed by banded far relief to the horizon, the tile's edge
    plain to see (a caldera's distant flanks: strata bands aliased to moire). Occlusion
    from the tile's field means nothing on the far field's mesh."""
    far = copy.deepcopy(material)
    far.pop("cavity", None)
    return far


def _geology(result):
    """The built geology node of ``result`` (the material's strata read it) and the rock's volume."""
    from arches_render.scene.nodes import NodeBuilder
    if "geology" not in result.tables:
        return None, None
    node = NodeBuilder({"geology": result.tables["geology"]}, Path("geology.toml"), Path(".")).named("geology")
    x0, y0, x1, y1 = result.extent
    base = float(result.terrain.bounds()[0][2])
    return node, (np.array([x0, y0, base]), np.array([x1, y1, float(result.heights.max())]))


#: How far around the tile, in tile widths, the close shots see the far field's ground
#: (:func:`.far_field.surrounding_ground`): their cameras' rays reach about 50 landform
#: distances, and past a few tiles the far field fades to the DEM's mean height.
SURROUNDINGS_WIDTHS = 4.0


def scene_document(result, name, work_dir, progress=None, close=3):
    """The scene document of an :class:`~.amplify.Amplified` and the header lines that describe it.

    Parameters
    ----------
    result : Amplified
    name : str
        Scene name.
    work_dir : Path
        Folder holding the data files of ``result`` (the water mesh is read there).
    progress : callable, optional
        ``progress(done, total)`` while choosing the close shots.
    close : int
        Close shots wanted.

    Returns
    -------
    (dict, list of str)
        The document for :func:`toml_text` and the header lines (preset and
        reason, precision and detail, water, cameras, notes).
    """
    import trimesh

    from .shots import close_shots, view_azimuth
    H, extent = result.heights, result.extent
    # The layers' heights (sand, grass, snow line) are the region's: a refined crop's
    # come from the DEM around it (its snow line is the mountains', not the crop's top).
    region = H if result.context is None else result.context[0]
    zlo, zhi = float(np.min(region)), float(np.max(region))
    x0, y0, x1, y1 = extent
    size = max(x1 - x0, y1 - y0)
    stats = result.stats
    water = result.water
    wmesh = trimesh.load_mesh(Path(work_dir) / result.water_file, process=False) if result.water_file else None
    feature = result.feature
    far_sea = float(water.sea_level) if water is not None and water.wet and water.touches_border else None
    over = frame_camera(H, extent, result.focus, sea_level=far_sea, context=result.context)
    overview = {"origin": over["origin"], "target": over["target"], "fov": over["fov"]}

    def sun_views(first):
        """The views the sun is chosen for: the first close shot (if any), then the overview."""
        return [dict(v, azimuth=view_azimuth(v)) for v in (first, overview) if v is not None]

    # One sun: lit from behind the first close shot unless that puts it in the overview's
    # lens (sun_for). Choosing it for every view left none clear of them all but one that
    # lit the first from the side (Jacksboro: 74 degrees from its ideal; shadow rays 40
    # steps), so the other close shots turn away from it instead (shots.close_shots).
    shots = close_shots(result.landforms or result.root, result.terrain, H, extent, feature,
                        water_level=water.level if water is not None else None, water_mesh=wmesh, count=close,
                        margin=result.terrain.R_np + 2 * stats["cell_size"], progress=progress,
                        sun=lambda first: (sun_for(sun_views(first))["azimuth"], SUN_CLEAR),
                        surroundings=surrounding_ground(result.terrain, SURROUNDINGS_WIDTHS, far_sea, result.context))
    label = LANDFORM_NAMES[result.preset]
    cameras = {f"{label}_{k + 1}": shot.table() for k, shot in enumerate(shots)}
    cameras["overview"] = overview
    doc = {
        "scene": {"name": name,
                  "description": f"DEM amplified with the '{result.preset}' preset (seed {stats['seed']}): "
                                 f"{stats['nodes']} nodes, {stats['primitives']} primitives"},
        "render": {"resolution": [640, 360], "spp": 32, "max_depth": 3, "view": VIEW},
        "cameras": cameras,
        "lights": [sun_for(sun_views(shots[0] if shots else None))],
        "materials": {"landscape": landscape_material(zlo, zhi, result.sea_level, *_geology(result),
                                                      preset=result.preset, cell=stats["cell_size"],
                                                      cliff_height=result.scales.get("cliff_height_m"),
                                                      flat_top=flat_topped(result.heights, stats["cell_size"]))},
        "field": {"root": "world", "material": "landscape"},
    }
    far = {"node": "terrain", "material": "landscape"}
    look = stats.get("fallen_blocks_look")
    if look:  # fallen blocks: bare rock, and the occlusion of the ground they lie on (.talus)
        mat = doc["materials"]["landscape"]
        doc["materials"]["landscape_far"] = far_material(mat)
        far["material"] = "landscape_far"
        mat["masks"] = look["masks"]
        if "cavity" in mat:
            mat["cavity"]["node"] = look["cavity_node"]
        if "strata" in mat and "strata_blocks" in look:  # the blocks carry their cliff's beds
            mat["strata"]["blocks"] = look["strata_blocks"]
    if water is not None and water.wet:
        doc["materials"]["water"] = dict(WATER)
        if result.water_file:
            doc["meshes"] = [{"file": result.water_file, "material": "water"}]
        if water.touches_border:
            far.update(sea_level=float(water.sea_level), water_material="water")
    doc["far_field"] = [far]
    # Air on every tile: the far field runs to the horizon, and without haze a small tile's
    # overview ended in a ruled line where the far ground met the sky (a 0.9 km volcano's
    # plain: 76 % contrast at the skyline; tiles over a kilometre, in default air: 8 %).
    thin = HAZE_RANGE_M / (HAZE_WIDTHS * size)
    doc["atmosphere"] = {} if thin >= 1.0 else {"density": round(thin, 4)}
    doc["nodes"] = result.tables
    lines = [f"Terrain amplification (Paris et al. 2019): {stats['nodes']} nodes, {stats['primitives']} primitives, "
             f"{stats['memory_bytes'] / 1e6:.2f} MB",
             f"Preset {result.preset}: {result.reason}",
             "Landform sizes (m): " + ", ".join(f"{k[:-2]} {v:.3g}" for k, v in result.scales.items()),
             f"Precision {result.precision:g} m: " + (
                 f"{result.detail['octaves']} fBm octaves from {result.detail['wavelength']:g} m, "
                 f"gain {result.detail['gain']:.3g} (Hurst {stats['detail_fit'].get('hurst') or 0:.2f})"
                 if result.detail else "no detail below the DEM's cell")]
    if water is not None and water.wet:
        lines.append(f"Water: {'sea at %g m' % water.sea_level if water.sea_level is not None else 'no sea'}"
                     f"{', reaching the border' if water.touches_border else ''}; {len(water.lakes)} lakes")
    lines.append("Cameras: " + "; ".join(
        [f"{n} ({s['height_class']}, {s['height_m']:.0f} m above ground, landform {s['volume_m3']:.3g} m3, covers "
         f"{100 * s['cover']:.0f} % of the frame; legible: sky {100 * s['legible_sky']:.0f} %, background "
         f"{100 * s['legible_background']:.0f} %, one sheet {100 * s['legible_one_surface']:.0f} %, contrast "
         f"{100 * s['legible_contrast']:.0f} %)"
         for n, s in zip(cameras, shots)] + ["overview"]))
    lines += [f"Note: {n}" for n in ([stats["note"]] if "note" in stats else []) + stats.get("notes", [])]
    return doc, lines
