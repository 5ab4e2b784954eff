"""The overview's framing of an isolated landform (issue 34): a photographer stands
outside a volcanic cone and frames it whole, not on its flank with the rim hiding the
crater; relief that runs off the tile keeps the features' framing."""

from __future__ import annotations

import math

import numpy as np

from arches_render.generators.terrain.scene_writer import (LANDFORM_FILL, LANDFORM_LEVEL, TILE_INSET, frame_camera,
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
