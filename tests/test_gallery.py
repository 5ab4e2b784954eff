"""The gallery (issue 15, items 4 and 5): every ``scenes/gallery`` scene loads and renders
(tiny, 1 spp) to a finite, nonzero beauty; the combined scene holds all five generators."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from helpers import variant

variant()

from arches_render.render.renderer import build_scene, render_image  # noqa: E402
from arches_render.scene import load_scene  # noqa: E402

GALLERY = Path(__file__).resolve().parents[1] / "scenes" / "gallery"
SCENES = sorted(p for p in GALLERY.glob("*.toml") if not p.name.startswith("_"))
COMBINED = GALLERY / "every_generator.toml"
STILLS = [p for p in SCENES if p != COMBINED]  # the combined scene renders as a turntable below


def test_gallery_is_not_empty():
    assert len(SCENES) >= 2, SCENES


def _looks_lit(img):
    """A landscape under a sky: finite, light everywhere (no black void), some variation."""
    lum = img.mean(axis=2)
    assert np.isfinite(img).all()
    assert lum.mean() > 0.02 and (lum > 0).mean() > 0.95 and lum.std() > 1e-3


@pytest.mark.parametrize("path", STILLS, ids=[p.stem for p in STILLS])
def test_gallery_scene_renders(path):
    desc = load_scene(path)
    assert desc.render.width == 1280 and desc.render.height == 720  # the gallery's size
    desc.render.width, desc.render.height = 48, 27
    img = render_image(build_scene(desc, width=48, height=27), 1, seed=0)
    assert img.shape == (27, 48, 3)
    _looks_lit(img)


def test_combined_scene_uses_every_generator():
    desc = load_scene(COMBINED)
    modules = {type(n).__module__ for n in desc.field.walk()}
    packages = {m.split(".")[2] for m in modules if m.startswith("arches_render.generators.")}
    assert {"terrain", "blocks", "layers"} <= packages, modules
    # Blocks and sand sit on the amplified terrain: their host/source is the terrain's node.
    kinds = {n.kind for n in desc.field.walk()}
    assert {"implicit_heightfield", "skeletal_set", "blocks_field", "layers"} <= kinds, kinds
    assert len(desc.rock_piles) == 1  # rocks, support = the terrain
    fins = [m for m in desc.meshes if "gmaps_arch" in str(m.get("filename", ""))]
    manifest = json.loads((GALLERY / "data" / "gmaps_arch" / "manifest.json").read_text())
    assert len(fins) == 1 and manifest["counts"]["hole"] >= 1  # the G-map window fin (genus one), a mesh


def test_combined_scene_renders_as_still_and_turntable(tmp_path):
    """Frame 1001 of the orbit is the still of camera ``orbit``; 1002 is half a turn on, behind
    the cliff (the orbit stays above the plateau: no frame inside the rock)."""
    from arches_render.cli import main
    from arches_render.imaging.exr import read_exr
    out = tmp_path / "tt"
    assert main(["turntable", str(COMBINED), "-o", str(out), "--frames", "2", "--resolution", "40x22",
                 "--spp", "1", "--camera", "orbit", "--no-aovs", "-q"]) == 0
    still, half = (read_exr(out / f"every_generator.{k}.exr") for k in (1001, 1002))
    cam = load_scene(COMBINED).cameras["orbit"]
    assert still.header["camera_origin"] == " ".join(f"{v:.9g}" for v in cam.origin)
    for img in (still, half):
        assert img.rgb.shape == (22, 40, 3)
        _looks_lit(img.rgb)
    assert not np.array_equal(still.rgb, half.rgb)
