"""Golden-image regression tests of the shipped scenes (``pytest --update-goldens``
re-renders the references). Images are small and the test spp low; thresholds are
calibrated per scene from renders with other seeds (see arches_render.imaging)."""

from __future__ import annotations

import pytest

from helpers import SCENES, variant

SHIPPED = sorted(p.stem for p in SCENES.glob("*.toml"))
WIDTH, HEIGHT, TEST_SPP, REF_SPP = 128, 72, 32, 1024
# Scenes whose image mean is noisier get more test samples, so that the 1 % mean
# rule keeps a margin of several sigma (see the calibration in golden/NAME.json).
TEST_SPP_OF = {"boulders": 96, "sea_cave": 96, "gmaps_arch": 96, "gmaps_drilling": 96, "gmaps_cavern": 96,
               "terrain_sea": 96}


@pytest.mark.parametrize("name", SHIPPED)
def test_golden(name, golden):
    variant()
    from arches_render.render.renderer import build_scene, render_image
    from arches_render.scene import load_scene

    desc = load_scene(SCENES / f"{name}.toml")
    scene = build_scene(desc, "field", WIDTH, HEIGHT)
    golden(name, lambda seed, spp: render_image(scene, spp, seed=seed), ref_spp=REF_SPP,
           test_spp=TEST_SPP_OF.get(name, TEST_SPP))
