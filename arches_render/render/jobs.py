"""Render jobs: picklable units of work (a frame, a tile, a golden render) and their execution.

A :class:`RenderJob` names a scene *file* and everything that decides the pixels
(resolution, spp, seed, sample stream, camera, crop window), so it can travel to
another process or machine (:mod:`arches_render.render.distributed`) and give the
same bits there as here: serial runs and Dask workers call the same
:func:`run_job`. A process keeps the Mitsuba scenes it built in a small cache
(keyed by the scene's inputs, :func:`scene_inputs`, and the settings that shape
the kernels), so a worker that renders many frames builds and compiles once; an
edit of the scene file or of any file it names builds anew. The camera of a frame
is applied as a parameter edit (``sensor.to_world``, ``sensor.x_fov``), which
re-uses the compiled kernels. A job with AOVs and one without share the built
scene and differ by its integrator (:func:`~arches_render.render.renderer.scene_integrator`).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass, field as dc_field, replace
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import faults, tomlfile
from ..backend import io_threads, set_variant
from ..scene import load_scene, paths
from .renderer import (build_scene, load_materials, render_layers, scene_integrator, set_pixel_spread,
                       tile_projection)

__all__ = ["RenderJob", "run_job", "clear_cache", "scene_inputs", "scene_files", "sensor_clip", "job_clip"]

_CACHE: "OrderedDict[tuple, tuple]" = OrderedDict()
_CACHE_SIZE = 4
# The loaded descriptions (generators run) by scene inputs: the modes and sizes of one
# scene (field and mesh, with and without AOVs) build from one load. build_scene
# reads a description and never edits it, so Mitsuba scenes may share one.
_DESCS: "OrderedDict[tuple, object]" = OrderedDict()
_DESCS_SIZE = 2
# One job at a time per process: two threads (a caller's, or a Dask worker's several,
# though workers now hand their jobs to one render process, render/isolated.py) would
# otherwise render two frames at once through the same cached scene, one moving the
# other's camera; Dr.Jit's own threads already use the cores.
_RUN_LOCK = threading.Lock()


@dataclass(frozen=True)
class RenderJob:
    """Everything that decides one rendered image.

    Attributes
    ----------
    scene : str
        Scene file (absolute path, readable where the job runs).
    width, height : int
        Full image size in pixels.
    spp, seed, passes : int
        Samples per pixel, base seed, sample passes (0: automatic).
    stream : int
        Sample stream (frame or tile index): mixed into the pass seeds
        (:func:`arches_render.render.renderer.pass_seed`).
    geometry : str
        ``'field'`` or ``'mesh'``.
    aovs : bool
        Also render the AOV layers.
    moments : bool
        Also render the second moments (layer ``moment2``, for golden tests).
    camera : tuple or None
        ``(origin, target, up, fov)`` replacing the scene's camera.
    crop : tuple or None
        ``(x0, y0, w, h)``: render this window only.
    voxel : float
        Mesh-mode voxel (0: the scene's).
    threads : int
        Dr.Jit worker threads (0: leave as is).
    allow : tuple of str
        Folders the scene may read files from besides its own
        (:mod:`arches_render.scene.paths`); default those allowed where the job is made.
    label : str
        What the job renders, for messages (``'frame 1003'``, ``'tile 2 of 4 ...'``;
        ``''``: the image); no part of the pixels.
    """

    scene: str
    width: int
    height: int
    spp: int
    seed: int = 0
    passes: int = 0
    stream: int = 0
    geometry: str = "field"
    aovs: bool = True
    moments: bool = False
    camera: tuple | None = None
    crop: tuple | None = None
    voxel: float = 0.0
    threads: int = 0
    allow: tuple = dc_field(default_factory=paths.extra_folders)
    label: str = ""

    def with_(self, **changes) -> "RenderJob":
        """A copy with some fields changed."""
        return replace(self, **changes)

    def describe(self) -> str:
        """``SCENE: WHAT (GEOMETRY[, AOVs])``, the job in one line for messages."""
        return f"{self.scene}: {self.label or 'image'} ({self.geometry}{', AOVs' if self.aovs else ''})"


def clear_cache() -> None:
    """Forget the scenes this process built and the descriptions it loaded."""
    _CACHE.clear()
    _DESCS.clear()


def _remember(cache: OrderedDict, size: int, key, value):
    cache[key] = value
    while len(cache) > size:
        cache.popitem(last=False)
    return value


def _desc_for(job: RenderJob):
    path = Path(job.scene).resolve()
    key = (str(path), scene_inputs(path), job.allow)
    if key in _DESCS:
        _DESCS.move_to_end(key)
        return _DESCS[key]
    with paths.allowed(job.allow):
        return _remember(_DESCS, _DESCS_SIZE, key, load_scene(path))


def _scene_for(job: RenderJob):
    """``(desc, scene, integrator)`` for ``job``: the scene from this process's cache or
    built, with the integrator of the job's AOVs (the scene's own, or another made for
    it and kept with it)."""
    key, outputs = _key(job), _outputs(job)
    entry = _CACHE.get(key)
    if entry is not None:
        _CACHE.move_to_end(key)
        desc, scene, bsdfs, integrators = entry
        if outputs not in integrators and bsdfs is not None:
            integrators[outputs] = scene_integrator(scene, desc, job.geometry, bsdfs, *outputs, width=job.width)
        if outputs in integrators:
            return desc, scene, integrators[outputs]
    # A job may have left this process one thread (job.threads), with which the EXR
    # files a scene reads would hang its load (backend.io_threads).
    with io_threads():
        desc = _desc_for(job)
        bsdfs = load_materials(desc)
        scene = build_scene(desc, job.geometry, job.width, job.height, job.voxel or None, aovs=job.aovs,
                            crop=job.crop, bsdfs=bsdfs, moments=job.moments)
    _remember(_CACHE, _CACHE_SIZE, key, (desc, scene, bsdfs, {outputs: scene.integrator()}))
    return desc, scene, scene.integrator()


def prime_cache(job: RenderJob, desc, scene, bsdfs=None) -> None:
    """Hand this process's cache a scene already built for ``job`` (e.g. with a progress bar).

    ``bsdfs``: the materials it was built with (:func:`~arches_render.render.renderer.load_materials`);
    without them a job with other AOVs builds its own scene."""
    _CACHE[_key(job)] = (desc, scene, bsdfs, {_outputs(job): scene.integrator()})


def _key(job: RenderJob) -> tuple:
    path = Path(job.scene).resolve()
    # Tiles of one size share a scene: run_job points its camera at each window. Jobs
    # with and without AOVs share it too: only the integrator differs (_outputs).
    window = None if job.crop is None else tuple(int(v) for v in job.crop[2:])
    return (str(path), scene_inputs(path), job.width, job.height, job.geometry, window, job.voxel, job.allow)


def _outputs(job: RenderJob) -> tuple:
    """``(aovs, moments)``: what the job's integrator returns besides the beauty."""
    return (bool(job.aovs or job.moments), bool(job.moments))


def scene_inputs(path) -> str:
    """Digest of what a scene file builds from: its text and every file it names.

    Parameters
    ----------
    path : str or Path
        The scene file.

    Returns
    -------
    str
        SHA-256 of the file's bytes and, for every string value of its TOML
        that names an existing file (relative to the scene's folder, or
        absolute), that file's path, size, inode and modification and change
        times.

    Notes
    -----
    The scene's own modification time alone misses an edit of a mesh, DEM or
    array file it names, and a scene cached under it then renders stale
    geometry. Every string is tried as a path, rather than the keys known to
    take one, so that a key added later is covered without a change here.
    Named files are identified by their metadata rather than hashed: the change
    time (``st_ctime_ns``) moves on every write and cannot be set back by a
    user, and hashing a large DEM for every frame would cost more than it
    renders.
    """
    path = Path(path)
    data = path.read_bytes()
    h = hashlib.sha256(data)
    try:
        doc = tomlfile.loads(data.decode("utf-8"))
    except (ValueError, UnicodeDecodeError):
        doc = {}  # load_scene reports the error; the text digest alone keys it
    for f in scene_files(path, doc):
        st = f.stat()
        h.update(f"\0{f}\0{st.st_size}\0{st.st_ino}\0{st.st_mtime_ns}\0{st.st_ctime_ns}".encode())
    return h.hexdigest()


def scene_files(path, doc=None) -> list[Path]:
    """The existing files a scene file names, resolved and sorted (see :func:`scene_inputs`).

    Parameters
    ----------
    path : str or Path
        The scene file.
    doc : dict, optional
        Its parsed TOML (read from ``path`` when not given; an unreadable file names none).

    Returns
    -------
    list of Path
    """
    path = Path(path)
    if doc is None:
        try:
            doc = tomlfile.load(path)
        except (OSError, ValueError):
            doc = {}
    return sorted(set(_named_files(doc, path.parent)))


def _named_files(value, base: Path):
    if isinstance(value, dict):
        for v in value.values():
            yield from _named_files(v, base)
    elif isinstance(value, list):
        for v in value:
            yield from _named_files(v, base)
    elif isinstance(value, str) and value and "\0" not in value and len(value) < 4096:
        try:
            f = (base / value).resolve()
            if f.is_file():
                yield f
        except (OSError, ValueError):
            pass  # not a path this system can name


def set_camera(scene, origin, target, up, fov, image=None, integrator=None) -> None:
    """Move a built scene's camera (a parameter edit: no kernel is recompiled).

    ``image = (width, height, crop)``: the scene renders the window ``crop`` of a
    ``width x height`` image (its film is the window's size, see
    :func:`arches_render.render.renderer.tile_projection`); ``crop`` may be ``None``.
    ``integrator``: the one the scene will render with, if not its own (its ray cones).
    """
    params = mi.traverse(scene)
    params["sensor.to_world"] = mi.AffineTransform4f(
        mi.ScalarTransform4f().look_at(origin=[float(v) for v in origin],
                                       target=[float(v) for v in target], up=[float(v) for v in up]))
    x_fov, offset, width = float(fov), (0.0, 0.0), None
    if image is not None and image[2] is not None:
        width = int(image[0])
        x_fov, *offset = tile_projection(fov, image[0], image[1], image[2])
    params["sensor.x_fov"] = x_fov
    params["sensor.principal_point_offset_x"] = float(offset[0])
    params["sensor.principal_point_offset_y"] = float(offset[1])
    params.update()
    set_pixel_spread(scene, float(fov), width, integrator)


def sensor_clip(scene) -> tuple[float, float]:
    """``(near, far)`` clip distances of a built scene's sensor, metres (for the EXR header)."""
    params = mi.traverse(scene.sensors()[0])
    return float(params["near_clip"]), float(params["far_clip"])


def job_clip(job: RenderJob) -> tuple[float, float]:
    """``(near, far)`` of the sensor ``job`` renders through (:func:`sensor_clip`).

    The planes depend on the scene only (its box, meshes included: see
    :func:`arches_render.render.renderer.clip_planes`), not on the job's camera,
    crop or stream, so the scene built for the whole image answers for every
    frame and tile. That scene comes from this process's cache: free after a
    serial render, one scene build (no render) where the pixels came from Dask
    workers.
    """
    set_variant()
    _, scene, _ = _scene_for(job.with_(crop=None, stream=0))
    return sensor_clip(scene)


def run_job(job: RenderJob, progress=None):
    """Render a job in this process.

    Parameters
    ----------
    job : RenderJob
    progress : callable, optional
        ``progress(samples_done, spp)`` after each pass.

    Returns
    -------
    (numpy.ndarray, dict)
        Beauty ``(h, w, 3)`` float32 and the AOV layers ``{name: (array, letters)}``
        (see :func:`arches_render.render.renderer.render_layers`).
    """
    set_variant()
    faults.point("render.job")  # test-only kill point (arches_render.faults)
    with _RUN_LOCK:
        if job.threads:
            dr.set_thread_count(int(job.threads))
        desc, scene, integrator = _scene_for(job)
        cam = job.camera or (desc.camera.origin, desc.camera.target, desc.camera.up, desc.camera.fov)
        set_camera(scene, *cam, image=(job.width, job.height, job.crop), integrator=integrator)
        rgb, layers = render_layers(scene, job.spp, job.seed, job.passes, progress, stream=job.stream,
                                    integrator=integrator)
    return np.ascontiguousarray(rgb), layers
