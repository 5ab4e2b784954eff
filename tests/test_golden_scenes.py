"""Golden-image regression tests of the shipped scenes (``pytest --update-goldens``
re-renders the references).

Each check renders the scene small, with each pixel's sample variance, and tests it
against the stored reference (4x the samples) with Welch's statistic
(:mod:`arches_render.imaging.welch`); it also proves, on that render, that a 1 %
global change, a 25 % change of its weakest 8 x 8 window at least a quarter as bright
as the image and one of its weakest 16 x 16 window down to 1/32 of it (shadows; see
:mod:`arches_render.imaging.golden`), up and down, would have failed. Resolution and spp of
each check: ``golden/checks.toml`` (also read by ``benchmarks/golden_seeds.py``).
"""

from __future__ import annotations

import pytest

from helpers import SCENES, golden_checks, variant

SHIPPED, (WIDTH, HEIGHT), spp_of = golden_checks()


@pytest.mark.parametrize("name", SHIPPED)
def test_golden(name, golden):
    variant()
    from arches_render.render.renderer import build_scene, render_moments
    from arches_render.scene import load_scene

    desc = load_scene(SCENES / f"{name}.toml")
    scene = build_scene(desc, "field", WIDTH, HEIGHT, moments=True)
    spp = spp_of(name)
    golden(name, lambda seed, n: render_moments(scene, n, seed=seed), ref_spp=4 * spp, test_spp=spp,
           meta={"scene": f"scenes/{name}.toml"})
