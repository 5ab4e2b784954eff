"""The erosion tool: bedrock turned into sand and rocks (Peytavie et al. 2009, 4.4, figs. 15-16).

The tool has a region of influence ``R`` (here an ellipsoid: centre and three
radii, optionally roughened by seeded value noise so that scars are not spheres)
and a ratio ``0 <= rho <= 1``, the relative volume of rocks among the eroded
material. Two strategies, as in the paper:

* ``surface`` (progressive surface erosion): only the bedrock inside ``R`` within
  ``depth`` of air along the stack axis (the surface layers) becomes sand;
* ``collapse`` (rocks detaching along internal joints): all the bedrock of the
  stacks inside ``R`` becomes granular, a share ``rho`` of each stack's eroded run
  as rocks and ``1 - rho`` as sand.

Volume is conserved (no bulking): each eroded quantum of bedrock becomes one
quantum of sand or rock. The transport is left to the stabilization step ("the
stabilization of material layers performs the transport of the eroded materials"),
which drops the debris to the floor of its section and lets it flow out into piles.
The paper's ``sigma`` (rock size) belongs to rock instancing and is not used here.
"""

from __future__ import annotations

import numpy as np

from .editing import Region, axis_mask, value_noise
from .material_stacks import AIR, BEDROCK, ROCK, SAND, SANDSTONE, MaterialStacks

STABLE_ROCK = (BEDROCK, SANDSTONE)


def erode(stacks: MaterialStacks, center, radius, rho=0.5, mode="collapse", depth=None,
          roughness=0.0, seed=0):
    """Turn bedrock inside the region into granular material.

    Parameters
    ----------
    stacks : MaterialStacks
    center : sequence of 3 floats
    radius : float or sequence of 3 floats
        Radii of the ellipsoid (> 0).
    rho : float
        Relative volume of rocks in ``[0, 1]`` (``collapse``; ``surface`` makes sand).
    mode : {'collapse', 'surface'}
    depth : float, optional
        ``surface``: thickness eroded below the air (default one cell size).
    roughness : float
        Relative noise on the region's radius, in ``[0, 0.9]``.
    seed : int

    Returns
    -------
    (MaterialStacks, int)
        The stacks and the number of eroded quanta.
    """
    if mode not in ("collapse", "surface"):
        raise ValueError(f"erosion mode must be 'collapse' or 'surface' (got {mode!r})")
    if not 0.0 <= float(rho) <= 1.0:
        raise ValueError(f"erosion rho must be in [0, 1] (got {rho})")
    if not 0.0 <= roughness <= 0.9:
        raise ValueError(f"erosion roughness must be in [0, 0.9] (got {roughness})")
    radii = np.broadcast_to(np.asarray(radius, dtype=np.float64), (3,))
    if not np.all(radii > 0):
        raise ValueError(f"erosion radius must be > 0 (got {radius})")
    c = np.asarray(center, dtype=np.float64).reshape(3)
    reach = radii * (1 + roughness)
    region = Region(stacks, c - reach, c + reach)
    if region.empty:
        return stacks.copy(), 0
    noise_wl = max(radii.min() / 1.5, stacks.cell)

    def inside_fn(P):
        r = np.sqrt((((P - c) / radii) ** 2).sum(-1))
        if roughness > 0:
            r = r / (1.0 + roughness * value_noise(P, noise_wl, seed))
        return r < 1.0

    inside = axis_mask(stacks, region, inside_fn)
    current = stacks.dense_columns(region.cols, region.lev0, region.n)
    rock = inside & np.isin(current, STABLE_ROCK)
    if mode == "surface":
        d = max(1, int(round((stacks.cell if depth is None else float(depth)) / stacks.dz)))
        near_air = _near_air(stacks, region, current, d)
        rock &= near_air
        block = np.where(rock, SAND, -1).astype(np.int16)
        return stacks.rewrite(region.cols, region.lev0, block), int(rock.sum())
    # Per stack, the lowest (1 - rho) of its eroded quanta become sand, the rest rock
    # (sorting then stacks the rocks over the sand, section 3.4).
    rank = np.cumsum(rock, axis=1)
    total = rock.sum(axis=1, keepdims=True)
    n_sand = np.rint((1.0 - float(rho)) * total)
    block = np.full(rock.shape, -1, dtype=np.int16)
    block[rock & (rank <= n_sand)] = SAND
    block[rock & (rank > n_sand)] = ROCK
    return stacks.rewrite(region.cols, region.lev0, block), int(rock.sum())


def _near_air(stacks, region, current, d):
    """Levels within ``d`` quanta (along the axis) of air, including air just outside the window."""
    lo = max(0, region.lev0 - d)
    hi = min(stacks.n_levels, region.lev0 + region.n + d)
    wide = stacks.dense_columns(region.cols, lo, hi - lo) == AIR
    # The sky above each stack's top is air too (dense_columns pads it as 0 = air).
    from scipy.ndimage import maximum_filter1d
    near = maximum_filter1d(wide.astype(np.uint8), size=2 * d + 1, axis=1) > 0
    a = region.lev0 - lo
    return near[:, a:a + region.n]
