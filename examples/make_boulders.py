"""Write scenes/data/boulders.npz: 2,000 boulders scattered on the boulders scene's terrain.

The arrays (``a``, ``b``, ``radius``) feed a ``capsule_set`` node. Positions are
seeded, so the file is reproducible: ``python examples/make_boulders.py``.
"""

from pathlib import Path

import numpy as np


def main(seed: int = 12, count: int = 2000) -> None:
    from arches_render.field.heightmaps import fbm_heightmap

    extent = (-40.0, -40.0, 40.0, 40.0)
    heights = fbm_heightmap(extent, (161, 161), amplitude=4.0, wavelength=30.0, octaves=5, seed=8)
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-32.0, 32.0, (count, 2))
    radius = 0.25 + 0.9 * rng.power(0.35, count)[::-1] ** 2
    ix = ((xy - extent[0]) / (extent[2] - extent[0]) * 160).astype(int)
    z = heights[ix[:, 1], ix[:, 0]]
    # Centres sit 0.35 r above the ground: boulders are about two thirds buried.
    # Some are elongated along a random, mostly horizontal axis.
    centre = np.c_[xy, z + radius * 0.35]
    axis = rng.normal(size=(count, 3)) * radius[:, None] * rng.uniform(0.0, 0.8, (count, 1))
    axis[:, 2] *= 0.3
    a, b = centre - axis / 2, centre + axis / 2
    out = Path(__file__).resolve().parents[1] / "scenes" / "data" / "boulders.npz"
    np.savez_compressed(out, a=a.astype(np.float32), b=b.astype(np.float32),
                        radius=radius.astype(np.float32))
    print(f"wrote {out} ({count} boulders)")


if __name__ == "__main__":
    main()
