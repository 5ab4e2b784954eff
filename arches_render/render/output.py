"""Render outputs: the EXR of a render (beauty, AOV layers, header) and its preview.

One EXR per image: linear Rec.709 beauty in ``R, G, B``; the AOVs of
:mod:`arches_render.render.aovs` as layers; with denoising, a ``denoised`` layer
(the raw beauty stays in ``R, G, B``). Channels are stored as float32, since depth
and world positions need more than a half float's 11 bits. The header
(``arches:<key>`` string attributes, see :mod:`arches_render.imaging.exr`) holds
the scene name and file, seed, spp, resolution, geometry, camera and the
arches-render version: enough to re-render the image and to tell whether a file
on disk is the one a job would write (:func:`is_complete`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import __version__
from ..imaging.exr import ExrError, read_exr, write_exr
from .aovs import ray_count_header

__all__ = ["render_header", "write_render", "is_complete", "IDENTITY_KEYS"]

#: Header keys that identify a render: a file whose keys differ is re-rendered.
IDENTITY_KEYS = ("scene_name", "seed", "spp", "resolution", "geometry", "camera_origin",
                 "camera_target", "camera_up", "camera_fov", "stream", "arches_render_version")


def _vec(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


def render_header(name: str, scene_file, seed: int, spp: int, width: int, height: int,
                  geometry: str, camera, stream: int = 0, **extra) -> dict:
    """Header of a render EXR.

    Parameters
    ----------
    name : str
        Scene name.
    scene_file : str or Path
        Scene file.
    seed, spp, width, height : int
    geometry : str
    camera : tuple
        ``(origin, target, up, fov)``.
    stream : int
        Sample stream (turntable frame index, 0 for stills).
    **extra
        More keys (e.g. ``frame``, ``frames``).

    Returns
    -------
    dict of str to str
    """
    origin, target, up, fov = camera
    h = {"arches_render_version": __version__, "scene_name": name, "scene_file": str(scene_file),
         "seed": str(int(seed)), "spp": str(int(spp)), "resolution": f"{int(width)}x{int(height)}",
         "geometry": geometry, "camera_origin": _vec(origin), "camera_target": _vec(target),
         "camera_up": _vec(up), "camera_fov": f"{float(fov):.9g}", "stream": str(int(stream))}
    h.update({k: str(v) for k, v in extra.items()})
    return h


def write_render(path, rgb, layers=None, header=None, denoised=None) -> Path:
    """Write a render's EXR atomically (float32 channels).

    Parameters
    ----------
    path : str or Path
        Destination ``.exr``.
    rgb : numpy.ndarray
        ``(H, W, 3)`` beauty.
    layers : dict, optional
        AOV layers ``{name: (array, letters)}``.
    header : dict, optional
        See :func:`render_header`; the AOV layer names are added as ``aovs``, and
        with the ``exhausted``/``unresolved`` layers the image's counts of rays
        that needed the tracer's second pass or were left after it
        (:func:`~arches_render.render.aovs.ray_count_header`, from ``spp``).
    denoised : numpy.ndarray, optional
        Denoised beauty, stored as layer ``denoised``.

    Returns
    -------
    pathlib.Path
    """
    layers = dict(layers or {})
    if denoised is not None:
        layers["denoised"] = (np.asarray(denoised, np.float32), ("R", "G", "B"))
    header = dict(header or {})
    header["aovs"] = " ".join(sorted(layers))
    header.update({k: str(v) for k, v in ray_count_header(layers, int(header.get("spp", 1))).items()})
    return write_exr(path, rgb, header=header, layers=layers, half=False)


def is_complete(path, header: dict, layers=()) -> bool:
    """Whether ``path`` is a readable render EXR made with ``header``'s identity.

    Parameters
    ----------
    path : str or Path
    header : dict
        Expected header; the keys of :data:`IDENTITY_KEYS` it has must match.
    layers : sequence of str
        Layers the file must hold.

    Returns
    -------
    bool
        False for a missing, truncated or corrupt file, another render, or a
        file lacking a layer or holding non-finite beauty.
    """
    path = Path(path)
    if not path.is_file():
        return False
    try:
        img = read_exr(path)
    except (ExrError, OSError, ValueError):
        return False
    for k in IDENTITY_KEYS:
        if k in header and img.header.get(k) != str(header[k]):
            return False
    w, h = (int(v) for v in header.get("resolution", f"{img.shape[1]}x{img.shape[0]}").split("x"))
    if img.shape != (h, w) or any(name not in img.layers for name in layers):
        return False
    return bool(np.all(np.isfinite(img.rgb)))
