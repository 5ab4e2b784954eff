"""A preview session: one scene file rendered progressively, again after every edit.

:class:`PreviewSession` owns two :class:`~arches_render.api.Lookdev` views of the scene
file: a *small* one (:data:`FIRST_WIDTH` pixels wide, the scene's aspect) and one at the
scene's resolution. After each change it renders the small one at :data:`FIRST_SPP`
samples (the first image: a fraction of a second on warm kernels), then the full one
pass by pass up to the scene's spp, publishing the running mean after every pass.
A newer change interrupts the passes at the next pass boundary.

Changes come from the web page or the file watcher, through :meth:`PreviewSession.post`:

* ``reload``: the scene file or a file it names was saved. The file is read and
  validated again; a bad edit leaves the image and the live scene as they were and
  sets :attr:`PreviewState.error` to its one-line message until a good edit comes.
* ``camera``: render through another of the scene's cameras.
* ``orbit`` / ``dolly``: move the camera around its target (degrees of azimuth and
  elevation) or towards it (a factor of the distance). The moved camera is an
  override on the scene's tables (``camera.origin`` or ``cameras.NAME.origin``), so
  an edit saved meanwhile keeps the view; choosing a camera drops it. A move that
  would put the camera inside the field's solid is refused with one line.
* ``save_camera``: write the current view into the scene file as ``[cameras.NAME]``.
* ``layer``, ``exposure``, ``view``: what the picture shows (the beauty under a view
  transform and exposure, or an AOV layer, :mod:`arches_render.imaging.aov_view`);
  only the picture is made again, except for the first AOV asked, which renders
  with AOVs from then on. A scene that asks for denoising (``[render] denoise``)
  shows the OIDN-denoised beauty (layer ``denoised``) once its passes are done.

Every change but a new scene structure is a parameter edit of the live Mitsuba
scenes (:meth:`~arches_render.api.Lookdev.set`): a camera move or a material value
compiles no kernel (:attr:`PreviewState.compiled` counts those of the last render).

All Dr.Jit work happens in the session's own thread; other threads only post
changes and read the published picture, under a lock.
"""

from __future__ import annotations

import math
import re
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .. import tomlfile
from ..atomic import atomic_write
from ..field import evaluate
from ..imaging.aov_view import BEAUTY, DENOISED, layer_to_uint8
from ..imaging.colour import VIEWS
from ..imaging.exposure import exposure_of
from ..imaging.preview import png_bytes
from ..render.denoise import denoise
from ..render.jobs import scene_inputs
from ..scene import SceneError, parse_scene, read_toml

__all__ = ["FIRST_WIDTH", "FIRST_SPP", "PreviewSession", "PreviewState", "orbit", "dolly"]

#: Width of the first, small image of every change (pixels; the height keeps the aspect).
FIRST_WIDTH = 160
#: Samples per pixel of the first image.
FIRST_SPP = 2
#: Samples per pass of the full-resolution refinement.
PASS_SPP = 4
#: Elevation limit of an orbit (degrees from the plane normal to ``up``): the view
#: never flips over the pole.
MAX_ELEVATION = 85.0
#: Names a camera may be saved under (a bare TOML key).
CAMERA_NAME = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


@dataclass
class PreviewState:
    """What the page shows, as of :attr:`version`.

    Attributes
    ----------
    version : int
        Increases with every change of this state.
    picture : int
        Increases with every published picture.
    stage : str
        ``"starting"``, ``"first"`` (the small image), ``"refining"``, ``"done"``.
    samples, spp : int
        Samples per pixel rendered so far, and the goal.
    size : (int, int)
        The picture's width and height.
    error : str or None
        The one-line message of the last bad edit (the picture is the last good one).
    compiled : int
        Kernels the last render compiled (0 for parameter edits on warm kernels).
    camera : str
        The camera rendered through.
    cameras : list of str
        The scene's cameras.
    layer, layers : str, list of str
        The layer shown and those available.
    exposure : float
        Stops over the scene's exposure.
    view, views : str, list of str
        View transform of the beauty, and those available.
    seconds : float
        Since the change this picture renders (the first image's latency).
    """

    version: int = 0
    picture: int = 0
    stage: str = "starting"
    samples: int = 0
    spp: int = 0
    size: tuple = (0, 0)
    error: str | None = None
    compiled: int = 0
    camera: str = "camera"
    cameras: list = field(default_factory=list)
    layer: str = BEAUTY
    layers: list = field(default_factory=lambda: [BEAUTY])
    exposure: float = 0.0
    view: str = "srgb"
    views: list = field(default_factory=lambda: list(VIEWS))
    seconds: float = 0.0


class _Superseded(Exception):
    """A newer change arrived during a render: stop its passes."""


def orbit(origin, target, up, d_azimuth: float, d_elevation: float) -> list:
    """The camera origin moved around ``target``: ``d_azimuth`` degrees about ``up``, then
    ``d_elevation`` degrees towards ``up`` (clamped to :data:`MAX_ELEVATION`); the
    distance to the target is kept.

    Parameters
    ----------
    origin, target, up : sequence of 3 floats
    d_azimuth, d_elevation : float
        Degrees.

    Returns
    -------
    list of 3 floats
    """
    o, t, u = (np.asarray(v, np.float64) for v in (origin, target, up))
    u = u / np.linalg.norm(u)
    v = o - t
    r = float(np.linalg.norm(v))
    along = float(np.dot(v, u))
    h = v - along * u
    if np.linalg.norm(h) < 1e-9 * r:  # looking straight along up: any horizontal axis
        h = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
    h = h / np.linalg.norm(h)
    side = np.cross(u, h)
    az = math.radians(d_azimuth)
    h = h * math.cos(az) + side * math.sin(az)
    el = math.asin(max(-1.0, min(1.0, along / r))) + math.radians(d_elevation)
    el = max(-math.radians(MAX_ELEVATION), min(math.radians(MAX_ELEVATION), el))
    return [float(x) for x in t + r * (math.cos(el) * h + math.sin(el) * u)]


def dolly(origin, target, factor: float) -> list:
    """The camera origin moved along its line to ``target``: the distance times ``factor``
    (clamped to ``[1/20, 20]`` per move)."""
    o, t = np.asarray(origin, np.float64), np.asarray(target, np.float64)
    f = max(0.05, min(20.0, float(factor)))
    return [float(x) for x in t + (o - t) * f]


class PreviewSession:
    """Progressive renders of one scene file (module docstring).

    Parameters
    ----------
    path : str or Path
        The scene file.
    camera : str, optional
        The camera to start with (default: the scene's).
    first_width : int
        Width of the first image of every change.

    Raises
    ------
    arches_render.scene.SceneError
        When the scene file does not read or validate at start.
    """

    def __init__(self, path, camera=None, first_width=FIRST_WIDTH):
        self.path = Path(path).resolve()
        desc = parse_scene(read_toml(self.path), self.path)  # a bad file fails here, in the caller
        desc.select_camera(camera)
        self.first_width = int(first_width)
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._pending: dict = {}
        self._state = PreviewState(camera=camera or next(iter(desc.cameras)), cameras=list(desc.cameras),
                                   view=desc.render.view)
        self._png = b""
        self._picture = None          # (layers dict with the beauty, scene exposure) of the last render
        self._channels: dict = {}     # the layers' channel names
        self._override: dict = {}     # the moved camera, on top of the file
        # A scene that denoises its renders shows the denoised picture when the passes
        # are done (the ``denoised`` layer, as ``render`` writes it), which needs the AOVs.
        self._aovs = bool(desc.render.denoise)
        if self._aovs:
            self._state.layer = DENOISED
        self._digest = scene_inputs(self.path)
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._failure = None
        self._thread = threading.Thread(target=self._run, args=(camera,), name="preview-render", daemon=True)

    # -- the outside: post changes, read the picture ---------------------------------
    def start(self) -> "PreviewSession":
        """Start the render thread; returns once the scene is built (raises what the build raised)."""
        self._thread.start()
        self._ready.wait()
        if self._failure is not None:
            raise self._failure
        return self

    def stop(self, timeout: float = 30.0) -> None:
        """Stop the render thread (after its current pass)."""
        self._stop.set()
        self._wake.set()
        self._thread.join(timeout)

    def post(self, kind: str, value=None) -> None:
        """Ask for a change (module docstring): ``reload``, ``camera``, ``orbit`` (``(d_az,
        d_el)`` degrees), ``dolly`` (factor), ``save_camera`` (name), ``layer``,
        ``exposure`` (stops), ``view``. Moves accumulate until the thread takes them."""
        with self._lock:
            if kind == "orbit":
                a, e = self._pending.get("orbit", (0.0, 0.0))
                self._pending["orbit"] = (a + float(value[0]), e + float(value[1]))
            elif kind == "dolly":
                self._pending["dolly"] = self._pending.get("dolly", 1.0) * float(value)
            else:
                self._pending[kind] = value
        self._wake.set()

    def picture(self) -> tuple[int, bytes]:
        """``(picture number, PNG bytes)`` of the current picture (:attr:`PreviewState.picture`)."""
        with self._lock:
            return self._state.picture, self._png

    def state(self) -> PreviewState:
        """A copy of the current :class:`PreviewState`."""
        with self._lock:
            return replace(self._state)

    def wait_for(self, predicate, timeout: float = 60.0) -> PreviewState:
        """Poll :meth:`state` until ``predicate(state)`` holds (tests and benchmarks).

        Raises
        ------
        TimeoutError
        """
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            s = self.state()
            if predicate(s):
                return s
            if self._failure is not None:
                raise self._failure
            time.sleep(0.01)
        raise TimeoutError(f"preview: no state matching the condition within {timeout:g} s ({self.state()})")

    # -- the render thread ----------------------------------------------------------
    def _run(self, camera):
        try:
            from ..api import Lookdev
            first = Lookdev(self.path)
            w, h = first.width, first.height
            self._full = first
            self._small = Lookdev(self.path, resolution=(self.first_width, max(1, round(self.first_width * h / w))))
            for look in (self._full, self._small):
                look.use_camera(camera)
        except BaseException as exc:  # noqa: BLE001 (handed to the caller of start)
            self._failure = exc
            self._ready.set()
            return
        self._ready.set()
        changed_at = time.monotonic()
        render = True
        while not self._stop.is_set():
            if render:
                try:
                    self._render(changed_at)
                except _Superseded:
                    pass
                except Exception as exc:  # noqa: BLE001 (a render failure is shown, the server stays up)
                    self._set(error=f"render failed: {type(exc).__name__}: {exc}".splitlines()[0])
            self._wake.wait(0.5)
            self._wake.clear()
            changed_at = time.monotonic()
            try:
                render = self._take_changes()
            except Exception as exc:  # noqa: BLE001 (shown on the page; the session lives on)
                self._set(error=f"{type(exc).__name__}: {exc}".splitlines()[0])
                render = False

    def _take_changes(self) -> bool:
        """Apply the posted changes; True when the scene must be rendered again."""
        with self._lock:
            todo, self._pending = self._pending, {}
        if not todo:
            return False
        render = False
        repaint = any(k in todo for k in ("layer", "exposure", "view"))
        with self._lock:
            if "exposure" in todo:
                self._state.exposure = float(todo["exposure"])
            if todo.get("view") in VIEWS:
                self._state.view = todo["view"]
            if "layer" in todo:
                self._state.layer = str(todo["layer"])
                if self._state.layer != BEAUTY and not self._aovs:
                    self._aovs = render = True
        try:
            if "camera" in todo:
                self._override = {}
                for look in (self._small, self._full):
                    look.use_camera(todo["camera"])
                render = True
            if "reload" in todo:
                digest = scene_inputs(self.path)  # (raises OSError while the file is missing)
                if digest != self._digest:
                    self._digest = digest
                    for look in (self._small, self._full):
                        look.reload(self._override)
                    render = True
                else:
                    del todo["reload"]  # (another file of the folder: nothing to do)
            if "orbit" in todo or "dolly" in todo:
                self._move(todo.get("orbit", (0.0, 0.0)), todo.get("dolly", 1.0))
                render = True
            if "save_camera" in todo:
                self._save_camera(str(todo["save_camera"]))
            if todo.keys() - {"layer", "exposure", "view"}:
                # A good edit (or move) clears the last bad one's message.
                self._set(error=None, camera=self._full.camera_name or self._state.camera,
                          cameras=list(self._full.desc.cameras))
        except (SceneError, KeyError, ValueError) as exc:
            self._set(error=str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
        except OSError as exc:
            # The file gone for a moment (an editor that saves by renaming) or unreadable:
            # say so and keep the picture; the watcher's next event reloads it.
            self._set(error=f"{exc.filename or self.path}: {exc.strerror or exc}")
        if repaint and not render:
            self._repaint()
        return render

    def _camera_key(self) -> str:
        name = self._full.camera_name or next(iter(self._full.desc.cameras))
        return "camera" if name == "camera" else f"cameras.{name}"

    def _move(self, turn, factor):
        cam = self._full.desc.camera
        origin = orbit(cam.origin, cam.target, cam.up, *turn)
        origin = dolly(origin, cam.target, factor)
        field = self._full.desc.field
        if field is not None and evaluate(field, np.asarray([origin]))[0] >= 0.0:
            # A camera inside rock sees nothing: keep the view and say why.
            where = ", ".join(f"{v:.1f}" for v in origin)
            raise ValueError(f"that move puts the camera inside the terrain at [{where}]: the view is kept")
        self._override = {f"{self._camera_key()}.origin": origin}
        for look in (self._small, self._full):
            look.update(self._override)

    def _save_camera(self, name: str):
        """Append the current view to the scene file as ``[cameras.NAME]`` (atomically,
        only if the file then reads and validates) and render through it."""
        if not CAMERA_NAME.match(name) or name == "camera":
            raise ValueError(f"camera name {name!r}: use 1-64 letters, digits, '-' or '_' (not 'camera')")
        if name in self._full.desc.cameras:
            raise ValueError(f"camera name {name!r} is taken (cameras: {', '.join(self._full.desc.cameras)})")
        cam = self._full.desc.camera
        vec = lambda v: "[" + ", ".join(repr(float(x)) for x in v) + "]"  # noqa: E731
        text = self.path.read_text(encoding="utf-8")
        text = (text.rstrip("\n") + f"\n\n[cameras.{name}]\norigin = {vec(cam.origin)}\n"
                f"target = {vec(cam.target)}\nup = {vec(cam.up)}\nfov = {float(cam.fov)!r}\n")
        parse_scene(tomlfile.loads(text), self.path)  # raises before the file is touched
        with atomic_write(self.path, "w", encoding="utf-8") as f:
            f.write(text)
        self._digest = scene_inputs(self.path)
        self._override = {}
        for look in (self._small, self._full):
            look.reload()
            look.use_camera(name)

    def _render(self, changed_at):
        spp = self._full.desc.render.spp
        self._small.render(spp=FIRST_SPP, aovs=self._aovs)
        self._publish(self._small, "first", FIRST_SPP, FIRST_SPP, changed_at)

        def on_pass(done, beauty):
            if self._stop.is_set() or self._changes_waiting():
                raise _Superseded
            if done < spp:  # (the last pass is published with its layers below)
                self._publish_arrays({BEAUTY: beauty}, self._full, "refining", done, spp, changed_at)

        self._full.render(spp=spp, aovs=self._aovs, passes=max(1, math.ceil(spp / PASS_SPP)), on_pass=on_pass)
        self._publish(self._full, "done", spp, spp, changed_at)

    def _changes_waiting(self) -> bool:
        with self._lock:
            return any(k not in ("layer", "exposure", "view") for k in self._pending)

    def _publish(self, look, stage, done, spp, changed_at):
        layers = {BEAUTY: look.last}
        layers.update({name: arr for name, (arr, _) in look.last_layers.items()})
        self._channels = {name: letters for name, (_, letters) in look.last_layers.items()}
        if stage == "done" and look.desc.render.denoise and "albedo" in layers and "normal" in layers:
            layers[DENOISED] = denoise(look.last, layers["albedo"], layers["normal"])
        self._publish_arrays(layers, look, stage, done, spp, changed_at, compiled=look.compiled)

    def _publish_arrays(self, layers, look, stage, done, spp, changed_at, compiled=None):
        exposure = exposure_of(look.desc.render, layers[BEAUTY])[0]
        with self._lock:
            keep = self._picture[0] if self._picture is not None and stage == "refining" else {}
            self._picture = ({**keep, **layers}, exposure)
        self._repaint(stage=stage, samples=done, spp=spp, seconds=time.monotonic() - changed_at,
                      size=tuple(layers[BEAUTY].shape[1::-1]), compiled=compiled)

    def _repaint(self, **state):
        with self._lock:
            if self._picture is None:
                return
            layers, exposure = self._picture
            s = self._state
            name = s.layer if s.layer in layers else BEAUTY
            pixels = layer_to_uint8(name, layers[name], s.view, exposure + s.exposure, self._channels.get(name, ()))
        png = png_bytes(pixels)
        with self._lock:
            self._png = png
            for k, v in state.items():
                if v is not None:
                    setattr(self._state, k, v)
            self._state.layers = [BEAUTY] + [k for k in layers if k != BEAUTY]
            self._state.picture += 1
            self._state.version += 1

    def _set(self, **values):
        with self._lock:
            for k, v in values.items():
                setattr(self._state, k, v)
            self._state.version += 1
