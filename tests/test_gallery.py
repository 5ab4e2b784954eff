"""The gallery (issue 15, items 4 and 5): every ``scenes/gallery`` scene loads and renders
(tiny, 1 spp, with AOVs) to a lit landscape: every pixel below the horizon hits the ground,
every hit is lit, no prism wall; the combined scene holds all five generators, and its
turntable frames are the renders their headers name."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from helpers import exr_layers, render_as_header_says, variant
from landscape_helpers import shot_report

variant()

from arches_render.render.renderer import build_scene, render_layers  # noqa: E402
from arches_render.scene import load_scene  # noqa: E402

GALLERY = Path(__file__).resolve().parents[1] / "scenes" / "gallery"
SCENES = sorted(p for p in GALLERY.glob("*.toml") if not p.name.startswith("_"))
COMBINED = GALLERY / "every_generator.toml"
STILLS = [p for p in SCENES if p != COMBINED]  # the combined scene renders as a turntable below


def test_gallery_is_not_empty():
    assert len(SCENES) >= 2, SCENES


def test_readme_shows_rendered_gallery_images_listed_in_the_index():
    """Every image the README shows is in ``docs/gallery`` and in its index (which
    ``examples/make_gallery.py`` writes with each image's scene, spp and seconds), and
    every gallery scene has its image there (the Fig. 11 steps as one strip)."""
    import re
    repo = GALLERY.parents[1]
    shown = re.findall(r'src="docs/gallery/([\w.]+\.png)"', (repo / "README.md").read_text())
    index = (repo / "docs" / "gallery" / "index.md").read_text()
    assert len(set(shown)) >= 10, shown
    for name in shown:
        assert (repo / "docs" / "gallery" / name).is_file(), name
        stem = name[:-4]
        assert f"[{stem}]" in index or f"[{stem}_step1]" in index, f"{name} is not in docs/gallery/index.md"
    for scene in SCENES:
        stem = re.sub(r"_step\d+$", "", scene.stem)
        assert f"{stem}.png" in shown, f"the README does not show {scene.name}'s image"


def _looks_lit(desc, camera, rgb, layers, walls=True):
    """A landscape under a sky, judged by the AOVs: finite; every pixel whose footprint lies below
    the horizon hit something in every sample (a missed slab shows the sky there, which a beauty
    check takes for light); every hit is lit (not black); no hit on the field prism's walls
    (``walls=False``: not checked)."""
    h, w = rgb.shape[:2]
    rep = shot_report(desc, layers, camera, w, h)
    hit = layers["coverage"][0].sum(axis=-1) > 0
    lum = rgb.mean(axis=2)
    assert np.isfinite(rgb).all()
    assert rep["below_horizon_pixels"] > 0 and rep["below_horizon_misses"] == 0.0, rep
    assert rep["hits"] > 0.5 and (rep["wall_hits"] == 0.0 or not walls), rep
    assert (lum[hit] > 0).mean() > 0.99 and lum.mean() > 0.02 and lum.std() > 1e-3, float(lum.mean())


@pytest.mark.parametrize("path", STILLS, ids=[p.stem for p in STILLS])
def test_gallery_scene_renders(path):
    desc = load_scene(path)
    # The gallery's size; the panels of a strip (NAME_stepK, joined side by side) are half that.
    size = (640, 360) if "_step" in path.stem else (1280, 720)
    assert (desc.render.width, desc.render.height) == size
    rgb, layers = render_layers(build_scene(desc, "field", 48, 27, aovs=True), 1, seed=0)
    assert rgb.shape == (27, 48, 3)
    _looks_lit(desc, desc.camera, rgb, layers)


def test_combined_scene_uses_every_generator():
    desc = load_scene(COMBINED)
    modules = {type(n).__module__ for n in desc.field.walk()}
    packages = {m.split(".")[2] for m in modules if m.startswith("arches_render.generators.")}
    assert {"terrain", "blocks", "layers"} <= packages, modules
    # Blocks and sand sit on the amplified terrain: their host/source is the terrain's node.
    kinds = {n.kind for n in desc.field.walk()}
    assert {"implicit_heightfield", "skeletal_set", "blocks_field", "layers"} <= kinds, kinds
    assert len(desc.rock_piles) == 1  # rocks, support = the talus node (two ellipsoids at the cliff foot)
    fins = [m for m in desc.meshes if "gmaps_arch" in str(m.get("filename", ""))]
    manifest = json.loads((GALLERY / "data" / "gmaps_arch" / "manifest.json").read_text())
    assert len(fins) == 1 and manifest["counts"]["hole"] >= 1  # the G-map window fin (genus one), a mesh


def test_combined_scene_renders_as_still_and_turntable(tmp_path):
    """Frame 1001 of the orbit is the still of camera ``orbit``; 1002 is half a turn on, behind
    the cliff (the orbit stays above the plateau: no frame inside the rock). Each frame is the
    render its header names (camera, samples, stream), bit for bit."""
    from arches_render.cli import main
    from arches_render.imaging.exr import read_exr
    from arches_render.render.output import render_header
    from arches_render.render.turntable import orbit_camera
    out = tmp_path / "tt"
    assert main(["turntable", str(COMBINED), "-o", str(out), "--frames", "2", "--resolution", "40x22",
                 "--spp", "1", "--camera", "orbit", "-q"]) == 0
    desc = load_scene(COMBINED)
    cam = desc.cameras["orbit"]
    for k in (0, 1):
        img = read_exr(out / f"every_generator.{1001 + k}.exr")
        origin = orbit_camera(cam.origin, cam.target, cam.up, k, 2)
        want = render_header(desc.name, COMBINED, 0, 1, 40, 22, "field", (origin, cam.target, cam.up, cam.fov))
        assert [img.header[key] for key in ("camera_origin", "camera_target", "camera_fov", "stream")] == [
            want[key] for key in ("camera_origin", "camera_target", "camera_fov")] + [str(k)]
        assert img.rgb.shape == (22, 40, 3)
        rgb, _ = render_as_header_says(COMBINED, img.header)
        assert np.array_equal(img.rgb, rgb), f"frame {1001 + k} is not the render its header names"
        # Half a turn on, the orbit looks at the tile's +y side: the scene has no [[far_field]], so 14 % of
        # that frame is the cut wall of the terrain's prism (reported, issue 23); the still has none.
        _looks_lit(desc, type(cam)(list(origin), cam.target, cam.up, cam.fov), img.rgb, exr_layers(img),
                   walls=k == 0)
