"""The lookdev Python API: load a scene file, override parameters, render, compare.

A lookdev session::

    from arches_render import api
    look = api.load("scenes/default.toml", resolution=(320, 180), spp=16)
    before = look.render()                                   # numpy (H, W, 3), linear
    look.set("materials.landscape.snow.height_min", 12.0)   # a triplanar layer value
    look.set("lights.0.elevation", 15.0)                    # the sun
    look.set("camera.origin", [-60.0, -80.0, 30.0])
    look.set("nodes.arch_core.radius", 2.0)                 # a field parameter
    after = look.render("out/look.exr")                     # also writes EXR + PNG
    print(api.compare(before, after).summary())

Keys are dotted paths into the scene file's TOML (``camera.fov``,
``lights.0.turbidity``, ``nodes.NAME.KEY``, ``materials.NAME.color``), and for
triplanar materials ``materials.NAME.LAYER.FIELD`` (a preset override, e.g.
``snow.height_min``, ``rock.tint``). Every edit is validated like the scene file
itself (errors name the key and range) and applied to the live Mitsuba scene as a
*parameter edit* where the value is held in a Dr.Jit array: camera (``to_world``,
``x_fov``), emitter parameters (sun direction, turbidity, scales), triplanar layer
values and mask ranges, and the field tree (rebuilt from the edited tables and
re-attached: opaque parameters such as radii, centres, and the tracer's box keep
the kernel's code). Such edits compile nothing; :attr:`Lookdev.compiled` counts the
kernels the last render compiled, to check. Values that the kernels hold as
constants (noise octaves, Lipschitz bounds of a changed amplitude, a new node
type, a texture, render settings) change the code: the scene is rebuilt or the
kernel recompiled, and the result is still right.

References
----------
Jakob, W. et al. (2022). Mitsuba 3 renderer, ``mi.traverse`` / ``SceneParameters``.
"""

from __future__ import annotations

import copy
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from . import notebook
from .backend import set_variant
from .imaging.colour import view_to_uint8
from .imaging.exposure import exposure_of
from .imaging.compare import Thresholds, compare as _compare
from .imaging.exr import read_exr
from .imaging.preview import write_png
from .render.jobs import sensor_clip, set_camera
from .render.output import render_header, write_render
from .materials.triplanar import STRUCTURAL
from .render.renderer import attach_atmosphere, attach_material_nodes, build_scene, load_materials, render_layers
from .scene import parse_scene, read_toml

__all__ = ["Lookdev", "load", "compare"]


def _fog_shape(desc):
    """What of a scene's ``[atmosphere]`` shapes the kernels: on or off, haze layer or not."""
    a = desc.atmosphere
    return None if a is None else a.haze_density > 0


def load(path, resolution=None, spp=None, seed=None) -> "Lookdev":
    """Open a scene file for lookdev.

    Parameters
    ----------
    path : str or Path
        Scene file (``.toml``).
    resolution : (int, int), optional
        ``(width, height)`` overriding ``render.resolution``.
    spp, seed : int, optional
        Defaults of :meth:`Lookdev.render` (else the scene's).

    Returns
    -------
    Lookdev

    Raises
    ------
    arches_render.scene.SceneError
        For an unreadable or invalid scene file.
    """
    return Lookdev(path, resolution, spp, seed)


def compare(ref, test, thresholds=None):
    """Compare two renders (arrays or EXR paths) with the golden-image metrics.

    Parameters
    ----------
    ref, test : numpy.ndarray or str or Path
        ``(H, W, 3)`` linear images, or EXR files (their beauty).
    thresholds : arches_render.imaging.compare.Thresholds, optional
        Limits (default: mean shift 1 %, worst 8x8 window 5 %, mean FLIP 0.05:
        "the same look" for renders of a few hundred spp). Golden tests, which
        know each pixel's variance, use :mod:`arches_render.imaging.welch`.

    Returns
    -------
    arches_render.imaging.compare.CompareResult
        Mean shift, tile errors, FLIP, ... and ``passed``.

    References
    ----------
    :func:`arches_render.imaging.compare.compare`.
    """
    ref, test = (read_exr(x).rgb if isinstance(x, (str, Path)) else np.asarray(x, np.float32)
                 for x in (ref, test))
    return _compare(ref, test, thresholds or Thresholds(tile=0.05, flip=0.05))


class Lookdev:
    """A scene file loaded for interactive edits and renders (see module docstring).

    Attributes
    ----------
    path : pathlib.Path
        The scene file.
    data : dict
        The (edited) TOML tables.
    desc : SceneDescription
        The validated scene of :attr:`data`.
    scene : mi.Scene
        The live Mitsuba scene.
    compiled : int
        Kernels compiled by the last :meth:`render` (0 when every edit was a
        parameter edit and the kernels were compiled before).
    rebuilds : int
        Times the Mitsuba scene was built (1 after :func:`load`).
    last : numpy.ndarray or None
        The last :meth:`render` (what a notebook shows of the look).
    last_layers : dict
        Its AOV layers (``{layer: (array, channel letters)}``; empty without ``aovs``).
    camera_name : str or None
        The camera rendered through (:meth:`use_camera`; ``None``: the scene's default).
    """

    def __init__(self, path, resolution=None, spp=None, seed=None):
        set_variant()
        self.path = Path(path)
        self.data = read_toml(self.path)
        self._parse = parse_scene
        self.desc = parse_scene(copy.deepcopy(self.data), self.path)
        self.width, self.height = resolution or (self.desc.render.width, self.desc.render.height)
        self.spp, self.seed = spp, seed
        self.camera_name = None
        self.compiled = 0
        self.rebuilds = 0
        self.last = None
        self.last_layers = {}
        self._build()

    # ------------------------------------------------------------------ building
    def _build(self):
        self.bsdfs = load_materials(self.desc)
        self.scene = build_scene(self.desc, "field", self.width, self.height, bsdfs=self.bsdfs)
        self.rebuilds += 1

    # ------------------------------------------------------------------ edits
    def get(self, key: str):
        """Current value of a dotted key (see :meth:`set`)."""
        node, last = self._locate(self.data, key, create=False)
        return copy.deepcopy(node[last])

    def set(self, key: str, value) -> "Lookdev":
        """Override one parameter and apply it to the live scene.

        Parameters
        ----------
        key : str
            Dotted path: ``camera.origin``, ``lights.0.elevation``,
            ``nodes.NAME.KEY``, ``materials.NAME.KEY``, or
            ``materials.NAME.LAYER.FIELD`` for a triplanar preset override.
        value : object
            The new value (TOML types: numbers, strings, lists).

        Returns
        -------
        Lookdev
            ``self`` (edits chain).

        Raises
        ------
        arches_render.scene.SceneError
            When the edited scene is invalid (nothing is changed then).
        KeyError
            For a path into a table that does not exist.
        """
        return self.update({key: value})

    def update(self, overrides: dict) -> "Lookdev":
        """Apply several overrides at once (see :meth:`set`)."""
        return self._replace(self.data, overrides)

    def reload(self, overrides: dict | None = None) -> "Lookdev":
        """Read the scene file again (an edit saved by the user) and apply it to the live
        scene, then ``overrides`` (dotted keys, as :meth:`update`) on top: the parameter
        edits of :meth:`set` where the change allows them.

        Raises
        ------
        arches_render.scene.SceneError
            When the file no longer reads or validates (nothing is changed then).
        """
        return self._replace(read_toml(self.path), overrides or {})

    def use_camera(self, name: str | None) -> "Lookdev":
        """Render through the scene's camera ``name`` (``"camera"`` for ``[camera]``, else a
        ``[cameras.NAME]``); ``None``: the scene's default. A parameter edit.

        Raises
        ------
        arches_render.scene.SceneError
            For a name the scene does not have (the message lists its cameras).
        """
        desc = copy.copy(self.desc)  # (the same tables and field: only the camera changes)
        desc.select_camera(name)
        old, self.desc, self.camera_name = self.desc, desc, name
        self._apply(old, desc)
        return self

    def _replace(self, data: dict, overrides: dict) -> "Lookdev":
        data = copy.deepcopy(data)
        for key, value in overrides.items():
            node, last = self._locate(data, key, create=True)
            node[last] = copy.deepcopy(value)
        desc = self._parse(copy.deepcopy(data), self.path)  # validates: raises before any change
        if self.camera_name in desc.cameras:
            desc.select_camera(self.camera_name)
        old, self.data = self.desc, data
        self.desc = desc
        self._apply(old, desc)
        return self

    def _locate(self, data: dict, key: str, create: bool):
        parts = key.split(".")
        if len(parts) < 2:
            raise KeyError(f"lookdev key {key!r} must be a dotted path such as 'camera.fov'")
        # materials.NAME.LAYER.FIELD -> the preset override 'LAYER.FIELD'
        if parts[0] == "materials" and len(parts) == 4:
            mat = data.get("materials", {}).get(parts[1])
            if mat is None:
                raise KeyError(f"lookdev key {key!r}: no material {parts[1]!r}")
            return mat.setdefault("overrides", {}), f"{parts[2]}.{parts[3]}"
        node = data
        for part in parts[:-1]:
            if isinstance(node, list):
                try:
                    node = node[int(part)]
                except (ValueError, IndexError):
                    raise KeyError(f"lookdev key {key!r}: no item {part!r}") from None
            elif isinstance(node, dict) and part in node:
                node = node[part]
            else:
                raise KeyError(f"lookdev key {key!r}: no table {part!r}")
        if not create and parts[-1] not in node:
            raise KeyError(f"lookdev key {key!r} is not set in the scene")
        return node, parts[-1]

    def _apply(self, old, new):
        """Bring the live scene from ``old`` to ``new`` with parameter edits where possible."""
        same = (old.render == new.render and old.meshes == new.meshes
                and [l["type"] for l in old.lights] == [l["type"] for l in new.lights]
                and set(old.materials) == set(new.materials)
                and old.field_material == new.field_material
                and (old.field is None) == (new.field is None)
                and _fog_shape(old) == _fog_shape(new))
        if same:
            for name in new.materials:
                same &= self._edit_material(name, old, new)
        if not same:
            self._build()
            return
        params = mi.traverse(self.scene)
        for i, (a, b) in enumerate(zip(old.lights, new.lights)):
            if a != b:
                emitter = mi.traverse(mi.load_dict(b))
                for k in emitter.keys():
                    if f"light{i}.{k}" in params:
                        params[f"light{i}.{k}"] = emitter[k]
        params.update()
        cam = new.camera
        set_camera(self.scene, cam.origin, cam.target, cam.up, cam.fov)
        if new.field is not None:
            self.scene.integrator().attach(new.field, self.bsdfs[new.field_material])
        # Its suns and sky come from the lights: re-derive them (opaque values, no compile).
        attach_atmosphere(self.scene, new)

    def _edit_material(self, name, old, new) -> bool:
        """Copy a material's new values into its live BSDF; False if its code must change."""
        a, b = old.materials[name], new.materials[name]
        masks_a, masks_b = old.material_masks.get(name, []), new.material_masks.get(name, [])
        nodes_a, nodes_b = old.material_nodes.get(name, {}), new.material_nodes.get(name, {})
        if a == b and not masks_b and not nodes_b:
            return True
        # Strings and flags (type, textures, sRGB decoding, names), the layer
        # count and the other integer counts shape the code; numbers are opaque values.
        structural = {k: v for k, v in b.items() if k in STRUCTURAL
                      or not isinstance(v, (int, float, list, dict)) or isinstance(v, bool)}
        if ({k: v for k, v in a.items() if k in structural} != structural
                or [(m[0], m[4]) for m in masks_a] != [(m[0], m[4]) for m in masks_b]
                or set(nodes_a) != set(nodes_b)):
            return False
        bsdf = self.bsdfs[name]
        live = mi.traverse(bsdf)
        fresh = mi.traverse(mi.load_dict(b))
        if set(fresh.keys()) - set(live.keys()):
            return False
        for k in fresh.keys():
            live[k] = fresh[k]
        live.update()
        attach_material_nodes(bsdf, new, name)
        return True

    # ------------------------------------------------------------------ rendering
    def render(self, path=None, spp=None, seed=None, view="srgb", aovs=False, on_pass=None, passes=None):
        """Render the current state.

        Parameters
        ----------
        path : str or Path, optional
            Also write this EXR (with header; AOV layers when ``aovs``) and a PNG
            beside it under ``view``.
        spp, seed : int, optional
            Default: those given to :func:`load`, else the scene's.
        view : str
            View transform of the PNG (:data:`arches_render.imaging.colour.VIEWS`).
        aovs : bool
            Render AOV layers into the EXR (builds a second scene once).
        on_pass : callable, optional
            ``on_pass(samples_done, beauty)`` after each sample pass, the mean beauty so
            far (:func:`~arches_render.render.renderer.render_layers`).
        passes : int, optional
            Sample passes (default: the scene's ``[render] passes``): more passes, a
            finer progression of ``on_pass``.

        Returns
        -------
        numpy.ndarray
            ``(H, W, 3)`` float32 linear Rec.709 (also kept as :attr:`last`).
        """
        s = self.desc.render
        spp = spp or self.spp or s.spp
        seed = s.seed if (seed if seed is not None else self.seed) is None else \
            (seed if seed is not None else self.seed)
        scene = self._aov_scene() if aovs else self.scene
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            rgb, layers = render_layers(scene, spp, seed, s.passes if passes is None else passes, on_pass=on_pass)
            hist = dr.kernel_history()
        # A kernel this process has not launched before misses the in-memory
        # cache (whether it was then compiled or loaded from the disk cache).
        self.compiled = sum(1 for k in hist if k["type"] == dr.KernelType.JIT and not k.get("cache_hit", False))
        if path is not None:
            self._write(Path(path), rgb, layers, spp, seed, view)
        self.last, self.last_layers = rgb, layers
        return rgb

    # ------------------------------------------------------------------ notebooks
    def _repr_png_(self):
        """Jupyter's picture of the look: its last render (one now if there is none)
        under the scene's view and exposure (:mod:`arches_render.notebook`)."""
        return notebook.look_png(self, self.last if self.last is not None else self.render())

    def preview(self, spp=None):
        """Render and show the image in one notebook output, refined pass by pass
        (:func:`arches_render.notebook.preview`); returns the render."""
        return notebook.preview(self, spp)

    def slider(self, key: str, lo: float, hi: float, step: float | None = None):
        """A notebook slider over ``key`` and the image it re-renders
        (:func:`arches_render.notebook.slider`)."""
        return notebook.slider(self, key, lo, hi, step)

    def _aov_scene(self):
        key = (id(self.scene), self.rebuilds)
        if getattr(self, "_aov_key", None) != key:
            self._aov = build_scene(self.desc, "field", self.width, self.height, aovs=True, bsdfs=self.bsdfs)
            self._aov_key = key

        src, dst = mi.traverse(self.scene), mi.traverse(self._aov)
        for k in src.keys():
            if k.startswith("light") and k in dst:
                dst[k] = src[k]
        dst.update()
        cam = self.desc.camera
        set_camera(self._aov, cam.origin, cam.target, cam.up, cam.fov)
        if self.desc.field is not None:
            self._aov.integrator().attach(self.desc.field, self.bsdfs[self.desc.field_material])
        attach_atmosphere(self._aov, self.desc)
        return self._aov

    def _write(self, path, rgb, layers, spp, seed, view):
        if path.suffix.lower() != ".exr":
            raise ValueError(f"render path must end in .exr (got {path})")
        path.parent.mkdir(parents=True, exist_ok=True)
        cam = self.desc.camera
        header = render_header(self.desc.name, self.path, seed, spp, self.width, self.height, "field",
                               (cam.origin, cam.target, cam.up, cam.fov))
        write_render(path, rgb, layers, header, clip=sensor_clip(self.scene))
        write_png(path.with_suffix(".png"), view_to_uint8(rgb, view, exposure_of(self.desc.render, rgb)[0]))
