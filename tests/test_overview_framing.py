"""The overview's framing of an isolated landform (issue 34): a photographer stands
outside a volcanic cone and frames it whole, not on its flank with the rim hiding the
crater; relief that runs off the tile keeps the features' framing."""

from __future__ import annotations

import math

import numpy as np

from arches_render.generators.terrain.overview import (LANDFORM_FILL, LANDFORM_LEVEL, TILE_INSET, frame_camera,
                                                       landform_view)

EXTENT = (-500.0, -400.0, 500.0, 400.0)


def _grid(cell=10.0):
    x0, y0, x1, y1 = EXTENT
    X, Y = np.meshgrid(np.arange(x0, x1 + cell / 2, cell), np.arange(y0, y1 + cell / 2, cell))
    return X, Y


def _cone_with_crater():
    """A cone 100 m high and 600 m across on a plain, with a crater 160 m across whose
    floor (30 m) lies below half the relief: only its rim holds it in the landform."""
    X, Y = _grid()
    r = np.hypot(X + 100.0, Y)
    H = np.clip(100.0 * (1.0 - r / 300.0), 0.0, None)
    return np.where(r < 80.0, 30.0 + 60.0 * (r / 80.0) ** 4, H).astype(np.float32)


def _height_at(H, x, y):
    j = int(round((y - EXTENT[1]) / 10.0))
    i = int(round((x - EXTENT[0]) / 10.0))
    return float(H[j, i])


def test_an_isolated_cone_is_framed_whole_from_outside_its_footprint():
    H = _cone_with_crater()
    crater = np.array([[-100.0 + 30.0 * math.cos(a), 30.0 * math.sin(a), 30.0] for a in np.linspace(0, 6, 12)])
    cam = frame_camera(H, EXTENT, crater)
    origin, target = np.asarray(cam["origin"]), np.asarray(cam["target"])
    # The camera's ground lies off the cone (below the landform's level), and over the tile.
    level = float(H.min()) + LANDFORM_LEVEL * float(H.max() - H.min())
    assert _height_at(H, origin[0], origin[1]) < level, cam
    x0, y0, x1, y1 = EXTENT
    assert x0 < origin[0] < x1 and y0 < origin[1] < y1, cam
    # It aims at the cone's middle height, not at the crater floor behind the rim.
    X, Y = _grid()
    footprint = (H >= level) | (np.hypot(X + 100.0, Y) < 80.0)  # the crater counted in
    assert target[2] >= np.median(H[footprint]) - 1e-3, cam
    # Far enough to frame it whole (the footprint's disc within the frame's width), or
    # as far as the tile allows; 0.95: this footprint's cells on the level line differ
    # from the filled one's (3 % of the disc's radius here).
    radius = math.sqrt(np.count_nonzero(footprint) * 100.0 / math.pi)
    dist = float(np.hypot(*(origin - target)[:2]))
    assert dist >= 0.95 * min(radius / (LANDFORM_FILL * math.tan(math.radians(cam["fov"]) / 2)),
                              TILE_INSET * _to_border(target, origin)), (dist, radius, cam)
    # With the features' framing alone (half the distance that fits them) it stood on the flank.
    near = 0.5 * 0.3 * 0.5 * math.hypot(x1 - x0, y1 - y0) / math.tan(math.radians(25.0))
    assert dist > 1.5 * near, (dist, near)


def _to_border(target, origin):
    x0, y0, x1, y1 = EXTENT
    d = (origin - target)[:2]
    d = d / np.linalg.norm(d)
    ts = [((x1 if d[0] > 0 else x0) - target[0]) / d[0], ((y1 if d[1] > 0 else y0) - target[1]) / d[1]]
    return min(t for t in ts if t > 0)


def test_relief_that_runs_off_the_tile_keeps_the_features_framing():
    X, Y = _grid()
    ridge = (120.0 * np.exp(-(Y / 150.0) ** 2)).astype(np.float32)  # a ridge along x, off both ends
    assert landform_view(ridge, EXTENT, (0.0, 0.0, 120.0), 1.0, 50.0) is None
    # A target on the plain beside a cone: no landform under it.
    H = _cone_with_crater()
    assert landform_view(H, EXTENT, (350.0, 300.0, 0.0), 1.0, 50.0) is None
    # On the cone: a distance and a height.
    view = landform_view(H, EXTENT, (-100.0, 0.0, 30.0), 1.0, 50.0)
    assert view is not None and view[0] > 0.0 and view[1] > 30.0, view


def test_features_spread_past_an_isolated_cone_leave_it_the_subject_framed_from_over_the_tile():
    # A cone in the tile's west half, features (a river's primitives, say) scattered round
    # it and far past it, their centroid on its flank: the overview aims at the cone's
    # centre, from over the tile. It used to aim at the features' centroid from the
    # features' own framing distance, off the tile over the far field's plain: a small
    # volcano's overview was a green plain with the cone at its edge.
    X, Y = _grid()
    centre = np.array([-250.0, 0.0])
    H = np.clip(100.0 * (1.0 - np.hypot(X - centre[0], Y - centre[1]) / 200.0), 0.0, None).astype(np.float32)
    rng = np.random.default_rng(2)
    spread = np.column_stack([rng.uniform(-120.0, 280.0, 60) - 250.0 + 50.0, rng.uniform(-350.0, 350.0, 60) + 50.0,
                              np.full(60, 40.0)])
    spread[:, :2] -= spread[:, :2].mean(axis=0) - (centre + [50.0, 50.0])  # the centroid on the flank
    cam = frame_camera(H, EXTENT, spread)
    origin, target = np.asarray(cam["origin"]), np.asarray(cam["target"])
    assert np.linalg.norm(target[:2] - centre) < 10.0, cam
    x0, y0, x1, y1 = EXTENT
    assert x0 < origin[0] < x1 and y0 < origin[1] < y1, cam
    assert _height_at(H, origin[0], origin[1]) < 50.0, cam  # outside the cone's footprint


def test_a_coast_under_a_mountain_is_seen_from_low_over_the_sea_with_the_slope_rising_under_the_sky():
    # The sea in the south, a 1.5 km mountain behind the coast. The overview tilts up
    # towards the slope: the camera stays low, the coast low in the frame and the ridge
    # under its top 15 %. It used to rise with its target, the pitch kept, until no ground
    # stood over the frame's top line: 1.2 km up, looking down a slope in haze.
    cell = 100.0
    extent = (-5000.0, -5000.0, 5000.0, 5000.0)
    x = np.arange(-5000.0, 5000.0 + cell / 2, cell)
    X, Y = np.meshgrid(x, x)
    H = np.where(Y < -1000.0, -40.0, 1500.0 * np.clip((Y + 1000.0) / 4000.0, 0.0, 1.0) ** 0.7
                 + 80.0 * np.sin(X / 700.0)).astype(np.float32)
    coast = np.column_stack([np.linspace(-3000.0, 3000.0, 30), np.full(30, -950.0), np.full(30, 10.0)])
    cam = frame_camera(H, extent, coast, sea_level=0.0)
    origin, target = np.asarray(cam["origin"]), np.asarray(cam["target"])
    assert origin[2] < 600.0, cam
    vfov2 = math.atan(math.tan(math.radians(cam["fov"]) / 2) * 9 / 16)
    axis = target - origin
    pitch = math.atan2(axis[2], math.hypot(*axis[:2]))

    def angle(p):  # elevation of a point over the frame's middle, along the view's vertical
        d = np.asarray(p, float) - origin
        return math.atan2(d[2], float(np.dot(d[:2], axis[:2])) / math.hypot(*axis[:2])) - pitch

    # The coast in the frame, in its lower part.
    assert -0.85 * vfov2 <= angle(coast.mean(axis=0)) < 0.0, cam
    # Every ground sample ahead of the camera (within the frame's width) under the top line.
    u = axis[:2] / math.hypot(*axis[:2])
    along = (X - origin[0]) * u[0] + (Y - origin[1]) * u[1]
    across = (Y - origin[1]) * u[0] - (X - origin[0]) * u[1]
    ahead = (along > 0) & (np.abs(across) < along * math.tan(math.radians(20)))
    rise = np.degrees(np.arctan2(H[ahead] - origin[2], along[ahead]))
    assert rise.max() <= math.degrees(pitch + 0.7 * vfov2) + 0.5, (rise.max(), cam)
