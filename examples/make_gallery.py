"""Render the gallery: every ``scenes/gallery/*.toml`` at its own resolution (1280x720) and
spp, and the shipped scenes of :data:`SHIPPED` at 1280x720.

Each scene is rendered by ``arches-render render --denoise --view aces`` (field
sphere-traced, meshes by Mitsuba; denoised by Intel Open Image Denoise from beauty,
albedo and normal; ACES 2.0 view) into a temporary folder; its PNG goes to
``docs/gallery/NAME.png``. Scenes named ``NAME_stepK`` are also joined, left to right,
into one strip ``NAME.png`` (Fig. 11's erosion steps). ``docs/gallery/index.md`` lists
every image with its scene, seconds (JIT included), spp, size, the machine and its
load average at the end of the render (timings under load are inflated; compare
them only within one run).

Run from the repository root::

    python examples/make_gallery.py [NAME ...] [--spp N] [--resolution WxH]

``examples/make_gallery_scenes.py`` writes the scenes.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

from arches_render.cli import main as cli
from arches_render.scene import load_scene

REPO = Path(__file__).resolve().parents[1]
GALLERY = REPO / "scenes" / "gallery"
DOCS = REPO / "docs" / "gallery"
#: Shipped scenes shown in the gallery too (the Arches paper's swept arch and its tunnel
#: with rock fall, scree below a cliff, a block-fractured cliff face), rendered at
#: 1280x720 and SHIPPED_SPP.
SHIPPED = ("layers_sweep_arch", "layers_tunnel_rockfall", "rocks_scree", "blocks_limestone_scarp")
SHIPPED_SPP = 16
STEP = re.compile(r"^(.*)_step(\d+)$")


def machine() -> str:
    """One line naming the CPU and its core count."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores"


def render(path: Path, spp=None, resolution=None) -> dict:
    """Render one scene; return its row of the index (name, description, seconds, spp, size)."""
    desc = load_scene(path)
    args = ["render", str(path), "-q", "--denoise", "--view", "aces"]
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
    return {"name": desc.name, "description": desc.description, "seconds": seconds, "scene": path.relative_to(REPO),
            "spp": spp or desc.render.spp, "size": size, "load": os.getloadavg()[0]}


def gallery_renders(names=()) -> list:
    """``(scene path, spp or None, resolution or None)`` of every gallery render (or of ``names``):
    the gallery scenes at their own settings, the shipped ones at 1280x720 and SHIPPED_SPP."""
    every = [(p, None, None) for p in sorted(GALLERY.glob("*.toml")) if not p.name.startswith("_")]
    every += [(REPO / "scenes" / f"{n}.toml", SHIPPED_SPP, "1280x720") for n in SHIPPED]
    return [r for r in every if r[0].stem in names] if names else every


def join_strips(names) -> list:
    """Join ``docs/gallery/NAME_stepK.png`` into ``NAME.png``, left to right; the strip names."""
    groups = {}
    for n in names:
        m = STEP.match(n)
        if m:
            groups.setdefault(m.group(1), []).append((int(m.group(2)), n))
    for strip, parts in groups.items():
        images = [np.asarray(Image.open(DOCS / f"{n}.png").convert("RGB")) for _, n in sorted(parts)]
        tmp = DOCS / f".{strip}.png"
        Image.fromarray(np.concatenate(images, axis=1)).save(tmp, optimize=True)
        tmp.replace(DOCS / f"{strip}.png")
    return sorted(groups)


def write_index(rows: list, strips=()) -> None:
    """``docs/gallery/index.md``: one row per render (rows of scenes not re-rendered are kept),
    then the images (a strip in place of its steps)."""
    index = DOCS / "index.md"
    old = {}
    if index.exists():
        for line in index.read_text().splitlines():
            if line.startswith("| [") and "](" in line:
                old[line.split("]")[0][3:]] = line
    for r in rows:
        old[r["name"]] = (f"| [{r['name']}]({r['name']}.png) | `{r['scene']}` | {r['description']} | {r['size']} | "
                          f"{r['spp']} | {r['seconds']:.0f} | {r['machine']} | {r['load']:.1f} |")
    lines = ["# Gallery", "", "Rendered by `python examples/make_gallery.py` (scenes in `scenes/gallery/` and the "
             "shipped scenes it lists), denoised with Intel Open Image Denoise, ACES 2.0 view.",
             "Seconds include JIT compilation; the load average is the machine's at the end of each render.",
             "", "| image | scene | landscape | size | spp | seconds | machine | load |",
             "|---|---|---|---|---|---|---|---|"]
    lines += [old[k] for k in sorted(old)]
    shown = sorted({STEP.match(k).group(1) if STEP.match(k) else k for k in old} | set(strips))
    lines += [""] + [f"![{k}]({k}.png)" for k in shown]
    index.write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="scene names (default: all of scenes/gallery)")
    ap.add_argument("--spp", type=int, help="override every scene's spp")
    ap.add_argument("--resolution", help="override the resolution (WxH)")
    a = ap.parse_args(argv)
    rows, where = [], machine()
    todo = gallery_renders(a.names)
    for k, (path, spp, resolution) in enumerate(todo):
        print(f"[{k + 1}/{len(todo)}] {path.stem}", flush=True)
        rows.append(render(path, a.spp or spp, a.resolution or resolution))
        rows[-1]["machine"] = where
        write_index(rows)
        print(f"    {rows[-1]['seconds']:.0f} s at {rows[-1]['size']}, {rows[-1]['spp']} spp", flush=True)
    strips = join_strips(p.stem for p, _, _ in gallery_renders() if (DOCS / f"{p.stem}.png").exists())
    write_index(rows, strips)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
