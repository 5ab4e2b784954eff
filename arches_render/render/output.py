"""Render outputs: the EXR of a render (beauty, AOV layers, header) and its preview.

One EXR per image: linear Rec.709 beauty in ``R, G, B``; the AOVs of
:mod:`arches_render.render.aovs` as layers; with denoising, a ``denoised`` layer
(the raw beauty stays in ``R, G, B``). Channels are stored as float32, since depth
and world positions need more than a half float's 11 bits. The header
(``arches:<key>`` string attributes, see :mod:`arches_render.imaging.exr`) holds
the scene name and file, seed, spp, resolution, geometry, camera and the
arches-render version: enough to re-render the image and to tell whether a file
on disk is the one a job would write (:func:`is_complete`).

Compositing metadata
--------------------
Besides the ``arches:`` strings every render EXR carries the OpenEXR standard
camera attributes [1]_ that Nuke and OpenImageIO read (OIIO reports them under
the same names, as ``matrix``/``float``/``float2``), built by
:func:`camera_attributes` from the header's camera and resolution:

``worldToCamera`` (M44f)
    World to the RenderMan camera space that OpenEXR adopts [1]_: origin at the
    camera centre, ``+x`` image right, ``+y`` image up, ``+z`` the viewing
    direction (points in front have ``z > 0``), hence left-handed. Mitsuba's own
    camera frame (``look_at``) is ``(left, up, forward)``: ours is it with ``x``
    negated.
``worldToNDC`` (M44f)
    World to RenderMan NDC [1]_: ``(0, 0)`` the upper-left and ``(1, 1)`` the
    lower-right *corner* of the display window, ``y`` running down, so that
    pixel ``(i, j)`` (column, row) has its centre at ``((i + 1/2) / W, (j + 1/2) / H)``.
    It is projective: ``(x, y, z, w) = (X, Y, Z, 1) M`` then ``x / w, y / w``
    (``w`` is the camera-space ``z``); ``z / w`` maps ``[near, far]`` to ``[0, 1]``.
``screenWindowWidth``, ``screenWindowCenter``
    The screen window on the ``z = 1`` plane of camera space [2]_:
    ``2 tan(fov_x / 2)`` wide and centred at ``(0, 0)`` (no lens shift).
``nearClip``, ``farClip`` (float)
    The sensor's clip distances (metres); not OpenEXR standard names, but plain
    floats that any reader lists.

Matrices are stored as Imath stores them, for row vectors (``p' = p M``): the
transposes of the usual column-vector matrices. The AOVs follow from these
conventions: ``position`` is the world point ``P`` that ``worldToNDC`` maps
into its pixel, and ``depth`` is the Euclidean distance ``|P worldToCamera|``
from the camera centre, not the camera-space ``z``.

References
----------
.. [1] OpenEXR, "Standard Attributes": worldToCamera, worldToNDC,
   https://openexr.com/en/latest/StandardAttributes.html
.. [2] Kainz, F. et al., "Technical Introduction to OpenEXR", section "Projection,
   camera coordinate system and screen window",
   https://openexr.com/en/latest/TechnicalIntroduction.html
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import __version__
from ..imaging.exr import ExrError, read_exr, write_exr
from .aovs import ray_count_header

__all__ = ["render_header", "write_render", "is_complete", "IDENTITY_KEYS", "camera_attributes",
           "world_to_camera", "camera_to_ndc"]

#: Header keys that identify a render: a file whose keys differ is re-rendered.
IDENTITY_KEYS = ("scene_name", "seed", "spp", "resolution", "geometry", "camera_origin",
                 "camera_target", "camera_up", "camera_fov", "stream", "arches_render_version")


def _vec(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


def world_to_camera(origin, target, up) -> np.ndarray:
    """The 4x4 world-to-camera matrix (column vectors, float64) of a ``look_at`` camera.

    Rows are the camera axes in world space, ``R = [r; u; f]`` with
    ``f = (t - o) / |t - o|``, ``l = (u0 x f) / |u0 x f|`` (Mitsuba's "left"),
    ``r = -l`` and ``u = f x l``; the matrix is ``[R, -R o; 0, 1]``. This is the
    frame Mitsuba's ``look_at`` builds, with its ``x`` (left) turned to image right.
    """
    o, t, up = (np.asarray(v, np.float64) for v in (origin, target, up))
    f = (t - o) / np.linalg.norm(t - o)
    left = np.cross(up, f)
    left /= np.linalg.norm(left)
    R = np.stack([-left, np.cross(f, left), f])
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = R, -R @ o
    return m


def camera_to_ndc(fov: float, width: int, height: int, near: float, far: float) -> np.ndarray:
    """The 4x4 projective camera-to-NDC matrix (column vectors, float64).

    With ``s = 1 / (2 tan(fov_x / 2))`` and ``a = W / H``, a camera point
    ``(x, y, z)`` goes to ``u = 1/2 + s x / z`` (right) and ``v = 1/2 - s a y / z``
    (down), which is ``[[s, 0, 1/2, 0], [0, -s a, 1/2, 0], [0, 0, f/(f-n), -f n/(f-n)], [0, 0, 1, 0]]``
    followed by the divide by ``w = z``. Mitsuba's ``perspective`` sensor
    (``fov_axis = "x"``, square pixels) samples the same plane: its ``x_fov``
    spans the image width.
    """
    s = 0.5 / math.tan(math.radians(float(fov)) / 2.0)
    a = float(width) / float(height)
    n, f = float(near), float(far)
    return np.array([[s, 0.0, 0.5, 0.0], [0.0, -s * a, 0.5, 0.0],
                     [0.0, 0.0, f / (f - n), -f * n / (f - n)], [0.0, 0.0, 1.0, 0.0]])


def camera_attributes(camera, width: int, height: int, clip) -> dict:
    """OpenEXR standard camera attributes of a render (see the module docstring).

    Parameters
    ----------
    camera : tuple
        ``(origin, target, up, fov)``, ``fov`` horizontal, in degrees.
    width, height : int
        Full image size in pixels.
    clip : (float, float)
        The sensor's ``(near, far)`` clip distances.

    Returns
    -------
    dict
        ``worldToCamera``/``worldToNDC`` as float32 ``(4, 4)`` arrays in Imath's
        row-vector layout (the transposes), ``screenWindowWidth``,
        ``screenWindowCenter`` (float32 ``(2,)``), ``nearClip`` and ``farClip``;
        the types :func:`~arches_render.imaging.exr.write_exr` stores as M44f,
        float and V2f.
    """
    origin, target, up, fov = camera
    near, far = (float(v) for v in clip)
    w2c = world_to_camera(origin, target, up)
    w2ndc = camera_to_ndc(fov, width, height, near, far) @ w2c
    return {"worldToCamera": np.ascontiguousarray(w2c.T, np.float32),
            "worldToNDC": np.ascontiguousarray(w2ndc.T, np.float32),
            "screenWindowWidth": 2.0 * math.tan(math.radians(float(fov)) / 2.0),
            "screenWindowCenter": np.zeros(2, np.float32),
            "nearClip": near, "farClip": far}


def _header_camera(header: dict):
    """``(camera, width, height)`` from a :func:`render_header`, or None if it names no camera."""
    keys = ("camera_origin", "camera_target", "camera_up", "camera_fov", "resolution")
    if not all(k in header for k in keys):
        return None
    vec = [tuple(float(v) for v in str(header[k]).split()) for k in keys[:3]]
    width, height = (int(v) for v in str(header["resolution"]).split("x"))
    return (*vec, float(header["camera_fov"])), width, height


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


def write_render(path, rgb, layers=None, header=None, denoised=None, clip=None) -> Path:
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
    clip : (float, float), optional
        The sensor's near and far clip distances
        (:func:`arches_render.render.jobs.sensor_clip`). With it and a header
        that names the camera, the file carries the standard camera attributes
        of :func:`camera_attributes`, derived here from the header so that every
        writer (render, tiles, turntable, API) stores the same ones.

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
    cam = _header_camera(header)
    standard = camera_attributes(*cam, clip) if cam is not None and clip is not None else None
    return write_exr(path, rgb, header=header, layers=layers, half=False, attributes=standard)


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
