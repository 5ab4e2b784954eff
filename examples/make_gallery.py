"""Render the gallery: every ``scenes/gallery/*.toml`` at its own resolution (1280x720) and spp.

Each scene is rendered by ``arches-render render`` (field sphere-traced, meshes by
Mitsuba) into a temporary folder; its sRGB preview goes to ``docs/gallery/NAME.png``
and ``docs/gallery/README.md`` lists every image with its figure, seconds (JIT
included), spp and the machine's load average at the time (timings under load are
inflated; compare them only within one run).

Run from the repository root::

    python examples/make_gallery.py [NAME ...] [--spp N] [--resolution WxH]

``examples/make_gallery_scenes.py`` writes the scenes.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

from arches_render.cli import main as cli
from arches_render.scene import load_scene

REPO = Path(__file__).resolve().parents[1]
GALLERY = REPO / "scenes" / "gallery"
DOCS = REPO / "docs" / "gallery"


def render(path: Path, spp=None, resolution=None) -> dict:
    """Render one scene; return its row of the index (name, description, seconds, spp, size)."""
    desc = load_scene(path)
    args = ["render", str(path), "-q", "--no-aovs"]
    if spp:
        args += ["--spp", str(spp)]
    if resolution:
        args += ["--resolution", resolution]
    with tempfile.TemporaryDirectory() as tmp:
        exr = Path(tmp) / f"{desc.name}.exr"
        t0 = time.perf_counter()
        if cli(args + ["-o", str(exr)]) != 0:
            raise SystemExit(f"{path}: render failed")
        seconds = time.perf_counter() - t0
        DOCS.mkdir(parents=True, exist_ok=True)
        shutil.move(str(exr.with_suffix(".png")), DOCS / f"{desc.name}.png")
    size = resolution or f"{desc.render.width}x{desc.render.height}"
    return {"name": desc.name, "description": desc.description, "seconds": seconds,
            "spp": spp or desc.render.spp, "size": size, "load": os.getloadavg()[0]}


def write_index(rows: list) -> None:
    """``docs/gallery/README.md``: one line per image (kept rows of scenes not re-rendered)."""
    index = DOCS / "README.md"
    old = {}
    if index.exists():
        for line in index.read_text().splitlines():
            if line.startswith("| [") and "](" in line:
                old[line.split("]")[0][3:]] = line
    for r in rows:
        old[r["name"]] = (f"| [{r['name']}]({r['name']}.png) | {r['description']} | {r['size']} | "
                          f"{r['spp']} | {r['seconds']:.0f} | {r['load']:.1f} |")
    lines = ["# Gallery", "", "Rendered by `python examples/make_gallery.py` (scenes in `scenes/gallery/`).",
             "Seconds include JIT compilation; the load average is the machine's at the end of each render.",
             "", "| image | landscape | size | spp | seconds | load |", "|---|---|---|---|---|---|"]
    lines += [old[k] for k in sorted(old)]
    lines += [""] + [f"![{k}]({k}.png)" for k in sorted(old)]
    index.write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="scene names (default: all of scenes/gallery)")
    ap.add_argument("--spp", type=int, help="override every scene's spp")
    ap.add_argument("--resolution", help="override the resolution (WxH)")
    a = ap.parse_args(argv)
    paths = [GALLERY / f"{n}.toml" for n in a.names] or sorted(
        p for p in GALLERY.glob("*.toml") if not p.name.startswith("_"))
    rows = []
    for k, path in enumerate(paths):
        print(f"[{k + 1}/{len(paths)}] {path.stem}", flush=True)
        rows.append(render(path, a.spp, a.resolution))
        write_index(rows)
        print(f"    {rows[-1]['seconds']:.0f} s at {rows[-1]['size']}, {rows[-1]['spp']} spp", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
