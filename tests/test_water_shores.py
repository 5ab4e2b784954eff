"""Water surfaces meet their shores and never stand in the air (issue 34): a lake filled
to its spill point ends at the low point of its rim, where the ground past it falls away."""

from __future__ import annotations

import numpy as np

from arches_render.generators.terrain.hydrology import fill_depressions
from arches_render.generators.terrain.water import find_water, water_mesh

EXTENT = (-1.0, -1.0, 1.0, 1.0)


def _covered_cells(mesh, shape):
    """``(ny - 1, nx - 1)`` level of the water quad over each DEM cell (NaN: dry)."""
    ny, nx = shape
    dx, dy = 2.0 / (nx - 1), 2.0 / (ny - 1)
    out = np.full((ny - 1, nx - 1), np.nan)
    V, F = mesh.vertices, mesh.faces.reshape(-1, 2, 3)
    for quad in F[:, 0]:
        (xa, ya, z), (xb, _, _), _ = V[quad]
        j = int(round((ya + 1.0) / dy))
        out[j, int(round((xa + 1.0) / dx)):int(round((xb + 1.0) / dx))] = z
    return out


def test_a_lake_at_its_spill_point_does_not_spill_its_surface_past_the_rim():
    # A valley dammed across its lower end fills to the dam's lowest point; past the dam
    # the valley falls on. The lake grew a cell into every neighbour, over the dam's low
    # point onto the ground below it: a sheet of water in the air (a crater lake of the
    # Maunga Whau DEM showed it as dark shards past its rim).
    x = np.linspace(-1.0, 1.0, 64)
    X, Y = np.meshgrid(x, x)
    V = 50.0 * np.abs(X) + 30.0 * Y + 25.0 * np.exp(-((Y + 0.6) / 0.05) ** 2)
    w = find_water(V, None)
    assert len(w.lakes) == 1
    level = w.lakes[0][0]
    wet = np.isfinite(w.level)
    assert level == fill_depressions(V)[wet].max()  # filled to its spill point
    cells = _covered_cells(water_mesh(w, EXTENT), V.shape)
    corners = np.stack([V[:-1, :-1], V[:-1, 1:], V[1:, :-1], V[1:, 1:]])
    corner_wet = np.stack([wet[:-1, :-1], wet[:-1, 1:], wet[1:, :-1], wet[1:, 1:]])
    covered = np.isfinite(cells)
    # No water over a corner of dry ground below it: outside the lake, water lies under
    # the ground (its shore) or nowhere.
    assert not np.any(covered & np.any(~corner_wet & (corners < cells), axis=0))
    # The lake itself is covered, and its surface reaches its shore: every cell with a
    # lake corner and no dry corner below the level, and the shore's cells beside them.
    inside = np.any(corner_wet, axis=0) & ~np.any(~corner_wet & (corners < level), axis=0)
    assert np.all(covered[inside]) and np.all(cells[covered] == level)
    assert covered.sum() > inside.sum()
