"""Turntables: a seamless orbit of the camera around the scene's target.

Frame ``k`` of ``N`` (``k = 0 .. N-1``) puts the camera at the scene camera's
origin rotated about the axis through the target along the camera's ``up``
vector by

    theta_k = 2 pi (k mod N) / N,

with Rodrigues' formula ``R v = v cos theta + (a x v) sin theta + a (a . v)(1 - cos theta)``
applied to ``v = origin - target``. Distance to the target, height along ``up``
and field of view stay those of the scene: one exposure, one speed. Frame ``N``
(the one after the last) would be frame 0 exactly (the angle is reduced modulo
``N`` before the sine and cosine), so the loop has no seam; frame 0 is the scene's
own camera.

The same frames, resume and layers serve a keyframed camera path
(:mod:`arches_render.render.camera_path`): :func:`plan_turntable` takes the
cameras of every frame in place of the orbit.

Frames are ``DIR/NAME.####.exr`` numbered from 1001 (a VFX convention that keeps
handles free before the first frame), each written atomically with its AOVs and
header (:mod:`arches_render.render.output`). A rerun skips every frame that is
already complete and valid (it reads back and carries the expected header), so a
killed or crashed turntable resumes where it stopped; a truncated or corrupt
frame is rendered again. Frame ``k`` uses sample stream ``k``
(:func:`arches_render.render.renderer.pass_seed`): the bits of a frame do not
depend on which process rendered it or in which order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import faults
from .aovs import BASE_LAYERS
from .denoise import denoise as oidn
from .distributed import map_jobs
from .jobs import RenderJob, job_clip, run_job
from .output import is_complete, render_header, write_render

__all__ = ["FIRST_FRAME", "orbit_camera", "frame_path", "TurntablePlan", "plan_turntable",
           "render_turntable"]

FIRST_FRAME = 1001


def orbit_camera(origin, target, up, k: int, frames: int):
    """Camera origin of frame ``k`` of an ``frames``-frame orbit (see module docstring).

    Parameters
    ----------
    origin, target, up : sequence of 3 floats
        The scene's camera.
    k : int
        Frame index (any integer; taken modulo ``frames``).
    frames : int
        Frames per revolution (>= 1).

    Returns
    -------
    numpy.ndarray
        The origin of frame ``k`` (float64).
    """
    if frames < 1:
        raise ValueError(f"frames must be >= 1 (got {frames})")
    o, t = np.asarray(origin, np.float64), np.asarray(target, np.float64)
    a = np.asarray(up, np.float64)
    a = a / np.linalg.norm(a)
    theta = 2.0 * math.pi * (int(k) % int(frames)) / int(frames)
    v = o - t
    c, s = math.cos(theta), math.sin(theta)
    return t + v * c + np.cross(a, v) * s + a * np.dot(a, v) * (1.0 - c)


def frame_path(out_dir, name: str, k: int) -> Path:
    """``out_dir/NAME.####.exr`` of frame index ``k`` (numbered from :data:`FIRST_FRAME`)."""
    return Path(out_dir) / f"{name}.{FIRST_FRAME + int(k):04d}.exr"


@dataclass
class TurntablePlan:
    """Jobs, files and headers of a turntable; ``todo`` are the frame indices to render."""

    jobs: list
    paths: list
    headers: list
    todo: list
    layers: tuple


def plan_turntable(desc, scene_file, out_dir, frames: int, spp: int, width: int, height: int,
                   seed: int | None = None, passes: int = 0, aovs: bool = True,
                   denoise: bool = False, threads: int = 0, cameras=None) -> TurntablePlan:
    """Jobs of a turntable and the frames still to render.

    Parameters
    ----------
    desc : SceneDescription
        The loaded scene (its name and camera).
    scene_file : str or Path
        The scene file the jobs load.
    out_dir : str or Path
        Frame folder.
    frames, spp, width, height : int
    seed : int, optional
        Default: the scene's.
    passes : int
    aovs, denoise : bool
        Layers the frames hold (denoising needs the AOVs).
    threads : int
        Dr.Jit threads per job (0: default).
    cameras : list of tuple, optional
        ``(origin, target, up, fov)`` of every frame (a camera path,
        :func:`arches_render.render.camera_path.path_cameras`); ``frames`` must be
        its length. Default: the orbit of the scene's camera.

    Returns
    -------
    TurntablePlan
    """
    cam = desc.camera
    seed = desc.render.seed if seed is None else int(seed)
    jobs, paths, headers, todo = [], [], [], []
    layers = tuple(name for name, _ in BASE_LAYERS) if aovs else ()
    if denoise:
        layers += ("denoised",)
    if cameras is not None and len(cameras) != frames:
        raise ValueError(f"{len(cameras)} cameras for {frames} frames")
    for k in range(frames):
        if cameras is not None:
            camera = cameras[k]
        else:
            origin = orbit_camera(cam.origin, cam.target, cam.up, k, frames)
            camera = (tuple(origin.tolist()), tuple(cam.target), tuple(cam.up), cam.fov)
        job = RenderJob(scene=str(Path(scene_file).resolve()), width=width, height=height, spp=spp,
                        seed=seed, passes=passes, stream=k, geometry="field", aovs=aovs or denoise,
                        camera=camera, threads=threads, label=f"frame {FIRST_FRAME + k}")
        header = render_header(desc.name, scene_file, seed, spp, width, height, "field", camera,
                               stream=k, frame=FIRST_FRAME + k, frames=frames)
        path = frame_path(out_dir, desc.name, k)
        jobs.append(job)
        paths.append(path)
        headers.append(header)
        if not is_complete(path, header, layers):
            todo.append(k)
    return TurntablePlan(jobs, paths, headers, todo, layers)


def _write_frame(plan: TurntablePlan, k: int, result, denoise: bool) -> Path:
    rgb, layers = result
    denoised = None
    if denoise:
        denoised = oidn(rgb, layers["albedo"][0], layers["normal"][0])
    # The clip planes come from the scene, known once built: at write time, not
    # at plan time (a resumed turntable with nothing left to do builds nothing).
    return write_render(plan.paths[k], rgb, layers, plan.headers[k], denoised, clip=job_clip(plan.jobs[k]))


def render_turntable(plan: TurntablePlan, denoise: bool = False, client=None, progress=None,
                     sample_progress=None) -> list:
    """Render the frames of ``plan.todo``, serially or on a Dask client.

    Parameters
    ----------
    plan : TurntablePlan
    denoise : bool
        Add the ``denoised`` layer (OIDN runs where the frame is written).
    client : dask.distributed.Client, optional
        Render frames on its workers; results are written here.
    progress : callable, optional
        ``progress(frames_done, frames_todo)``.
    sample_progress : callable, optional
        ``progress(samples_done, spp)`` inside a frame (serial runs only).

    Returns
    -------
    list of pathlib.Path
        The frames written by this call.
    """
    written = []
    if progress:
        progress(0, len(plan.todo))
    if client is None:
        for k in plan.todo:
            written.append(_write_frame(plan, k, run_job(plan.jobs[k], sample_progress), denoise))
            faults.point("turntable.after_frame")  # test-only kill point (arches_render.faults)
            if progress:
                progress(len(written), len(plan.todo))
        return written
    for k, result in map_jobs(client, [plan.jobs[k] for k in plan.todo], keys=plan.todo):
        written.append(_write_frame(plan, k, result, denoise))
        faults.point("turntable.after_frame")
        if progress:
            progress(len(written), len(plan.todo))
    return written
