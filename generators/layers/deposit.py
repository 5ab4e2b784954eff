"""The granular deposit brush (Peytavie et al. 2009, section 4.3, figure 13).

A brush of region ``R`` (a disc of radius ``R`` around ``(x, y)``) drops granular
material with the distribution ``amount * g(r)``, ``g(r) = (1 - (r/R)^2)^2`` (the
falloff of the point primitive of section 4.1), from the height ``z`` (default: the
top of the grid). In every stack the material lands on the first solid floor below
``z`` (on a cave floor when ``z`` is inside the cave), filling the air there; it is
then left to :mod:`~.stabilization` ("we invoke the stabilization kernel to
stabilize the modified material stacks"). Thicknesses are rounded to the stacks'
quantum ``dz``; the dropped mass, in quanta, is returned exactly.
"""

from __future__ import annotations

import numpy as np

from .editing import Region, falloff, landing_levels
from .material_stacks import GRANULAR, MATERIAL_NAMES, MaterialStacks, material_id


def deposit(stacks: MaterialStacks, center, radius, amount, material="sand", z=None):
    """Drop granular material with the brush.

    Parameters
    ----------
    stacks : MaterialStacks
    center : sequence of 2 floats
        Brush centre ``(x, y)``.
    radius : float
        Brush radius ``R`` (> 0).
    amount : float
        Thickness dropped at the centre, in metres (> 0).
    material : str
        A granular material (``sand`` or ``rock``).
    z : float, optional
        Drop height; default the top of the grid.

    Returns
    -------
    (MaterialStacks, int)
        The stacks and the number of quanta deposited (mass added, in ``dz s^2`` units).
    """
    mat = material_id(material)
    if mat not in GRANULAR:
        raise ValueError(f"deposit material must be granular ({', '.join(MATERIAL_NAMES[m] for m in GRANULAR)}; "
                         f"got {material!r})")
    R = float(radius)
    if not R > 0 or not float(amount) > 0:
        raise ValueError(f"deposit radius and amount must be > 0 (got {radius}, {amount})")
    z0, z1 = stacks.z_range
    z = z1 if z is None else float(z)
    cx, cy = (float(v) for v in center)
    region = Region(stacks, (cx - R, cy - R, z0), (cx + R, cy + R, z1))
    if region.empty:
        return stacks.copy(), 0
    r = np.hypot(region.x - cx, region.y - cy)
    want = np.rint(float(amount) * falloff(r, R) / stacks.dz).astype(np.int64)
    lev = int(np.clip(np.floor((z - z0) / stacks.dz), 0, stacks.n_levels - 1))
    floor, ceil = landing_levels(stacks, region.cols, lev)
    take = np.clip(np.minimum(want, ceil - floor), 0, None)
    keep = take > 0
    if not keep.any():
        return stacks.copy(), 0
    cols, floor, take = region.cols[keep], floor[keep], take[keep]
    lev0 = int(floor.min())
    n = int((floor + take).max()) - lev0
    block = np.full((len(cols), n), -1, dtype=np.int16)
    idx = np.arange(n)[None, :] + lev0
    block[(idx >= floor[:, None]) & (idx < (floor + take)[:, None])] = mat
    return stacks.rewrite(cols, lev0, block), int(take.sum())
