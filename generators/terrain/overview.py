"""The overview camera of an amplified terrain: where a landscape photographer stands (issue 34).

:func:`frame_camera` aims at the landforms the presets made from their downhill side,
low, the horizon or a skyline under sky in the frame; an isolated landform (a volcanic
cone, a butte: :func:`landform_view`) is the subject, framed whole from over the tile.
:mod:`.scene_writer` writes the result as the scene's ``overview`` camera.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .continued_relief import ContinuedRelief

__all__ = ["frame_camera", "landform_view", "LandformView", "LANDFORM_LEVEL", "LANDFORM_FILL",
           "LANDFORM_CLEARANCE", "TILE_INSET"]


def frame_camera(heights, extent, features=None, fov=50.0, elevation=10.0, margin=0.5, aspect=16 / 9,
                 sea_level=None, context=None):
    """A landscape photographer's overview: the features seen from their downhill side, the
    horizon in the frame.

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
        How far the camera looks down at the target (it stands this many degrees above
        it): below half the vertical field of view (14.7 degrees at 50 degrees across a
        16:9 frame), the horizon is in the frame, with sky above it.
    margin : float
        Distance factor: the camera stands ``margin`` times the distance at which the
        features' extent fills the frame's width.
    aspect : float
        The frame's width over its height.
    sea_level : float, optional
        The far field's sea level, where the sea reaches the tile's border (its ground
        past the tile is held to the border's sea and land: :class:`.ContinuedRelief`).
    context : (numpy.ndarray, tuple), optional
        ``(heights, extent)`` of the DEM the tile was refined from (:mod:`.refined_crop`):
        the ground around the tile, which the far field shows, instead of its continuation.

    Returns
    -------
    dict
        ``origin``, ``target`` (the point on the view's axis, which tilts up from the
        features where relief rises behind them), ``fov`` and ``azimuth`` (degrees, of
        the view direction from the camera towards the target).

    Notes
    -----
    The camera stands *downhill* of the target (the direction of the regional
    slope, a Gaussian-smoothed gradient over an eighth of the tile): cliffs,
    cave mouths and canyon walls face downhill, and a canyon is seen along its
    course. On flat ground it stands on the tile's lowest side.

    Low and close, as a photographer stands (issue 34): the default 10 degrees and half
    the framing distance put the landforms in the foreground and middle distance with
    the relief receding to a horizon in haze. Where the target lies on an isolated
    landform the camera steps back out of it and aims at its centre (:func:`landform_view`).
    The aerial view it replaced (16-32 degrees by preset, from 1.2 times the framing
    distance) showed the tile from above as a model on a table, its edges and the far
    field around it in view.

    Sky over the relief: where ground ahead rises over the line 15 % of the frame's
    height under its top, the view tilts up, as far as keeps the features over the line
    15 % above its bottom, and only then do camera and aim rise together.
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
    landform = landform_view(H, extent, target, az, fov)
    if landform is not None:
        # The landform is the subject: aimed at its centre and middle height (a crater's
        # floor hides behind its rim), from where it fills the frame. The features' own
        # framing distance stood off the tile where they spread past the landform (a
        # small cone's overview showed the far field's plain, the cone at the edge).
        target[:2] = landform.centre
        dist = landform.distance
        target[2] = max(target[2], landform.height)
    if context is not None:
        # A refined crop: the ground past the tile is the coarse DEM, whose facets in the
        # foreground read as a seam; the camera stays over the tile, as landform_view's does.
        dist = min(dist, TILE_INSET * _to_border(target, az, extent))
    el = math.radians(elevation)
    origin = target + dist * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    # Keep the camera above the ground under it (clamped lookup for points off the tile).
    i = int(np.clip(round((origin[0] - x0) / dx), 0, nx - 1))
    j = int(np.clip(round((origin[1] - y0) / dy), 0, ny - 1))
    origin[2] = max(origin[2], H[j, i] + 0.1 * (zhi - zlo) + 1.0)
    # Sky above the relief, the target in the frame: the ground ahead, the tile's or the
    # far field's (ContinuedRelief, unblurred: at least as high), stays below the line
    # 15 % of the frame's height under its top, the target above the line 15 % over its
    # bottom. The view tilts up towards the relief first (a mountain behind a coast: the
    # shore low in the frame, the slope rising behind it, sky above); what tilting cannot
    # clear raises camera and target together. Raising alone, the pitch kept, lifted a
    # coast's camera 1.1 km over the mountain behind it, looking down a slope in haze.
    vfov2 = math.atan(math.tan(math.radians(fov) / 2) / aspect)
    band = 0.7 * vfov2  # from the frame's middle to either line
    s = np.linspace(0.02, 3.0, 300)[:, None] * math.hypot(x1 - x0, y1 - y0)
    turns = np.radians(np.linspace(-0.5 * fov, 0.5 * fov, 5))
    ahead = az + math.pi + turns  # from the camera towards the target, across the frame
    qx = origin[0] + s * np.cos(ahead)[None]
    qy = origin[1] + s * np.sin(ahead)[None]
    around = ContinuedRelief(*(context or (H, extent)), sea_level)
    ground = around.heights(qx.ravel(), qy.ravel(), 0.0).reshape(qx.shape)
    aim = math.atan2(target[2] - origin[2], math.hypot(*(target - origin)[:2]))  # about -el
    # (the top line never below the horizontal: ground kilometres away would lift the camera
    # without end where a steep aim, under two bands, put it there)
    top = min(max(2.0 * band + aim, 0.0), 1.5)
    rise = max(float(np.max(ground - s * math.tan(top) - origin[2])), 0.0)
    origin[2] += rise
    target = target + np.array([0.0, 0.0, rise])
    pitch = max(aim, float(np.max(np.arctan2(ground - origin[2], s))) - band)
    look = az + math.pi
    target = origin + float(np.linalg.norm(target - origin)) * np.array(
        [math.cos(pitch) * math.cos(look), math.cos(pitch) * math.sin(look), math.sin(pitch)])
    view = target - origin
    return dict(origin=[float(v) for v in origin], target=[float(v) for v in target], fov=float(fov),
                azimuth=math.degrees(math.atan2(view[1], view[0])))


#: The level, as a fraction of the tile's relief, above which the ground around the target
#: is a landform the overview frames from outside (:func:`landform_view`).
LANDFORM_LEVEL = 0.5

#: How much of the frame's width an isolated landform's footprint spans at the target.
LANDFORM_FILL = 0.9

#: How far past the landform's footprint the camera stands, as a fraction of its distance.
LANDFORM_CLEARANCE = 0.15

#: The camera stays over the tile: at most this fraction of the way to its border.
TILE_INSET = 0.95


def landform_view(heights, extent, target, azimuth, fov):
    """How far from ``target`` along ``azimuth`` an overview frames the isolated landform
    the target lies on, and at what height it aims; ``None`` where it lies on none.

    The landform is the ground above :data:`LANDFORM_LEVEL` of the tile's relief that
    holds the target's cell, with its enclosed hollows (a crater, a caldera) counted in;
    it is *isolated* when it does not reach the tile's border (a volcanic cone, a
    butte, an island). A photographer frames such a landform whole, from outside it:
    at half the framing distance of its features the overview of a 600 m volcano stood
    on its flank, the rim in front hiding the crater. So the camera stands where the
    footprint's equivalent disc spans :data:`LANDFORM_FILL` of the frame's width, and
    past the footprint's far edge along ``azimuth`` by :data:`LANDFORM_CLEARANCE`; never
    past :data:`TILE_INSET` of the way to the tile's border (the far field in the
    foreground reads as a seam). Relief that runs off the tile (a range, a plateau cut
    by canyons) has no outside to stand on and is left to the features' framing.

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` elevations over ``extent``.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)``.
    target : sequence of 3 floats
        The point the overview looks at.
    azimuth : float
        Direction from the target towards the camera, radians.
    fov : float
        Horizontal field of view, degrees.

    Returns
    -------
    LandformView or None
        The distance in metres from the footprint's centre (its centroid), the
        median height of the footprint (where a crater's floor, hidden behind its
        rim from a low camera, does not pull the aim down) and that centre.
    """
    from scipy.ndimage import binary_fill_holes, label
    H = np.asarray(heights, dtype=np.float64)
    ny, nx = H.shape
    x0, y0, x1, y1 = extent
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    zlo, zhi = float(H.min()), float(H.max())
    i, j = int(round((target[0] - x0) / dx)), int(round((target[1] - y0) / dy))
    if not (zhi > zlo and 0 <= i < nx and 0 <= j < ny):
        return None
    labels, _ = label(binary_fill_holes(H >= zlo + LANDFORM_LEVEL * (zhi - zlo)))
    own = labels[j, i]
    border = np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])
    if own == 0 or np.any(border == own):
        return None
    footprint = labels == own
    rows, cols = np.nonzero(footprint)
    centre = (x0 + float(cols.mean()) * dx, y0 + float(rows.mean()) * dy)
    radius = math.sqrt(len(rows) * dx * dy / math.pi)
    dist = radius / (LANDFORM_FILL * math.tan(math.radians(fov) / 2))
    # From the centre, the footprint's far edge along the azimuth (samples half a cell
    # apart), and the tile's.
    c, s_ = math.cos(azimuth), math.sin(azimuth)
    to_border = _to_border(centre, azimuth, extent)
    s = np.arange(0.0, to_border, 0.5 * min(dx, dy))
    on = labels[np.clip(np.round((centre[1] + s * s_ - y0) / dy).astype(int), 0, ny - 1),
                np.clip(np.round((centre[0] + s * c - x0) / dx).astype(int), 0, nx - 1)] == own
    edge = float(s[np.flatnonzero(on)[-1]]) if on.any() else 0.0
    return LandformView(min(max(dist, edge * (1.0 + LANDFORM_CLEARANCE)), TILE_INSET * to_border),
                        float(np.median(H[footprint])), centre)


class LandformView(NamedTuple):
    """An isolated landform's framing (:func:`landform_view`)."""

    distance: float  #: metres from ``centre`` to the camera's ground position
    height: float  #: the footprint's median height, where the camera aims
    centre: tuple  #: ``(x, y)``, the footprint's centroid


def _to_border(target, azimuth, extent) -> float:
    """Distance from ``target`` (inside ``extent``) along ``azimuth`` (radians) to the tile's border."""
    x0, y0, x1, y1 = extent
    c, s = math.cos(azimuth), math.sin(azimuth)
    return min((x1 - target[0]) / c if c > 0 else (x0 - target[0]) / c if c < 0 else np.inf,
               (y1 - target[1]) / s if s > 0 else (y0 - target[1]) / s if s < 0 else np.inf)
