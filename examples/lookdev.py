"""A lookdev session with the arches-render Python API (run by the tests).

Loads the default scene, renders it, changes the snow line, the rock colour, the
sun and the camera, renders again without recompiling the kernels, writes both
renders as EXR + PNG and compares them::

    python examples/lookdev.py [--resolution 320x180] [--spp 16] [--out out/lookdev]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from arches_render import api

REPO = Path(__file__).resolve().parents[1]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--resolution", default="320x180")
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--out", default="out/lookdev")
    args = p.parse_args()
    w, h = (int(v) for v in args.resolution.split("x"))
    out = Path(args.out)

    look = api.load(REPO / "scenes" / "default.toml", resolution=(w, h), spp=args.spp)
    before = look.render(out / "lookdev_before.exr")
    print(f"first render: {look.compiled} kernels compiled")

    look.set("materials.landscape.snow.height_min", 10.0)      # snow lower down
    look.set("materials.landscape.rock.tint", [0.45, 0.3, 0.22])
    look.set("lights.0.elevation", 12.0)                         # a low evening sun
    look.set("camera.origin", [-55.0, -85.0, 26.0])
    after = look.render(out / "lookdev_after.exr", view="aces")
    print(f"after the edits: {look.compiled} kernels compiled, scene built {look.rebuilds}x")

    result = api.compare(before, after)
    print(result.summary())


if __name__ == "__main__":
    main()
