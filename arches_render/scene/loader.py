"""Scene files: TOML data validated into a :class:`SceneDescription`.

A scene file is data, never code. Top-level tables:

``[scene]``      ``name``, ``description``
``[render]``     ``resolution = [w, h]``, ``spp``, ``passes``, ``seed``, ``max_depth``,
                 ``rr_depth``, ``geometry = "field" | "mesh"``, ``voxel`` (mesh mode,
                 metres), ``exposure`` (preview stops; absent: metered from the
                 render, :mod:`arches_render.imaging.exposure`), ``view`` (the
                 preview's view transform, ``srgb`` default or ``aces``...),
                 ``denoise`` (add the OIDN-denoised layer, which the preview
                 shows; default false), ``eps`` (relative hit
                 tolerance, default 2e-4: well below a pixel, since a tolerance
                 near a pixel inflates every silhouette), ``omega``, ``max_steps``
                 (sphere-tracing steps of a ray's first pass, default 512; a ray
                 that uses them up gets a second pass of ``16 max_steps``, see
                 :mod:`arches_render.render.march`), ``surface_cells`` (trace
                 through the surface cells of :mod:`arches_render.render.cell_tracer`:
                 empty space jumped over, rock seen ahead by shadow rays; default
                 false), ``sun_columns`` (shadow rays towards the sun end where a
                 map in its frame proves the rest free,
                 :mod:`arches_render.render.sun_columns`; default false), ``wavefront``
                 (paths traced depth by depth, field queries by persistent lanes:
                 :mod:`arches_render.render.wavefront`; the same picture, faster on
                 costly fields, slower on cheap ones; default false), ``lod``
                 (footprint level of detail: octaves finer than a ray's cone skipped, :mod:`arches_render.field.lod`; default true;
                 false renders full detail, e.g. a heavily displaced rim against
                 the sky, whose coverage level of detail thins)
``[camera]``     ``origin``, ``target``, ``up`` (default +Z), ``fov`` (degrees, horizontal)
``[cameras.NAME]`` named cameras with the keys of ``[camera]`` (``SceneDescription.cameras``,
                 in file order after ``[camera]``, which is named ``"camera"``); a
                 scene needs ``[camera]`` or at least one named camera; the first
                 is ``desc.camera`` unless ``select_camera`` picks another
                 (``render``/``turntable --camera NAME``)
``[camera_path]`` ``keys = [{camera, time}]`` (two or more named cameras, times in
                 seconds strictly increasing) and ``fps`` (default 24): a C¹ flight
                 through the cameras (:mod:`arches_render.render.camera_path`),
                 rendered by ``turntable --path``
``[[lights]]``   ``type`` = ``sunsky`` | ``directional`` | ``point`` | ``constant`` | ``envmap``
``[materials.NAME]`` ``type = "triplanar"`` with ``preset``, ``overrides``, ``tiling`` (every
                 layer's: ``histogram``, ``bands`` or ``repeat``; default: each layer's
                 preset tiling, histogram or bands),
                 ``masks = [{layer, [kind], node, lo, hi}]`` (a layer's coverage times
                 ``smoothstep(lo, hi, m)``, ``m`` a field or noise node's value, the
                 cavity or the wetness) and the lookdev keys ``detail``, ``strata``,
                 ``cavity``, ``wetness`` (:mod:`arches_render.scene.material_keys`;
                 ``detail = false`` drops the preset's detail layer),
                 ``type = "diffuse"`` with ``color``, or ``type = "glossy"`` with
                 ``color``, ``roughness`` (GGX alpha, default 0.05) and ``ior`` (1.333,
                 water): a diffuse base under a dielectric coating (Mitsuba's
                 ``roughplastic``), for water and wet surfaces that mirror the sky
``[[meshes]]``   ``file`` (PLY/OBJ) or ``shape`` (rectangle, disk, sphere, cube), a
                 transform (``translate``, ``rotate = {axis, angle}``, ``scale``), ``material``
``[field]``      ``root`` (node name or inline table), ``material``
``[[NAME]]``     the top-level tables of the generators (``SCENE_TABLES`` in the
                 registry, :mod:`arches_render.extensions`), e.g. ``[[rock_piles]]``
                 of :mod:`arches_render.generators.rocks.scene_piles`; the parsed
                 items are ``SceneDescription.tables[NAME]`` (also ``desc.NAME``)
``[nodes.NAME]`` field nodes (see :mod:`arches_render.scene.nodes`)
``[atmosphere]`` aerial perspective (absent: none; math in
                 :mod:`arches_render.render.atmosphere`): ``turbidity`` (aerosol
                 density, [1, 10], default the first ``sunsky`` light's, else 3),
                 ``density`` (multiplier on all extinction, >= 0, default 1),
                 ``ground`` (height in metres below which the density is constant,
                 default 0), ``rayleigh_height`` (8000) and ``aerosol_height``
                 (1200, scale heights in metres, > 0), ``anisotropy`` (aerosol
                 Henyey-Greenstein g in (-1, 1), 0.76), ``aerosol_albedo`` ([0, 1],
                 0.9), ``ground_albedo`` (of the ground that lights the air from
                 below, [0, 1], default the ``sunsky`` albedo, else 0.3) and an optional
                 low haze layer ``haze = {density, height}`` (extinction at
                 ``ground`` in 1/m, > 0, and scale height in metres, > 0, default 20).
                 With a sky light (``sunsky``, ``constant``, ``envmap``) the haze
                 fades to the sky, and ``anisotropy``, ``aerosol_albedo`` and
                 ``ground_albedo`` (single scattering's) have no effect

Paths are relative to the scene file. Errors name the file, the key path and the
allowed range (:class:`~arches_render.scene.errors.SceneError`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field as dc_field
from pathlib import Path

import mitsuba as mi

from .. import extensions, tomlfile
from ..backend import variant
from ..field.node import finite_box
from ..imaging.colour import VIEWS
from ..materials import presets
from .errors import SceneError
from .material_keys import parse_look, parse_masks
from ..materials.textures import TILINGS
from .mesh_files import read_mesh
from .nodes import NodeBuilder
from .paths import scene_file
from .texture_files import check_texture, layer_textures
from .validate import Table

#: Light types that are Mitsuba environment emitters (a scene may hold one).
ENVIRONMENT_LIGHTS = ("sunsky", "constant", "envmap")
GEOMETRY_MODES = ("field", "mesh")


@dataclass
class RenderSettings:
    width: int = 320
    height: int = 180
    spp: int = 16
    passes: int = 0            # 0: choose from spp
    seed: int = 0
    max_depth: int = 6
    rr_depth: int = 5
    geometry: str = "field"
    voxel: float = 0.0         # 0: choose from the field's bounds
    exposure: float | None = None   # None: metered
    view: str = "srgb"
    denoise: bool = False
    eps: float = 2e-4
    omega: float = 1.6
    max_steps: int = 512
    surface_cells: bool = False
    sun_columns: bool = False
    wavefront: bool = False
    lod: bool = True


@dataclass
class AtmosphereSettings:
    """The ``[atmosphere]`` table (see the module docstring and :mod:`arches_render.render.atmosphere`)."""

    turbidity: float = 3.0
    density: float = 1.0
    ground: float = 0.0
    rayleigh_height: float = 8000.0
    aerosol_height: float = 1200.0
    anisotropy: float = 0.76
    aerosol_albedo: float = 0.9
    ground_albedo: float = 0.3
    haze_density: float = 0.0   # 0: no haze layer
    haze_height: float = 20.0


@dataclass
class Camera:
    origin: list
    target: list
    up: list
    fov: float


@dataclass
class CameraPath:
    """The ``[camera_path]`` table: ``keys`` are ``(time, camera name)``, times increasing."""

    keys: list
    fps: float = 24.0


@dataclass
class SceneDescription:
    """A validated scene: plain data plus the built field tree."""

    file: Path
    name: str
    description: str
    render: RenderSettings
    camera: Camera                                      # the selected camera (default: the first)
    cameras: dict = dc_field(default_factory=dict)      # name -> Camera, in file order
    lights: list = dc_field(default_factory=list)       # Mitsuba emitter dicts
    materials: dict = dc_field(default_factory=dict)    # name -> Mitsuba BSDF dict
    material_masks: dict = dc_field(default_factory=dict)  # name -> [(layer, node, lo, hi, kind)]
    material_nodes: dict = dc_field(default_factory=dict)  # name -> {role: node} (material_keys)
    meshes: list = dc_field(default_factory=list)       # Mitsuba shape dicts
    field: object = None                                # root Node or None
    field_material: str | None = None
    tables: dict = dc_field(default_factory=dict)       # generators' [[NAME]] -> parsed items
    atmosphere: AtmosphereSettings | None = None
    camera_path: CameraPath | None = None

    def select_camera(self, name: str | None) -> Camera:
        """Make camera ``name`` (``None``: keep the current one) the scene's camera and return it.

        Raises
        ------
        SceneError
            For an unknown name (the message lists the scene's cameras).
        """
        if name is not None:
            if name not in self.cameras:
                raise SceneError(self.file, "cameras", f"has no camera {name!r} "
                                                       f"(cameras: {', '.join(self.cameras)})")
            self.camera = self.cameras[name]
        return self.camera

    def __getattr__(self, name):
        # A generator's scene table reads as an attribute: desc.rock_piles.
        tables = self.__dict__.get("tables", {})
        if name in tables:
            return tables[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")


def _camera(c: Table) -> Camera:
    camera = Camera(origin=c.vector("origin"), target=c.vector("target"),
                    up=c.vector("up", default=[0.0, 0.0, 1.0], nonzero=True),
                    fov=c.number("fov", 40.0, lo=0, hi=180, lo_open=True, hi_open=True))
    if camera.origin == camera.target:
        raise c.error("target", f"must differ from {c.path}.origin")
    c.finish()
    return camera


def _cameras(root: Table) -> dict:
    """``[camera]`` (named ``"camera"``) first, then the ``[cameras.NAME]`` in file order."""
    cameras = {}
    if root.has("camera") or not root.has("cameras"):
        cameras["camera"] = _camera(root.table("camera"))
    named = root.table("cameras", None)
    if named is not None:
        for name in list(named.data):
            if name in cameras:
                raise named.error(name, "is the name of the [camera] table: choose another")
            cameras[name] = _camera(named.table(name))
        named.finish()
        if not cameras:
            raise root.error("cameras", "holds no camera (add [cameras.NAME] with origin and target)")
    return cameras


def _camera_path(t: Table, cameras: dict) -> CameraPath:
    """Validate ``[camera_path]`` against the scene's cameras (see the module docstring)."""
    fps = t.number("fps", 24.0, lo=0, hi=1000, lo_open=True)
    raw = t.raw("keys")
    if not isinstance(raw, list) or len(raw) < 2 or not all(isinstance(k, dict) for k in raw):
        raise t.error("keys", "must be a list of two or more {camera, time} tables")
    keys = []
    for i, item in enumerate(raw):
        k = Table(item, t.file, f"{t.key('keys')}[{i}]")
        name = k.string("camera")
        if name not in cameras:
            raise k.error("camera", f"names no camera (cameras: {', '.join(cameras)}; got {name!r})")
        time = k.number("time", lo=-1e6, hi=1e6)
        if keys and time <= keys[-1][0]:
            raise k.error("time", f"must be greater than the previous key's time {keys[-1][0]:g} "
                                  f"(times strictly increase; got {time:g})")
        k.finish()
        keys.append((time, name))
    t.finish()
    return CameraPath(keys=keys, fps=fps)


def _sun_direction(t: Table):
    """Direction *towards* the sun from elevation/azimuth (degrees; azimuth from +X to +Y)."""
    el = math.radians(t.number("elevation", lo=-10, hi=90))
    az = math.radians(t.number("azimuth", 0.0, lo=-360, hi=360))
    return [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]


def _rgb(t: Table, name, default):
    v = t.raw(name, default)
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return {"type": "rgb", "value": [float(t.number(name, default, lo=0))] * 3}
    return {"type": "rgb", "value": t.vector(name, 3, default=default, lo=0)}


def _light(t: Table, base_dir: Path) -> dict:
    kind = t.string("type", choices={"sunsky", "directional", "point", "constant", "envmap"})
    if kind == "sunsky":
        d = {"type": "sunsky", "sun_direction": _sun_direction(t),
             "turbidity": t.number("turbidity", 3.0, lo=1.0, hi=10.0),
             "sun_scale": t.number("sun_scale", 1.0, lo=0.0),
             "sky_scale": t.number("sky_scale", 1.0, lo=0.0),
             "albedo": t.number("ground_albedo", 0.3, lo=0.0, hi=1.0)}
    elif kind == "directional":
        direction = (t.vector("direction", nonzero=True) if t.has("direction")
                     else [-c for c in _sun_direction(t)])
        d = {"type": "directional", "direction": direction,
             "irradiance": _rgb(t, "irradiance", 1.0)}
    elif kind == "point":
        d = {"type": "point", "position": t.vector("position"), "intensity": _rgb(t, "intensity", 1.0)}
    elif kind == "constant":
        d = {"type": "constant", "radiance": _rgb(t, "radiance", 1.0)}
    else:
        path = scene_file(t, "file", base_dir=base_dir, what="environment map")
        check_texture(path, t, "file", colour=True)
        # Mitsuba's envmaps are Y-up; our world is Z-up.
        d = {"type": "envmap", "filename": str(path), "scale": t.number("scale", 1.0, lo=0.0),
             "to_world": mi.ScalarTransform4f().rotate([0, 0, 1], t.number("rotation", 0.0))
             @ mi.ScalarTransform4f().rotate([1, 0, 0], 90.0)}
    t.finish()
    return d


def _atmosphere(t: Table, lights: list) -> AtmosphereSettings:
    """Validate ``[atmosphere]``; turbidity and ground albedo default to the first sunsky's."""
    sky = next((d for d in lights if d["type"] == "sunsky"), None)
    a = AtmosphereSettings(
        turbidity=t.number("turbidity", sky["turbidity"] if sky else 3.0, lo=1.0, hi=10.0),
        density=t.number("density", 1.0, lo=0.0),
        ground=t.number("ground", 0.0),
        rayleigh_height=t.number("rayleigh_height", 8000.0, lo=0.0, lo_open=True),
        aerosol_height=t.number("aerosol_height", 1200.0, lo=0.0, lo_open=True),
        anisotropy=t.number("anisotropy", 0.76, lo=-1.0, hi=1.0, lo_open=True, hi_open=True),
        aerosol_albedo=t.number("aerosol_albedo", 0.9, lo=0.0, hi=1.0),
        ground_albedo=t.number("ground_albedo", sky["albedo"] if sky else 0.3, lo=0.0, hi=1.0))
    haze = t.table("haze", None)
    if haze is not None:
        a.haze_density = haze.number("density", lo=0.0, lo_open=True)
        a.haze_height = haze.number("height", 20.0, lo=0.0, lo_open=True)
        haze.finish()
    t.finish()
    return a


def _material(t: Table, builder) -> tuple[dict, list, dict]:
    kind = t.string("type", "triplanar", choices={"triplanar", "diffuse", "glossy"})
    masks, nodes = [], {}
    if kind == "diffuse":
        d = {"type": "diffuse", "reflectance": _rgb(t, "color", [0.5, 0.5, 0.5])}
    elif kind == "glossy":
        d = {"type": "roughplastic", "diffuse_reflectance": _rgb(t, "color", [0.02, 0.05, 0.06]),
             "alpha": t.number("roughness", 0.05, lo=0.001, hi=1.0),
             "int_ior": t.number("ior", 1.333, lo=1.0, hi=3.0), "distribution": "ggx"}
    else:
        name = t.string("preset", "terrain")
        over = t.raw("overrides", {})
        if not isinstance(over, dict):
            raise t.error("overrides", "must be a table")
        try:
            over = layer_textures(t, name, over, builder.base_dir)
            d = presets.preset_dict(name, over)
            layers, _ = presets.preset_layers(name, over)
        except SceneError:
            raise
        except ValueError as exc:
            raise t.error("overrides" if over else "preset", str(exc)) from None
        names = [layer.name for layer in layers]
        # Every layer's tiling at once (a layer's own override wins); without it each layer
        # keeps its preset's tiling (histogram, or bands for banded textures).
        tiling = t.string("tiling", None, choices=set(TILINGS))
        for i, layer in enumerate(layers):
            if tiling is not None and f"{layer.name}.tiling" not in over:
                d[f"layer{i}_tiling"] = tiling
        nodes = parse_look(t, builder, names, d)
        masks = parse_masks(t, builder, names, d)
    t.finish()
    return d, masks, nodes


def _mesh(t: Table, base_dir: Path, materials: dict) -> dict:
    if t.has("file"):
        path = scene_file(t, "file", (".ply", ".obj"), base_dir, what="mesh")
        read_mesh(path, t, "file")  # Mitsuba reads it again: refuse here what it would fail on
        d = {"type": path.suffix.lower()[1:], "filename": str(path)}
    else:
        d = {"type": t.string("shape", choices={"rectangle", "disk", "sphere", "cube"})}
    xf = mi.ScalarTransform4f().translate(t.vector("translate", default=[0, 0, 0]))
    rot = t.table("rotate", None)
    if rot is not None:
        xf = xf @ mi.ScalarTransform4f().rotate(rot.vector("axis", nonzero=True), rot.number("angle"))
        rot.finish()
    s = t.raw("scale", 1.0)
    if isinstance(s, list):
        xf = xf @ mi.ScalarTransform4f().scale(t.vector("scale", lo=1e-9))
    else:
        xf = xf @ mi.ScalarTransform4f().scale(t.number("scale", 1.0, lo=0, lo_open=True))
    d["to_world"] = xf
    mat = t.string("material", "default")
    if mat not in materials:
        raise t.error("material", f"unknown material '{mat}' (defined: {', '.join(sorted(materials))})")
    d["bsdf"] = {"type": "ref", "id": mat}
    t.finish()
    return d


def read_toml(path) -> dict:
    """The TOML data of a scene file, unvalidated.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict

    Raises
    ------
    SceneError
        ``no such scene file``, ``not valid TOML: ...`` or ``cannot read: ...``.
    """
    path = Path(path)
    try:
        return tomlfile.load(path)
    except FileNotFoundError:
        raise SceneError(path, "", "no such scene file") from None
    except tomlfile.TOMLDecodeError as exc:
        raise SceneError(path, "", f"not valid TOML: {exc}") from None
    except RecursionError:  # tomllib recurses once per level of inline tables and arrays
        raise SceneError(path, "", "not valid TOML: inline tables or arrays nested too deeply") from None
    except OSError as exc:
        raise SceneError(path, "", f"cannot read: {exc.strerror}") from None


def load_scene(path) -> SceneDescription:
    """Read and validate a scene file.

    Parameters
    ----------
    path : str or Path
        The ``.toml`` scene.

    Returns
    -------
    SceneDescription

    Raises
    ------
    SceneError
        On unreadable files or invalid values (message names file, key, range).
    """
    return parse_scene(read_toml(path), path)


def parse_scene(data: dict, path) -> SceneDescription:
    """Validate already-parsed TOML data (see :func:`load_scene`)."""
    # A scene holds Mitsuba values (mesh transforms) before any field node is built, and a
    # node would select the variant only then: select it first (a script that loads a
    # scene with meshes before anything else failed here).
    variant()
    path = Path(path)
    base_dir = path.parent
    root = Table(data, path)

    meta = root.table("scene", {})
    name = meta.string("name", path.stem)
    description = meta.string("description", "")
    meta.finish()

    r = root.table("render", {})
    res = r.raw("resolution", [320, 180])
    if (not isinstance(res, list) or len(res) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 16384 for v in res)):
        raise r.error("resolution", f"must be [width, height] with integers in [1, 16384] (got {res!r})")
    settings = RenderSettings(
        width=res[0], height=res[1],
        spp=r.integer("spp", 16, lo=1, hi=1 << 20),
        passes=r.integer("passes", 0, lo=0, hi=4096),
        seed=r.integer("seed", 0, lo=0, hi=2 ** 31 - 1),
        max_depth=r.integer("max_depth", 6, lo=-1, hi=1024),
        rr_depth=r.integer("rr_depth", 5, lo=1, hi=1024),
        geometry=r.string("geometry", "field", choices=set(GEOMETRY_MODES)),
        voxel=r.number("voxel", 0.0, lo=0.0),
        exposure=r.number("exposure", None, lo=-20, hi=20),
        view=r.string("view", "srgb", choices=set(VIEWS)),
        denoise=r.boolean("denoise", False),
        eps=r.number("eps", 2e-4, lo=1e-7, hi=1e-2),
        omega=r.number("omega", 1.6, lo=1.0, hi=1.95),
        max_steps=r.integer("max_steps", 512, lo=16, hi=1 << 16),
        surface_cells=r.boolean("surface_cells", False),
        sun_columns=r.boolean("sun_columns", False),
        wavefront=r.boolean("wavefront", False),
        lod=r.boolean("lod", True))
    if settings.max_depth == 0:
        raise r.error("max_depth", "must be -1 (unbounded) or an integer in [1, 1024] (got 0)")
    r.finish()

    cameras = _cameras(root)
    camera = next(iter(cameras.values()))
    cp = root.table("camera_path", None)
    camera_path = _camera_path(cp, cameras) if cp is not None else None

    lights = [_light(t, base_dir) for t in root.tables("lights")]
    if not lights:
        raise root.error("lights", "at least one light is required ([[lights]] with type = sunsky, ...)")
    environments = [d["type"] for d in lights if d["type"] in ENVIRONMENT_LIGHTS]
    if len(environments) > 1:  # Mitsuba's scene holds one environment emitter
        raise root.error("lights", f"at most one of {', '.join(ENVIRONMENT_LIGHTS)} may be given "
                                   f"(got {', '.join(environments)}); add directional or point lights instead")

    at = root.table("atmosphere", None)
    atmosphere = _atmosphere(at, lights) if at is not None else None

    nodes_tbl = root.raw("nodes", {})
    if not isinstance(nodes_tbl, dict):
        raise root.error("nodes", "must be a table of named node tables")
    builder = NodeBuilder(nodes_tbl, path, base_dir)

    mats = root.table("materials", {})
    materials = {"default": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5] * 3}}}
    material_masks, material_nodes = {}, {}
    for mname in list(mats.data):
        materials[mname], masks, mnodes = _material(mats.table(mname), builder)
        if masks:
            material_masks[mname] = masks
        if mnodes:
            material_nodes[mname] = mnodes
    mats.finish()

    meshes = [_mesh(t, base_dir, materials) for t in root.tables("meshes")]

    field_node, field_material = None, None
    ft = root.table("field", None)
    if ft is not None:
        field_node = builder.build(ft.raw("root"), ft, "root")
        field_material = ft.string("material", "default")
        if field_material not in materials:
            raise ft.error("material", f"unknown material '{field_material}' "
                                       f"(defined: {', '.join(sorted(materials))})")
        if finite_box(field_node) is None:
            raise ft.error("root", "the field is unbounded (a plane or noise at the root): "
                                   "intersect it with a box")
        ft.finish()
    tables = {table: [parse(t, builder, field_node, materials, path, i)
                      for i, t in enumerate(root.tables(table))]
              for table, parse in extensions.scene_tables().items()}
    unused = sorted(set(nodes_tbl) - set(builder.built))
    if unused:
        raise SceneError(path, f"nodes.{unused[0]}", "is defined but used by neither field.root "
                                                     "nor a material mask")
    if field_node is None and not meshes and not any(tables.values()):
        kinds = ["[field]", "[[meshes]]"] + [f"[[{table}]]" for table in tables]
        raise root.error("field", f"the scene has no geometry: add {', '.join(kinds[:-1])} or {kinds[-1]}")
    root.finish()
    return SceneDescription(file=path, name=name, description=description, render=settings,
                            camera=camera, cameras=cameras, lights=lights, materials=materials,
                            material_masks=material_masks, material_nodes=material_nodes, meshes=meshes,
                            field=field_node, field_material=field_material, tables=tables,
                            atmosphere=atmosphere, camera_path=camera_path)
