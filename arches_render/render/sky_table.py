"""The sky's radiance as a table over azimuth and elevation: the background the haze fades to.

:class:`SkyTable` holds the radiance of a scene's sky emitters (``sunsky`` without
its sun disk, ``constant``, ``envmap``; all of them summed) in every direction of
the upper hemisphere, for the atmosphere's in-scatter ``(1 - Tr) L_bg(d)``
(:mod:`arches_render.render.atmosphere`). Directions below the horizon read the
horizon row in their azimuth (their elevation is clamped to 0).

Why a table. The in-scatter is evaluated on every segment of every path; Mitsuba's
``sunsky`` evaluates its sky model there (a few dozen operations and its own gathers),
an ``envmap`` a bilinear lookup in a large bitmap. The table is evaluated once per
scene, at load, with Mitsuba's own ``eval`` of the emitters (so it is the sky that
misses see, not a re-implementation), and read with four gathers. Its values are
held in Dr.Jit arrays of a fixed size: a new sky (a lookdev edit of the sun) brings
new numbers for the same kernels.

Grid. ``AZIMUTH_CELLS`` = 256 columns at azimuths ``2 pi j / 256`` (1.4 degrees
apart, wrapping) and ``ELEVATION_ROWS`` = 64 rows at elevations ``(pi / 2) (i /
63)^2``: uniform in the square root of the elevation, 0.02 degrees apart at the
horizon, where the sky brightens and reddens fastest, and 2.8 degrees apart at the
zenith, where it changes slowly. Read with bilinear interpolation in (azimuth,
sqrt(elevation)). 256 x 64 nodes of 3 floats are 192 KiB.

Interpolation error, measured against Mitsuba's ``eval`` of the emitter at 100,000
random directions uniform over the upper hemisphere for each of 15 ``sunsky`` skies
(turbidity 2, 3 and 6; sun elevations 5, 15, 33, 60 and 85 degrees; albedo 0.3),
relative, per channel: median 0.02 %, 99th percentile 0.17 % (0.27 % for the worst
sky, turbidity 6 with the sun at 85 degrees), 99.9th percentile 0.31 %; at most
0.81 % further than 5 degrees from the sun, and at most 3.6 % within half a degree
of it, where bilinear interpolation flattens the sky model's circumsolar peak. On
the horizon itself (the background of all downward rays) at most 0.12 %. The
elevation spacing sets the error: 32 rows of the same spacing give a 99th
percentile of 0.69 %, rows uniform in elevation or in its sine 8 to 11 % (and up to
70 %); 512 columns instead of 256 change nothing measurable. A
``constant`` sky is exact; an ``envmap`` is seen blurred to the grid's 1.4
degrees, which suits a background that the haze fades to.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

__all__ = ["SKY_LIGHTS", "AZIMUTH_CELLS", "ELEVATION_ROWS", "sky_lights",
           "row_elevations", "grid_directions", "emitter_radiance", "SkyTable"]

#: Light types that are sky emitters (Mitsuba environment emitters).
SKY_LIGHTS = ("sunsky", "constant", "envmap")
#: Columns over azimuth (wrapping) and rows over elevation [0, 90 degrees].
AZIMUTH_CELLS, ELEVATION_ROWS = 256, 64


def sky_lights(lights) -> list:
    """The sky emitters among a scene's light dicts, without the sun disk.

    Parameters
    ----------
    lights : list of dict
        Mitsuba emitter dicts as built by the scene loader.

    Returns
    -------
    list of dict
        The ``sunsky``, ``constant`` and ``envmap`` lights, a ``sunsky`` with
        ``sun_scale = 0`` (its sun is a light source, not background); empty when
        the scene has no sky.
    """
    return [dict(light, sun_scale=0.0) if light["type"] == "sunsky" else light
            for light in lights if light["type"] in SKY_LIGHTS]


def row_elevations(rows: int = ELEVATION_ROWS) -> np.ndarray:
    """Elevations (radians) of the table's rows: ``(pi / 2) (i / (rows - 1))^2``, 0 to ``pi / 2``."""
    return 0.5 * math.pi * (np.arange(rows) / (rows - 1)) ** 2


def grid_directions(columns: int = AZIMUTH_CELLS, rows: int = ELEVATION_ROWS) -> np.ndarray:
    """Unit directions ``(3, rows * columns)`` of the table's nodes, row-major (azimuth fastest)."""
    el = row_elevations(rows)[:, None]
    az = (2.0 * math.pi / columns) * np.arange(columns)[None, :]
    d = np.stack(np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)))
    return d.reshape(3, -1)


def emitter_radiance(lights, directions) -> np.ndarray:
    """Radiance ``(3, n)`` of the sum of emitter dicts seen in ``directions``, by Mitsuba's ``eval``.

    Parameters
    ----------
    lights : list of dict
        Mitsuba emitter dicts (infinite emitters: the radiance depends on the direction only).
    directions : array_like, shape (3, n)
        World-space directions in which the sky is seen (from the scene towards the sky).

    Returns
    -------
    numpy.ndarray
        ``sum_l L_l(d)`` in float64, what a ray in direction ``d`` that leaves the
        scene receives (an environment emitter reads ``-si.wi``).
    """
    d = np.asarray(directions, np.float64)
    total = np.zeros_like(d)
    for light in lights:
        em = mi.load_dict({"type": "scene", "light": light}).emitters()[0]
        si = dr.zeros(mi.SurfaceInteraction3f, d.shape[1])
        si.wi = -mi.Vector3f(d.astype(np.float32))
        # A constant emitter returns one literal value, not one per direction: broadcast.
        total += np.broadcast_to(np.asarray(em.eval(si), np.float64).reshape(3, -1), d.shape)
    return total


class SkyTable:
    """The sky's radiance on the grid of the module docstring, read by bilinear interpolation.

    Parameters
    ----------
    radiance : array_like, shape (3, ELEVATION_ROWS * AZIMUTH_CELLS)
        RGB radiance at :func:`grid_directions` (row-major, azimuth fastest).

    The values live in one Dr.Jit array of a fixed size: a table with other values
    re-uses the compiled kernels.
    """

    def __init__(self, radiance):
        rgb = np.asarray(radiance, np.float32).reshape(3, ELEVATION_ROWS * AZIMUTH_CELLS)
        # Interleaved (node, channel): one gather of a Color3f reads a node's three values.
        self.values = mi.Float(np.ascontiguousarray(rgb.T).ravel())
        dr.eval(self.values)

    @classmethod
    def for_lights(cls, lights):
        """The table of a scene's light dicts (:func:`sky_lights`), or None without a sky."""
        sky = sky_lights(lights)
        return cls(emitter_radiance(sky, grid_directions())) if sky else None

    def lookup(self, d):
        """``L_bg(d)``: the sky's radiance in direction ``d``, its elevation clamped to >= 0.

        Parameters
        ----------
        d : mi.Vector3f
            Directions (any length > 0).

        Returns
        -------
        mi.Color3f
            Bilinear interpolation of the four nodes around ``(azimuth, sqrt(elevation))``.
        """
        horizontal = dr.sqrt(dr.fma(d.x, d.x, d.y * d.y))
        u = dr.atan2(d.y, d.x) * (AZIMUTH_CELLS / (2.0 * math.pi))
        u = dr.select(u < 0.0, u + AZIMUTH_CELLS, u)              # [0, AZIMUTH_CELLS]
        elevation = dr.atan2(dr.maximum(d.z, 0.0), horizontal)   # [0, pi / 2]
        v = dr.sqrt(elevation * (2.0 / math.pi)) * (ELEVATION_ROWS - 1)
        col = dr.minimum(mi.UInt32(dr.floor(u)), AZIMUTH_CELLS - 1)
        row = dr.minimum(mi.UInt32(dr.floor(v)), ELEVATION_ROWS - 2)
        fu, fv = u - mi.Float(col), dr.minimum(v - mi.Float(row), 1.0)
        col1 = dr.select(col + 1 == AZIMUTH_CELLS, 0, col + 1)   # the azimuth wraps
        at = row * AZIMUTH_CELLS

        def node(r, c):
            return dr.gather(mi.Color3f, self.values, r + c)

        low = dr.lerp(node(at, col), node(at, col1), fu)
        high = dr.lerp(node(at + AZIMUTH_CELLS, col), node(at + AZIMUTH_CELLS, col1), fu)
        return dr.lerp(low, high, fv)
