"""Scene files for amplified terrains: TOML text, camera framing, sun and material.

``arches-render amplify`` writes the construction tree it built as ``[nodes.*]``
tables of a scene file (TOML data, never code), with the arrays of primitive sets
in ``.npz`` files and the heights in a ``.npy`` beside it. This module turns those
tables into TOML text and chooses what a first render needs:

Camera
    Aimed at the features (the centroid of the generated primitives, else the
    terrain's centre) from *downhill* (the sea, the valley), so that cliffs,
    caves and canyon walls face the camera; far enough to frame most features,
    ``el`` degrees above the target, and never below the terrain under it.
Sun
    ``sunsky`` at 35 degrees, 55 degrees round from the camera's azimuth: grazing
    enough to model overhangs with shadow, bright enough to see into caves.
Material
    The ``terrain`` triplanar preset (rock, sand, grass, snow) with its layer
    heights rescaled to the DEM's elevation range, so that a 6 km DEM is not all
    snow and a 100 m one not all sand; the rock coloured by the preset's own
    geology (strata palette, cavity, wetness at sea level:
    :func:`arches_render.materials.masks.terrain_look`).
"""

from __future__ import annotations

import json
import math
import re

import numpy as np

from arches_render.materials.masks import terrain_look

__all__ = ["toml_text", "frame_camera", "landscape_material", "sun_for"]

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k):
    return k if _BARE.match(k) else json.dumps(k)


def _value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if not math.isfinite(v):
            raise ValueError(f"cannot write a non-finite number ({v}) to a scene file")
        return repr(v)  # shortest exact form: the file rebuilds the very tree that was made
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a valid TOML basic string
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to a scene file")


def toml_text(doc, header=""):
    """TOML text of a scene document.

    Parameters
    ----------
    doc : dict
        Top-level keys map to tables (dicts of scalars, arrays and inline tables),
        arrays of tables (lists of dicts: ``[[lights]]``), or, for ``nodes`` and
        ``materials``, dicts of named tables (``[nodes.NAME]``).
    header : str
        Comment lines put first (without the ``#``).

    Returns
    -------
    str
    """
    out = [f"# {line}".rstrip() for line in header.splitlines()]
    for name, body in doc.items():
        if isinstance(body, list):
            for item in body:
                out += ["", f"[[{_key(name)}]]"] + [f"{_key(k)} = {_value(v)}" for k, v in item.items()]
        elif name in ("nodes", "materials"):
            for sub, table in body.items():
                out += ["", f"[{_key(name)}.{_key(sub)}]"] + [f"{_key(k)} = {_value(v)}" for k, v in table.items()]
        else:
            out += ["", f"[{_key(name)}]"] + [f"{_key(k)} = {_value(v)}" for k, v in body.items()]
    return "\n".join(out).lstrip("\n") + "\n"


def frame_camera(heights, extent, features=None, fov=50.0, elevation=24.0, margin=1.2):
    """A camera that looks at the features from the downhill side.

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` elevations over ``extent``.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)``.
    features : numpy.ndarray, optional
        ``(K, 3)`` positions of the generated landforms; the camera aims at their
        centroid and frames three quarters of them. Default: the whole tile.
    fov : float
        Horizontal field of view, degrees.
    elevation : float
        Angle of the view above the horizontal, degrees.
    margin : float
        Extra distance factor.

    Returns
    -------
    dict
        ``origin``, ``target``, ``fov`` and ``azimuth`` (degrees, of the view
        direction from the camera towards the target).

    Notes
    -----
    The camera stands *downhill* of the target (the direction of the regional
    slope, a Gaussian-smoothed gradient over an eighth of the tile): cliffs,
    cave mouths and canyon walls face downhill, and a canyon is seen along its
    course. On flat ground it stands on the tile's lowest side.
    """
    from scipy.ndimage import gaussian_filter
    H = np.asarray(heights, dtype=np.float64)
    ny, nx = H.shape
    x0, y0, x1, y1 = extent
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    zlo, zhi = float(H.min()), float(H.max())
    half_tile = 0.5 * math.hypot(x1 - x0, y1 - y0)
    if features is not None and len(features):
        F = np.asarray(features, dtype=np.float64).reshape(-1, 3)
        target = F.mean(axis=0)
        spread = float(np.percentile(np.linalg.norm(F[:, :2] - target[:2], axis=1), 75))
        half = min(max(1.3 * spread, 0.3 * half_tile), half_tile)
    else:
        target = np.array([(x0 + x1) / 2, (y0 + y1) / 2, (zlo + zhi) / 2])
        half = half_tile
    i = int(np.clip(round((target[0] - x0) / dx), 0, nx - 1))
    j = int(np.clip(round((target[1] - y0) / dy), 0, ny - 1))
    S = gaussian_filter(H, max(nx, ny) / 8.0, mode="nearest")
    gy, gx = np.gradient(S, dy, dx)
    if math.hypot(gx[j, i], gy[j, i]) > 1e-3:
        az = math.atan2(-gy[j, i], -gx[j, i])  # downhill
    else:
        k = max(1, min(nx, ny) // 4)
        sides = {(-1, 0): H[:, :k].mean(), (1, 0): H[:, -k:].mean(), (0, -1): H[:k].mean(), (0, 1): H[-k:].mean()}
        (sx, sy), _ = min(sides.items(), key=lambda kv: kv[1])
        az = math.atan2(sy, sx)
    az += math.radians(40.0)  # well off the axis: faces parallel to the view get relief
    dist = margin * half / math.tan(math.radians(fov) / 2)
    el = math.radians(elevation)
    origin = target + dist * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    # Keep the camera above the ground under it (clamped lookup for points off the tile).
    i = int(np.clip(round((origin[0] - x0) / dx), 0, nx - 1))
    j = int(np.clip(round((origin[1] - y0) / dy), 0, ny - 1))
    origin[2] = max(origin[2], H[j, i] + 0.1 * (zhi - zlo) + 1.0)
    view = target - origin
    return dict(origin=[float(v) for v in origin], target=[float(v) for v in target], fov=float(fov),
                azimuth=math.degrees(math.atan2(view[1], view[0])))


def sun_for(camera, elevation=35.0, turn=55.0):
    """A ``[[lights]]`` sunsky table lighting the faces the camera sees."""
    # The sun sits behind the camera, turned aside: azimuth of the direction *towards* the sun.
    az = camera["azimuth"] + 180.0 + turn
    az = (az + 180.0) % 360.0 - 180.0
    return {"type": "sunsky", "elevation": float(elevation), "azimuth": float(az), "turbidity": 3.0}


# -- lookdev (issue 15): the rock's strata palette per preset ----------------------------------
#: Chalk and limestone coasts and karst, sandstone canyons and layer cakes, banded badlands.
STRATA_PALETTE = {"sea": "limestone", "river": "sandstone", "karst": "limestone", "hoodoos": "badlands",
                  "strata": "sandstone"}


def landscape_material(zlo, zhi, sea_level=None, geology=None, box=None, preset=None, cell=1.0):
    """The ``terrain`` triplanar preset with layer heights fitted to ``[zlo, zhi]``.

    Sand covers low flats (up to 12 % of the relief, or a little above sea level),
    grass gentle slopes from 10 % to 75 %, and snow only the top 5 % of a relief
    of more than 300 m. With ``geology`` (the built resistance node of the scene's
    ``[nodes.geology]``) and ``box`` (the rock's volume), the rock takes the
    strata colours of the preset's palette (:data:`STRATA_PALETTE`), the cavity
    term (reach two cells) and, with ``sea_level``, a wet band.
    """
    relief = max(zhi - zlo, 1e-3)
    sand_top = zlo + 0.12 * relief if sea_level is None else sea_level + 0.06 * relief
    over = {
        "sand.height_max": sand_top, "sand.height_soft": 0.04 * relief,
        "grass.height_min": zlo + 0.10 * relief, "grass.height_max": zlo + 0.75 * relief,
        "grass.height_soft": 0.05 * relief,
        "snow.height_min": zhi - 0.05 * relief if relief > 300 else zhi + relief,
        "snow.height_soft": 0.02 * relief,
    }
    mat = {"type": "triplanar", "preset": "terrain", "overrides": over}
    if geology is not None:
        mat.update(terrain_look(geology, box, STRATA_PALETTE.get(preset, "sandstone"), "geology", sea_level,
                                cavity_radius=2.0 * cell))
    return mat
