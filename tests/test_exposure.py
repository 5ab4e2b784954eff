"""Metered exposure (issue 33): a camera's averaging meter, written to the render's header."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest

from helpers import SCENES, variant

from arches_render.imaging.exposure import KEY_VALUE, MAX_STOPS, metered_exposure


def test_a_uniform_grey_is_exposed_to_the_key_value():
    for y in (0.01, 0.18, 2.0):
        img = np.full((8, 8, 3), y)
        assert metered_exposure(img) == pytest.approx(math.log2(KEY_VALUE / (y + 1.8e-4)), abs=1e-9)
    assert metered_exposure(np.full((4, 4, 3), KEY_VALUE)) == pytest.approx(0.0, abs=2e-3)


def test_the_log_average_weighs_ratios_and_the_meter_is_clamped():
    dark, bright = np.full((4, 8, 3), 0.02), np.full((4, 8, 3), 2.0)
    half = np.concatenate([dark, bright], axis=0)
    # The geometric mean of 0.02 and 2.0 is 0.2: about one stop above middle grey's exposure.
    assert metered_exposure(half) == pytest.approx(math.log2(KEY_VALUE / math.sqrt(0.0202 * 2.0002)), abs=1e-3)
    assert metered_exposure(np.zeros((4, 4, 3))) == MAX_STOPS
    assert metered_exposure(np.full((4, 4, 3), 1e6)) == -MAX_STOPS
    nan = np.full((4, 4, 3), 0.18)
    nan[0, 0] = np.nan
    assert np.isfinite(metered_exposure(nan))


def test_render_meters_unless_the_scene_sets_an_exposure(tmp_path):
    variant()
    from arches_render import tomlfile
    from arches_render.cli import main
    from arches_render.imaging.exr import read_exr
    from PIL import Image

    from arches_render.tomlfile import toml_text
    src = tomlfile.load(SCENES / "default.toml")
    (tmp_path / "data").mkdir()   # the scene's DEM at the path it names (a scene reads only inside its folder)
    shutil.copy(SCENES / "data" / "default_gorge.heights.npy", tmp_path / "data")
    for exposure in (None, 1.5):
        doc = dict(src, render={k: v for k, v in src["render"].items() if k != "exposure"})
        if exposure is not None:
            doc["render"]["exposure"] = exposure
        scene = tmp_path / f"exposure_{exposure}.toml"
        scene.write_text(toml_text(doc, "test_exposure"))
        out = tmp_path / f"e{exposure}.exr"
        assert main(["render", str(scene), "-o", str(out), "--resolution", "48x27", "--spp", "2", "-q"]) == 0
        header = read_exr(out).header
        if exposure is None:
            assert header["exposure_metered"] == "true"
            image = read_exr(out)   # the meter reads what the PNG shows: the denoised beauty where there is one
            shown = image.layers.get("denoised", image.rgb)
            assert float(header["exposure"]) == pytest.approx(metered_exposure(shown), abs=1e-3)
        else:
            assert header["exposure_metered"] == "false" and float(header["exposure"]) == 1.5
        assert Image.open(out.with_suffix(".png")).size == (48, 27)
