"""Make the gallery scenes ``scenes/gallery/*.toml``: landscapes after the papers' figures.

Each scene is a landscape (a terrain reaching out of frame or into the haze, sky,
sun and aerial perspective), not an object on a plane. The amplified ones start
from a synthetic DEM made here (seeded) and run terrain amplification
(:func:`arches_render.generators.terrain.amplify.amplify`) exactly as
``arches-render amplify`` does, then get a chosen camera, sun and atmosphere;
the others are written as TOML from the generators' scene keys.

Run from the repository root::

    python examples/make_gallery_scenes.py [NAME ...]

Data files (heights, primitive arrays, meshes) go to ``scenes/gallery/data/``.
``examples/make_gallery.py`` renders the scenes into ``docs/gallery/``.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter, zoom

import arches_render  # noqa: F401  (chooses the libLLVM before Dr.Jit loads)
from arches_render.generators.terrain.amplify import amplify
from arches_render.generators.terrain.scene_writer import scene_document
from arches_render.tomlfile import toml_text

REPO = Path(__file__).resolve().parents[1]
GALLERY = REPO / "scenes" / "gallery"
DATA = "data"


# -- DEM helpers ------------------------------------------------------------------------------
def smooth(t):
    """Smoothstep of ``t`` clamped to [0, 1]."""
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def grid(nx, ny, cell):
    """Sample coordinates of an ``ny x nx`` DEM centred on the origin."""
    x = (np.arange(nx) - (nx - 1) / 2) * cell
    y = (np.arange(ny) - (ny - 1) / 2) * cell
    return np.meshgrid(x, y)


def noise(shape, seed, sigma, amp=1.0):
    """Gaussian-filtered white noise of standard deviation ``amp`` (features of ``sigma`` samples)."""
    r = gaussian_filter(np.random.default_rng(seed).normal(size=shape), sigma, mode="wrap")
    return amp * r / r.std()


# -- scene assembly ---------------------------------------------------------------------------
def amplified(name, heights, cell, preset, seed=7, steps=None):
    """The scene document ``arches-render amplify`` writes for ``heights`` (data in scenes/gallery/data)."""
    (GALLERY / DATA).mkdir(parents=True, exist_ok=True)
    options = {"steps": steps} if steps is not None else None
    with tempfile.TemporaryDirectory(dir=GALLERY) as tmp:
        result = amplify(np.asarray(heights, np.float32), cell, preset, seed, Path(tmp), f"{DATA}/{name}",
                         options=options)
        for rel in result.files:
            (GALLERY / rel).parent.mkdir(parents=True, exist_ok=True)
            (Path(tmp) / rel).replace(GALLERY / rel)
    # The command's own document (camera, sun, material from the geology, ground, far field,
    # water); no close shots (the gallery picks its own camera).
    return scene_document(result, name, GALLERY, close=0)[0], result


def finish(doc, name, description, camera, sun, atmosphere=None, spp=32, max_depth=4, wavefront=False):
    """Gallery settings on a scene document: 1280x720, camera, sun, atmosphere; the
    preview's exposure is metered (no ``exposure`` key), its view ACES, denoised;
    ``wavefront`` for a field costly to march (``[render] wavefront``)."""
    doc["scene"] = {"name": name, "description": description}
    doc["render"] = {"resolution": [1280, 720], "spp": spp, "max_depth": max_depth, "view": "aces",
                     "denoise": True}
    if wavefront:
        doc["render"]["wavefront"] = True
    doc["camera"] = camera
    doc["lights"] = [dict({"type": "sunsky", "turbidity": 3.0}, **sun)]
    if atmosphere is not None:
        doc["atmosphere"] = atmosphere
    order = ["scene", "render", "camera", "lights", "atmosphere", "materials", "meshes", "field"]
    out = {k: doc[k] for k in order if k in doc}
    out.update({k: v for k, v in doc.items() if k not in out})
    return out


def write(name, doc, header):
    """Write ``scenes/gallery/NAME.toml``."""
    GALLERY.mkdir(parents=True, exist_ok=True)
    (GALLERY / f"{name}.toml").write_text(toml_text(doc, header))
    print(f"wrote {GALLERY / f'{name}.toml'}")


def glossy_water(doc):
    """Water that mirrors the sky (a dark base under a smooth dielectric coating)."""
    if "water" in doc["materials"]:
        doc["materials"]["water"] = {"type": "glossy", "color": [0.015, 0.045, 0.05], "roughness": 0.04}


# -- the scenes -------------------------------------------------------------------------------
def island_dem():
    """A chalk island: a tilted plateau with a headland, a neck and a stack, falling to the sea all round."""
    nx, ny, cell = 161, 161, 1.0
    X, Y = grid(nx, ny, cell)
    # The main plateau: a rounded rectangle; a headland runs out to the south-west, its tip a stack.
    body = 1.0 - (np.abs((X + 8.0) / 54.0) ** 3 + np.abs((Y - 14.0) / 42.0) ** 3) ** (2 / 3) \
        + noise(X.shape, 4, 9.0, 0.22)
    head = 1.0 - np.hypot((X + 42.0) / 12.0, (Y + 32.0) / 26.0) ** 2
    neck = 1.0 - np.abs((X + 36.0) / 3.2) ** 2 - 2.0 * (1.0 - smooth((Y + 58.0) / 3.0) * smooth((-38.0 - Y) / 3.0))
    stack = 1.0 - np.hypot((X + 34.0) / 8.0, (Y + 64.0) / 8.0) ** 2
    shape = np.maximum.reduce([body, head, neck, stack]) + noise(X.shape, 3, 6.0, 0.12)
    land = smooth(shape / 0.12)
    # A tilted chalk down cut by dry valleys (the cliff height rises and falls along the coast).
    top = 16.0 + 0.22 * (Y + 80.0) + 5.0 * np.sin(X / 15.0 + 0.3 * np.sin(Y / 20.0)) + noise(X.shape, 1, 12.0, 1.5)
    return -6.0 + (top + 6.0) * land + noise(X.shape, 2, 2.0, 0.4) * land, cell


#: The island's camera, and its sun from the left of the view: raking light makes the
#: face's flutes and notches cast shadows (with the sun behind the camera, azimuth -125
#: degrees, the face read as a flat grey wall).
ISLAND_CAMERA = {"origin": [-100.0, -100.0, 12.0], "target": [-34.0, -46.0, 9.0], "fov": 50.0}
ISLAND_SUN = {"elevation": 24.0, "azimuth": 170.0}


def coastal_cliff():
    """Fig. 23 (2019): chalk cliffs after three steps of sea erosion."""
    H, cell = island_dem()
    name = "fig23_coastal_cliff"
    doc, _ = amplified(name, H, cell, "sea", seed=11)
    glossy_water(doc)
    doc = finish(doc, name, "Fig. 23 (Paris et al. 2019): chalk cliffs after three steps of sea erosion: "
                 "notches, caves, a sea stack and an arch through the headland's neck",
                 ISLAND_CAMERA, ISLAND_SUN,
                 {"haze": {"density": 0.0015, "height": 25.0}}, max_depth=3)
    write(name, doc, "Gallery: Fig. 23 of Paris et al. 2019, coastal cliff (examples/make_gallery_scenes.py)")


def crop_dem(file, rows, cols, cell):
    """A crop of a DEM shipped in scenes/data (rows from the south), its lowest point at 0."""
    H = np.load(REPO / "scenes" / "data" / file, allow_pickle=False)[rows[0]:rows[1], cols[0]:cols[1]]
    return (H - H.min()).astype(np.float32), cell


def river_camera(H, cell, at=0.3, ahead=0.65, height=1.6, fov=55.0):
    """A camera low in the valley, looking down along it: the river is the DEM's lowest decile,
    ordered along its principal axis; the camera stands at fraction ``at`` of it,
    ``height / 4`` of the valley's relief above the bed, aiming at fraction ``ahead``."""
    ny, nx = H.shape
    X, Y = grid(nx, ny, cell)
    low = H < np.percentile(H, 4)
    pts = np.stack([X[low], Y[low], H[low]], axis=1)
    axis = np.linalg.svd(pts[:, :2] - pts[:, :2].mean(0))[2][0]
    order = np.argsort(pts[:, :2] @ axis)
    a, b = pts[order[int(at * (len(order) - 1))]], pts[order[int(ahead * (len(order) - 1))]]
    relief = float(np.percentile(H, 60) - a[2])
    origin = [float(a[0]), float(a[1]), float(a[2] + height * 0.25 * relief)]
    target = [float(b[0]), float(b[1]), float(b[2] + 0.22 * relief)]
    return {"origin": origin, "target": target, "fov": fov}


def canyon():
    """Fig. 23 (2019): a canyon with deep overhangs, the river carving undercut walls."""
    name = "fig23_canyon_overhangs"
    H, cell = crop_dem("eroded_canyon.npy", (250, 410), (220, 380), 10.0)
    doc, _ = amplified(name, H, cell, "river", seed=3)
    glossy_water(doc)
    camera = river_camera(H, cell, at=0.02, ahead=0.45, height=4.4, fov=60.0)  # from above the rim
    # A low afternoon sun over the camera's right shoulder lights the strata of both walls
    # and the haze thins with the 2 km view (0.0004 /m, against the light, washed the
    # canyon grey: a transmittance of 0.45 at the far rim, 0.74 now).
    doc = finish(doc, name, "Fig. 23 (Paris et al. 2019): a canyon whose river undercut its walls "
                 "into deep overhangs", camera, {"elevation": 25.0, "azimuth": -110.0},
                 {"haze": {"density": 0.00015, "height": 60.0}}, max_depth=3)
    write(name, doc, "Gallery: Fig. 23 of Paris et al. 2019, canyon with overhangs (examples/make_gallery_scenes.py)")


def goblins():
    """Fig. 23 (2019): goblins (hoodoos) along the banks of a river, in alternating hard and soft strata."""
    name = "fig23_goblins"
    H, cell = crop_dem("eroded_canyon.npy", (300, 400), (330, 430), 10.0)
    doc, _ = amplified(name, H, cell, "hoodoos", seed=23)
    glossy_water(doc)
    camera = river_camera(H, cell, at=0.05, ahead=0.5, height=3.0, fov=55.0)
    doc = finish(doc, name, "Fig. 23 (Paris et al. 2019): goblins weathered out of the soft strata "
                 "along a river's banks", camera, {"elevation": 28.0, "azimuth": 120.0},
                 {"haze": {"density": 0.0004, "height": 60.0}}, max_depth=3,
                 # Star-noise hoodoos: the costliest field of the gallery to march, and the
                 # one whose rays diverge most (wavefront -33 % at 160x90).
                 wavefront=True)
    write(name, doc, "Gallery: Fig. 23 of Paris et al. 2019, goblins (examples/make_gallery_scenes.py)")


def karst():
    """Fig. 17 (2019): sinkholes, tunnels and cave mouths in a mesa plateau, a few km across."""
    name = "fig17_karst"
    H, cell = crop_dem("eroded_mesas.npy", (40, 240), (60, 260), 15.0)
    # Refined 3x by cubic spline interpolation (it passes through the DEM's samples): the
    # implicit heightfield interpolates bilinearly, whose creases follow the cells, so a
    # cliff diagonal to 15 m cells came out as a staircase of 15 m steps.
    H, cell = zoom(H, 3, order=3).astype(np.float32), cell / 3
    doc, _ = amplified(name, H, cell, "karst", seed=17)
    # A bare limestone plateau: no snow on its top (the relief is over the 300 m that turns it on).
    doc["materials"]["landscape"]["overrides"]["snow.coverage"] = 0.0
    # An oblique aerial view over the plateau's south-western cliffs (lowest point at z = 0).
    camera = {"origin": [-1450.0, -1350.0, 480.0], "target": [-150.0, -100.0, 200.0], "fov": 50.0}
    doc = finish(doc, name, "Fig. 17 (Paris et al. 2019): karst tunnels opening as cave mouths "
                 "in the cliffs of a mesa plateau", camera, {"elevation": 30.0, "azimuth": -35.0},
                 {"haze": {"density": 0.0003, "height": 80.0}}, max_depth=3)
    write(name, doc, "Gallery: Fig. 17 of Paris et al. 2019, karst (examples/make_gallery_scenes.py)")


def cove_dem(cell=2.0, cliff_width=10.0):
    """A limestone plateau ending in a wavy sea cliff over a sand cove, a headland to the east
    (140 x 120 m; noise features in metres, whatever the cell).

    ``cliff_width`` is measured across the cliff line (not along y): the bilinear DEM lookup
    can only hold a cliff some cells wide. Narrower (6 m along y: ~3 m across the headland's
    oblique edge, ~5 m across the back cliff's), the rim stair-stepped on the 2 m cells into
    a regular sawtooth on the skyline; the blocks give the face its sharp detail."""
    nx, ny = int(round(140 / cell)) + 1, int(round(120 / cell)) + 1
    X, Y = grid(nx, ny, cell)
    # The cliff line wanders; behind it a plateau at ~22 m rising gently inland.
    edge = 6.0 + 6.0 * np.sin(X / 17.0) + 3.0 * np.sin(X / 7.3 + 1.0) + noise(X.shape, 21, 8.0 / cell, 1.2)
    edge = np.where(X > 35.0, edge - 1.6 * (X - 35.0), edge)  # the headland juts seaward
    across = (Y - edge) / np.sqrt(1.0 + np.gradient(edge, cell, axis=1) ** 2)  # distance from the line
    cliff = smooth(across / cliff_width)
    plateau = 21.0 + 0.06 * (Y - edge) + noise(X.shape, 22, 10.0 / cell, 1.3)
    # The cove floor: a beach rising from the sea (z < 0 south of y ~ -28) to the cliff foot.
    floor = -4.0 + 6.5 * smooth((Y + 46.0) / 36.0) + noise(X.shape, 23, 6.0 / cell, 0.25)
    return floor + (plateau - floor) * cliff + noise(X.shape, 24, 1.5 / cell, 0.15) * cliff, cell


def weathered_fin(scale, seed=33):
    """The 3-G-map window fin (``data/gmaps_arch/volume_0.ply``, the arch scenario's output:
    a fin of 2.4 x 0.8 x 2.5 m pierced by a window) weathered for the landscape: ``scale``
    (x, y, z) applied, subdivided to ~20 cm edges, its edges rounded by Taubin smoothing
    (which keeps the volume) and displaced along the normals by ~16 cm of smooth noise.
    The topology (one volume, genus one) is the G-map's. Written beside the source as
    ``volume_0.weathered.ply``; returns its path relative to the gallery folder."""
    import trimesh
    from scipy.ndimage import map_coordinates
    src = GALLERY / DATA / "gmaps_arch" / "volume_0.ply"
    mesh = trimesh.load(src, process=True)
    if np.ndim(scale) == 0:
        mesh.apply_scale(float(scale))
    else:
        mesh.apply_transform(np.diag([*map(float, scale), 1.0]))
    v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=0.2)
    mesh = trimesh.Trimesh(v, f, process=True)
    trimesh.smoothing.filter_taubin(mesh, lamb=0.5, nu=-0.53, iterations=60)
    # Smooth noise: a Gaussian-filtered random grid of 0.25 m cells over the mesh's box.
    lo, hi = mesh.bounds[0] - 1.0, mesh.bounds[1] + 1.0
    shape = np.ceil((hi - lo) / 0.25).astype(int) + 1
    rng = np.random.default_rng(seed)
    grid_ = gaussian_filter(rng.normal(size=shape), 2.0) + 0.3 * gaussian_filter(rng.normal(size=shape), 1.0)
    n = map_coordinates(grid_, ((mesh.vertices - lo) / 0.25).T, order=1)
    mesh.vertices = mesh.vertices + (0.16 * n / n.std())[:, None] * mesh.vertex_normals
    assert mesh.is_watertight and mesh.euler_number == 0  # one closed surface of genus one
    out = GALLERY / DATA / "gmaps_arch" / "volume_0.weathered.ply"
    mesh.export(out)
    return f"{DATA}/gmaps_arch/volume_0.weathered.ply"


def every_generator():
    """Item 5 of issue 15 (rebuilt for issue 33): one sea cove holding all five generators,
    each at a scale and in a place where it reads as itself."""
    name = "every_generator"
    H, cell = cove_dem()
    doc, _ = amplified(name, H, cell, "sea", seed=5)
    glossy_water(doc)
    nodes = doc["nodes"]
    terrain_root = doc["field"]["root"]
    # Implicit blocks (Paris et al. 2020) where the amplified terrain is steep: host = the terrain.
    # The host's field is a vertical distance, saturated at +-T beyond R metres of it (amplify
    # picks R = 2 F ~ 3.6 m, T = R / 2 from the coast's cliff): on a cliff of slope ~3 the band
    # where blocks can be anchored is a few metres across, about the face's depth of blocks of
    # ~2 m, so they cover the face; the joints open between them and the blocks stand out
    # of the face by up to half their size (no protrusion clip: on this host it cuts the
    # rim's blocks into teeth); ``region`` stops the blocks below the rim, where tall ones
    # stood above the plateau's edge like columns.
    nodes["cliff_blocks"] = {"type": "blocks", "host": terrain_root, "structure": "rhombohedral",
                             "tile_size": 16.0, "spacing": 1.8, "obliquity": 20.0, "joint_width": 0.2,
                             "smoothness": 0.3, "warp": 0.06, "warp_wavelength": 1.2,
                             "region": [-70.0, -20.0, 1.0, 70.0, 40.0, 18.0],
                             "distance_range": [-4.0, 3.5], "min_slope": 55.0, "seed": 3}
    # A layered sand deposit (Peytavie et al. 2009) on the cove: material stacks over the terrain,
    # sand dropped by the deposit brush and spread at its angle of repose.
    nodes["cove_sand"] = {"type": "layers", "source": "node", "node": terrain_root, "cell": 0.5,
                          "extent": [-60.0, -34.0, 40.0, 6.0], "z_range": [-5.0, 8.0],
                          "column": [{"material": "sand", "thickness": 0.3}, {"material": "bedrock"}],
                          "seed": 5,
                          "operations": [{"tool": "deposit", "center": [-36.0, -12.0], "radius": 9.0,
                                          "amount": 1.6},
                                         {"tool": "deposit", "center": [8.0, -10.0], "radius": 7.0,
                                          "amount": 1.2}]}
    nodes["coast"] = {"type": "union", "children": ["cliff_blocks", "cove_sand"]}
    doc["field"]["root"] = "coast"
    landscape = doc["materials"]["landscape"]
    # Grass on the plateau only (the amplified preset reaches down to the beach); sand where
    # the layered terrain holds sand, up to the cliff foot.
    landscape["overrides"].update({"grass.height_min": 12.0, "sand.height_max": 7.0, "sand.height_soft": 1.0,
                                   "sand.tint": [0.70, 0.62, 0.48]})
    landscape["masks"] = [
        {"layer": "sand", "node": {"type": "layers_ratio", "terrain": "cove_sand", "material": "sand",
                                   "sigma": 0.5}, "lo": 0.15, "hi": 0.5}]
    # A sea arch from the 3-G-map evolution (Bezin et al.): the window fin (2.4 x 0.8 x 2.5 m),
    # stretched into a stack 6 m wide and 11 m tall, weathered (edges rounded, surface rough)
    # and stood in the shallows in the cliff's limestone, its window an arch over the water.
    doc["materials"]["stack"] = {"type": "triplanar", "preset": "limestone",
                                 "overrides": {"rock.scale": 3.0, "bedding.scale": 4.0,
                                               "rock.tint": [0.42, 0.40, 0.36]}}
    doc["meshes"].append({"file": weathered_fin([2.6, 3.4, 4.4]), "material": "stack",
                          "translate": [-10.0, -30.0, -2.6],
                          "rotate": {"axis": [0.0, 0.0, 1.0], "angle": -40.0}})
    # Rock piles (Peytavie et al. 2009): a talus cone of fallen blocks leaning on the cliff foot,
    # and blocks fallen from the stack round its foot, awash.
    nodes["talus"] = {"type": "union", "children": [
        {"type": "scale", "factor": [10.0, 6.0, 5.5], "pivot": [-18.0, -1.0, 1.0],
         "child": {"type": "sphere", "center": [-18.0, -1.0, 1.0], "radius": 1.0}},
        {"type": "scale", "factor": [6.0, 5.0, 1.2], "pivot": [-10.0, -30.0, -0.8],
         "child": {"type": "sphere", "center": [-10.0, -30.0, -0.8], "radius": 1.0}}]}
    doc["rock_piles"] = [{"support": "talus", "rock_size": 1.3, "n": 4, "seed": 9, "g_max": 4.0,
                          "erosion": {"steps": 4, "rate": 0.5}, "preset": "limestone",
                          # The cliff's own stone, darker: fallen blocks are fresh and in shade.
                          "overrides": {"rock.scale": 2.0, "rock.tint": [0.36, 0.34, 0.31],
                                        "bedding.coverage": 0.0}}]
    doc = finish(doc, name, "One landscape, every generator: an amplified sea cliff (2019) fractured "
                 "into implicit blocks (2020), a talus of fallen rocks at its foot (2009), a layered "
                 "sand cove (2009) and a sea arch from a 3-G-map evolution",
                 {"origin": [-62.0, -36.0, 7.0], "target": [10.0, -6.0, 7.0], "fov": 55.0},
                 {"elevation": 35.0, "azimuth": -45.0},
                 {"haze": {"density": 0.001, "height": 20.0}}, spp=16, max_depth=3,
                 # Blocks, rocks and an arch over a cliff (wavefront -11 to -16 % at 160x90).
                 wavefront=True)
    # A flight for ``turntable --path``: from the sea to the cove floor, then up onto the plateau.
    # "orbit": the turntable's camera (turntable --camera orbit), high enough that the half turn
    # behind the cliff stays above the plateau (the main camera's orbit would pass through it).
    doc["cameras"] = {"orbit": {"origin": [-70.0, -62.0, 46.0], "target": [-4.0, 8.0, 9.0], "fov": 55.0},
                      "cove": {"origin": [-42.0, -30.0, 3.5], "target": [-18.0, 2.0, 7.0], "fov": 55.0},
                      "plateau": {"origin": [18.0, 34.0, 30.0], "target": [-24.0, -30.0, 4.0], "fov": 55.0}}
    doc["camera_path"] = {"fps": 24.0, "keys": [{"camera": "camera", "time": 0.0},
                                                {"camera": "cove", "time": 4.0},
                                                {"camera": "plateau", "time": 9.0}]}
    write(name, doc, "Gallery: every generator in one landscape, issue 15 item 5, rebuilt for issue 33 "
                     "(examples/make_gallery_scenes.py)")


def gorge_dem():
    """A sandstone plateau cut by a winding gorge 60 m deep, 400 m across (2 m cells)."""
    nx, ny, cell = 201, 201, 2.0
    X, Y = grid(nx, ny, cell)
    centre = 22.0 * np.sin(Y / 70.0) + noise(X.shape, 31, 20.0, 3.0)
    across = np.abs(X - centre)
    # Stepped walls: a ledge a third of the way up (the strata will carve the rest).
    walls = 0.55 * smooth((across - 9.0) / 10.0) + 0.45 * smooth((across - 20.0) / 8.0)
    plateau = 70.0 + 0.02 * Y + noise(X.shape, 32, 25.0, 2.5)
    return 6.0 + (plateau - 6.0) * walls + noise(X.shape, 33, 2.0, 0.3) * walls, cell


def arch_bridge():
    """Fig. 23 (2019): a large natural arch bridging a gorge, the river undercutting its walls."""
    name = "fig23_arch_bridge"
    H, cell = gorge_dem()
    doc, _ = amplified(name, H, cell, "river", seed=29)
    glossy_water(doc)
    nodes = doc["nodes"]
    # The bridge: a slab of the plateau left standing across the gorge, its opening an
    # ellipsoid (the span the river and the wind removed), weathered by fBm and filleted
    # into both rims. A heightfield cannot hold it: the sky shows under the span.
    nodes["bridge_slab"] = {"type": "box", "center": [0.0, 0.0, 51.0], "size": [96.0, 16.0, 42.0],
                            "rounding": 3.0}
    nodes["bridge_opening"] = {"type": "scale", "factor": [34.0, 40.0, 37.0], "pivot": [0.0, 0.0, 24.0],
                               "child": {"type": "sphere", "center": [0.0, 0.0, 24.0], "radius": 1.0}}
    nodes["bridge"] = {"type": "displace", "amplitude": 1.2, "wavelength": 9.0, "octaves": 3, "seed": 7,
                       "child": {"type": "difference", "children": ["bridge_slab", "bridge_opening"]}}
    nodes["gorge_with_arch"] = {"type": "blend", "radius": 4.0, "children": [doc["field"]["root"], "bridge"]}
    doc["field"]["root"] = "gorge_with_arch"
    doc = finish(doc, name, "Fig. 23 (Paris et al. 2019): a large natural arch bridging a sandstone gorge "
                 "whose river undercut the walls",
                 # From inside the gorge, below the rims, looking up its length at the span.
                 {"origin": [-21.0, -120.0, 36.0], "target": [0.0, 0.0, 52.0], "fov": 55.0},
                 {"elevation": 40.0, "azimuth": -20.0},
                 {"haze": {"density": 0.0008, "height": 60.0}}, spp=16, max_depth=3,
                 # The bridge blended into the gorge's walls (wavefront -24 % at 160x90).
                 wavefront=True)
    write(name, doc, "Gallery: Fig. 23 of Paris et al. 2019, arch bridge (examples/make_gallery_scenes.py)")


def island_top_dem():
    """A flat-topped island 240 m across: a plateau on a ragged outline, falling away outside it."""
    nx, ny, cell = 161, 161, 2.0
    X, Y = grid(nx, ny, cell)
    angle = np.arctan2(Y, X)
    outline = 100.0 + 14.0 * np.sin(3 * angle + 0.4) + 8.0 * np.sin(7 * angle + 1.3)
    r = np.hypot(X, Y) / outline
    top = 40.0 + 9.0 * (1.0 - np.clip(r, 0, 1) ** 2) + noise(X.shape, 41, 12.0, 2.0)
    # Outside the outline the ground drops 40 m within a few cells: the cliffs the strata erode.
    return (top * (1.0 - smooth((r - 0.96) / 0.08)) + noise(X.shape, 42, 2.0, 0.25)).astype(np.float32), cell


def floating_islands():
    """Fig. 21 (2019): floating islands: an implicitized heightfield with eroded strata, cut
    from below by a second heightfield (its rocky underside), and two smaller copies."""
    name = "fig21_floating_islands"
    H, cell = island_top_dem()
    doc, _ = amplified(name, H, cell, "strata", seed=21)
    nodes = doc["nodes"]
    ny, nx = H.shape
    X, Y = grid(nx, ny, cell)
    angle = np.arctan2(Y, X)
    outline = 100.0 + 14.0 * np.sin(3 * angle + 0.4) + 8.0 * np.sin(7 * angle + 1.3)
    r = np.clip(np.hypot(X, Y) / outline, 0.0, 1.2)
    # The underside: an inverted, craggy cone 70 m deep; at and beyond the rim it sits at the
    # rim's height (38 m), above the ground the cliffs fall to, so nothing outside remains.
    under = 38.0 - 70.0 * (1.0 - smooth(r / 1.0)) ** 0.8 \
        + (noise(X.shape, 43, 3.0, 5.0) + noise(X.shape, 44, 1.2, 1.5)) * (1.0 - smooth(r))
    # Padded 20 cells at the rim's height: the implicit terrain's prism reaches beyond its DEM.
    under = np.pad(under, 20, mode="edge")
    np.save(GALLERY / DATA / f"{name}.underside.npy", under.astype(np.float32))
    half = (nx - 1 + 40) * cell / 2
    nodes["underside"] = {"type": "heightfield", "source": "file", "file": f"{DATA}/{name}.underside.npy",
                          "extent": [-half, -half, half, half]}
    nodes["island"] = {"type": "difference", "children": [doc["field"]["root"], "underside"]}
    # Two smaller islands: the same construction tree, scaled and turned.
    nodes["island_b"] = {"type": "translate", "offset": [190.0, 110.0, 60.0],
                         "child": {"type": "rotate", "axis": [0.0, 0.0, 1.0], "angle": 120.0,
                                   "child": {"type": "scale", "factor": 0.55, "child": "island"}}}
    nodes["island_c"] = {"type": "translate", "offset": [-120.0, 190.0, -25.0],
                         "child": {"type": "rotate", "axis": [0.0, 0.0, 1.0], "angle": 230.0,
                                   "child": {"type": "scale", "factor": 0.4, "child": "island"}}}
    nodes["islands"] = {"type": "union", "children": ["island", "island_b", "island_c"]}
    doc["field"]["root"] = "islands"
    # The islands float 300 m over a hazy valley floor: the ground disk goes down, the far
    # field (a continuation of the island's DEM) is dropped.
    doc.pop("far_field", None)
    # A grassy valley floor (its own material: the island's wet band would darken it).
    doc["materials"]["valley"] = {"type": "triplanar", "preset": "terrain",
                                  "overrides": {"sand.coverage": 0.0, "snow.coverage": 0.0,
                                                "grass.height_min": -1000.0, "grass.height_max": 1000.0,
                                                "grass.slope_max": 60.0}}
    doc["meshes"] = [{"shape": "disk", "translate": [0.0, 0.0, -300.0], "scale": 60000.0, "material": "valley"}]
    doc["materials"].pop("water", None)
    doc["materials"]["landscape"].pop("wetness", None)
    (GALLERY / DATA / f"{name}.water.ply").unlink(missing_ok=True)
    doc = finish(doc, name, "Fig. 21 (Paris et al. 2019): floating islands, implicitized heightfields "
                 "with eroded strata and craggy undersides, over a hazy valley",
                 {"origin": [-250.0, -200.0, 75.0], "target": [30.0, 60.0, 15.0], "fov": 55.0},
                 {"elevation": 30.0, "azimuth": -60.0},
                 {"haze": {"density": 0.0012, "height": 120.0}}, spp=16, max_depth=3)
    write(name, doc, "Gallery: Fig. 21 of Paris et al. 2019, floating islands (examples/make_gallery_scenes.py)")


def sea_cliff_steps():
    """Fig. 11 (2019): sea cliffs after 1, 2 and 3 steps of sea erosion (a strip of three)."""
    H, cell = island_dem()
    for steps in (1, 2, 3):
        name = f"fig11_sea_cliffs_step{steps}"
        doc, _ = amplified(name, H, cell, "sea", seed=11, steps=steps)
        glossy_water(doc)
        doc = finish(doc, name, f"Fig. 11 (Paris et al. 2019): sea cliffs after {steps} step"
                     f"{'s' if steps > 1 else ''} of sea erosion",
                     ISLAND_CAMERA, ISLAND_SUN,
                     {"haze": {"density": 0.0015, "height": 25.0}}, max_depth=3)
        doc["render"]["resolution"] = [640, 360]
        write(name, doc, f"Gallery: Fig. 11 of Paris et al. 2019, sea erosion step {steps} "
                         "(examples/make_gallery_scenes.py)")


SCENES = {"every_generator": every_generator, "fig23_coastal_cliff": coastal_cliff,
          "fig23_canyon_overhangs": canyon, "fig23_goblins": goblins, "fig17_karst": karst,
          "fig23_arch_bridge": arch_bridge, "fig21_floating_islands": floating_islands,
          "fig11_sea_cliffs": sea_cliff_steps}


def main(names):
    for n in names or SCENES:
        SCENES[n]()


if __name__ == "__main__":
    main(sys.argv[1:])
