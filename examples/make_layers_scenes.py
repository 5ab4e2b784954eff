"""Write the DEMs of the layered-terrain scenes (``scenes/data/layers_*.npy``).

    python examples/make_layers_scenes.py

A cliff or mesa drawn as a heightfield (no overhangs: the stack tools make those), its
edge roughened by smooth noise so the walls are not ruled. Deterministic (fixed seeds).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

DATA = Path(__file__).resolve().parents[1] / "scenes" / "data"


def _noise(shape, scale, seed):
    f = gaussian_filter(np.random.default_rng(seed).normal(size=shape), scale, mode="reflect")
    return f / f.std()


def plateau(shape, extent, edge, top, seed, x_sides=False):
    """Heights: a plateau of height ``top`` beyond a noisy edge line, ground 0 before it.

    ``edge(x, y) > 0`` on the plateau; the wall is about one metre wide (smoothstep).
    """
    ny, nx = shape
    x0, y0, x1, y1 = extent
    X, Y = np.meshgrid(np.linspace(x0, x1, nx), np.linspace(y0, y1, ny))
    d = edge(X, Y) + 1.2 * _noise(shape, 10, seed) + 0.4 * _noise(shape, 3, seed + 1)
    t = np.clip(d / 1.0 + 0.5, 0.0, 1.0)
    h = top * t * t * (3 - 2 * t) + 0.6 * _noise(shape, 6, seed + 2) * t
    return h + 0.08 * _noise(shape, 2, seed + 3)


def main():
    DATA.mkdir(parents=True, exist_ok=True)
    # Sea cliff: plateau for x > 16 (extent [-8, -16, 40, 16], 0.2 m samples).
    H = plateau((161, 241), (-8.0, -16.0, 40.0, 16.0), lambda x, y: x - 16.0, 11.0, seed=5)
    np.save(DATA / "layers_sea_cliff_beach.dem.npy", H.astype(np.float32))
    # Mesa for the tunnel: a block x in [3, 25], all across y.
    H = plateau((161, 241), (-16.0, -16.0, 32.0, 16.0), lambda x, y: np.minimum(x - 3.0, 25.0 - x), 9.5, seed=9)
    np.save(DATA / "layers_tunnel_rockfall.dem.npy", H.astype(np.float32))


if __name__ == "__main__":
    main()
