"""Make the shipped terrain-amplification scenes ``scenes/terrain_<preset>.toml`` from real terrain.

Each scene amplifies a DEM shipped in ``scenes/data/`` (sources and licences in
``scenes/data/DEMS.md``): real USGS elevation or a synthetic DEM that went through
stream-power and thermal erosion (``examples/make_eroded_dems.py``), never a block
of smoothstep plateaus. ``arches-render amplify`` writes the scene with its named
cameras (close shots of the landforms first, then ``overview``), the far field to
the horizon and the water; the scene renders from its first close shot.

``sea``      ``eroded_coast`` (7.7 km at 20 m): an eroded coast -> sea caves, arches
``river``    ``real_nm_canyon_10m`` (5.1 km at 10 m, USGS NED): a canyon -> undercut walls
``karst``    ``eroded_mesas`` (5.8 km at 15 m): a tableland -> tunnels
``hoodoos``  ``eroded_canyon`` (5.1 km at 10 m): canyon slopes -> hoodoo groups
``strata``   ``eroded_mesas`` (5.8 km at 15 m): mesas -> layered cliffs with overhangs

Run from the repository root::

    python examples/make_terrain_scenes.py [PRESET ...] [--out DIR]

The heights and arrays go to ``DIR/data/`` (default ``scenes/``). Everything is seeded.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: preset -> (DEM in scenes/data, cell size in metres)
SOURCES = {"sea": ("eroded_coast.npy", 20.0), "river": ("real_nm_canyon_10m.npy", 10.0),
           "karst": ("eroded_mesas.npy", 15.0), "hoodoos": ("eroded_canyon.npy", 10.0),
           "strata": ("eroded_mesas.npy", 15.0)}


def main(presets, out=REPO / "scenes"):
    for preset in presets:
        dem, cell = SOURCES[preset]
        cmd = [sys.executable, "-m", "arches_render.cli", "amplify", str(REPO / "scenes" / "data" / dem), "-o",
               str(Path(out) / f"terrain_{preset}.toml"), "--preset", preset, "--seed", "7",
               "--cell-size", f"{cell:g}", "--data-dir", "data", "-q"]
        subprocess.run(cmd, check=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    dest = REPO / "scenes"
    if "--out" in args:
        k = args.index("--out")
        dest = Path(args[k + 1])
        del args[k:k + 2]
    main(args or list(SOURCES), dest)
