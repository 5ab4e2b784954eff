"""Make the shipped terrain-amplification scenes ``scenes/terrain_<preset>.toml``.

Each scene is a small synthetic DEM (about 100 x 100 m at 1 m) made for one preset
of ``arches-render amplify`` and amplified by the command itself:

``sea``      a cliffed plateau with a narrow headland into the sea (-> sea caves, arch)
``river``    a plateau cut by a meandering slot canyon (-> undercut walls)
``karst``    a plateau with sinkholes ending in a cliff (-> tunnels opening on the cliff)
``hoodoos``  an amphitheatre with talus slopes (-> hoodoos)
``strata``   a mesa with steep walls (-> layered, folded, faulted cliffs)

Run from the repository root::

    python examples/make_terrain_scenes.py [PRESET ...]

The scenes' heights and arrays go to ``scenes/data/`` (``--data-dir data``); the
input DEMs are temporary (the heights file holds them). Everything is seeded.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
N = 97  # samples per side (96 m at 1 m)


def _grid():
    x = np.linspace(-48.0, 48.0, N)
    return np.meshgrid(x, x)


def _smooth(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _noise(seed, amp, scale=8.0):
    from scipy.ndimage import gaussian_filter
    r = np.random.default_rng(seed).normal(size=(N, N))
    r = gaussian_filter(r, scale)
    return amp * r / r.std()


def sea():
    X, Y = _grid()
    # Coast along y = -5 (land to +y); a headland: a neck 7 m wide, then a stack 18 m wide.
    land = _smooth((Y + 5.0) / 3.0)
    neck = _smooth((3.5 - np.abs(X + 6.0)) / 2.0) * _smooth((Y + 20.0) / 3.0)
    stack = _smooth((9.0 - np.hypot(X + 6.0, Y + 27.0)) / 2.5)
    m = np.maximum(np.maximum(land, neck), stack) * _smooth((40.0 - np.abs(X)) / 6.0)
    return -4.0 + 26.0 * m + _noise(1, 0.6) * m + 0.8 * _noise(2, 1.0, 3.0) * m


def river():
    X, Y = _grid()
    centre = 12.0 * np.sin(Y / 14.0)
    d = np.abs(X - centre)
    canyon = _smooth((d - 7.0) / 2.0)
    return 2.0 + 0.08 * (Y + 48.0) + 26.0 * canyon + _noise(3, 0.8) * canyon


def karst():
    X, Y = _grid()
    plateau = 8.0 + 30.0 * _smooth((X + 20.0) / 4.0)  # cliff at x = -20, plateau to +x
    sinks = sum(3.5 * np.exp(-((X - cx) ** 2 + (Y - cy) ** 2) / 18.0)
                for cx, cy in ((5.0, -15.0), (20.0, 12.0), (-2.0, 20.0)))
    return plateau - sinks * _smooth((X + 12.0) / 4.0) + _noise(4, 0.5)


def hoodoos():
    X, Y = _grid()
    r = np.hypot(X, Y + 20.0)
    bowl = 30.0 * _smooth((r - 14.0) / 40.0) ** 1.2
    return bowl + _noise(5, 1.2, 4.0)


def strata():
    X, Y = _grid()
    r = np.maximum(np.abs(X + 4.0) / 1.3, np.abs(Y - 6.0))
    return 3.0 + 34.0 * _smooth((26.0 - r) / 9.0) + _noise(6, 0.6)


DEMS = {"sea": sea, "river": river, "karst": karst, "hoodoos": hoodoos, "strata": strata}


def main(presets):
    import tempfile
    (REPO / "scenes" / "data").mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for preset in presets:
            dem = Path(tmp) / f"terrain_{preset}.npy"
            np.save(dem, DEMS[preset]().astype(np.float32))
            cmd = [sys.executable, "-m", "arches_render.cli", "amplify", str(dem), "-o",
                   str(REPO / "scenes" / f"terrain_{preset}.toml"), "--preset", preset, "--seed", "7",
                   "--cell-size", "1", "--data-dir", "data", "-q"]
            subprocess.run(cmd, check=True)


if __name__ == "__main__":
    main(sys.argv[1:] or list(DEMS))
