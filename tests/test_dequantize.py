"""Quantized DEMs (:mod:`arches_render.field.dequantize`): whole-metre heights lose their
terraces, and nothing moves by more than half a step or across the sea level."""

from __future__ import annotations

import numpy as np

from arches_render.field.dequantize import dequantize, quantization_step


def _relief(n=192, cell=10.0):
    """A smooth landscape (a hill on a tilted plane, gentle waves): 0.2-2 m a cell."""
    y, x = np.mgrid[0:n, 0:n] * cell
    return (80.0 * np.exp(-((x - 900.0) ** 2 + (y - 1000.0) ** 2) / 500.0 ** 2) + 0.02 * x
            + 5.0 * np.sin(x / 300.0) * np.cos(y / 250.0))


def _equal_neighbours(H, step):
    return float(np.mean(np.abs(np.diff(H, axis=1)) < 1e-3 * step))


def test_whole_metres_lose_their_terraces_and_keep_their_samples():
    """Rounded to whole metres, the relief is a staircase (most neighbours equal); the
    dequantized heights are within half a metre of every sample, have almost no
    treads left, and lie nearer the true relief than the staircase did."""
    S = _relief()
    Q = np.round(S)
    assert quantization_step(Q) == 1.0
    Z = dequantize(Q, 1.0)
    assert np.all(np.abs(Z - Q) <= 0.5 + 1e-12)
    assert _equal_neighbours(Q, 1.0) > 0.5 and _equal_neighbours(Z, 1.0) < 0.1
    # Measured 0.29 -> 0.15 m: rounding's error is uniform, the smooth surface's half of it.
    rms = [float(np.sqrt(np.mean((A - S) ** 2))) for A in (Q, Z)]
    assert rms[1] < 0.6 * rms[0]


def test_a_lattice_of_any_step_and_offset_is_found():
    """Decimetres above an offset, stored as float32 (as a DEM file holds them), and the
    levels of an 8-bit image."""
    S = _relief() * 0.1 + 1234.5
    Q = (np.round((S - 1234.5) / 0.1) * 0.1 + 1234.5).astype(np.float32)
    step = quantization_step(Q)
    assert step is not None and abs(step - 0.1) < 1e-3
    # An 8-bit heightmap scaled to 500 m: 255 levels.
    S = _relief()
    eight_bit = np.round((S - S.min()) / np.ptp(S) * 255.0) / 255.0 * 500.0
    assert abs(quantization_step(eight_bit) - 500.0 / 255.0) < 1e-9


def test_heights_that_show_no_terraces_are_left_alone():
    """Continuous heights, a few plateaus (shapes, not rounding) and whole metres under
    steps of tens of metres a cell are not quantized DEMs to smooth."""
    S = _relief()
    assert quantization_step(S) is None
    assert quantization_step(np.where(S > 40.0, 100.0, 0.0)) is None
    assert quantization_step(np.round(S * 200.0)) is None
    assert quantization_step(np.full((8, 8), 3.0)) is None


def test_the_coast_stays_where_it_is():
    """With a sea level, sea samples stay at or below it and land samples above it."""
    Q = np.round(_relief() - 30.0)
    wet = Q <= 0.0
    assert 0.2 < wet.mean() < 0.8
    Z = dequantize(Q, 1.0, sea_level=0.0)
    assert np.array_equal(Z <= 0.0, wet)
    assert np.array_equal(Z.astype(np.float32) <= 0.0, wet)
    assert np.all(np.abs(Z - Q) <= 0.5 + 1e-12)


def test_a_heightfield_node_smooths_its_file_when_asked(tmp_path):
    """``dequantize = true`` on a heightfield node reading whole metres: its heights are
    within half a metre of the file's and lose their terraces; without the key the file's
    heights are kept; a value that is not a boolean names the key."""
    import pytest
    from helpers import variant
    variant()
    from arches_render.scene import SceneError, load_scene
    Q = np.round(_relief(96))
    np.save(tmp_path / "dem.npy", Q.astype(np.float32))
    scene = """[camera]
origin = [475.0, -400.0, 300.0]
target = [475.0, 475.0, 50.0]
[[lights]]
type = "sunsky"
elevation = 30.0
azimuth = 120.0
[field]
root = "ground"
[nodes.ground]
type = "heightfield"
extent = [0.0, 0.0, 950.0, 950.0]
source = "file"
file = "dem.npy"
"""
    heights = {}
    for key, line in (("kept", ""), ("smoothed", "dequantize = true\n")):
        (tmp_path / f"{key}.toml").write_text(scene + line)
        heights[key] = np.asarray(load_scene(tmp_path / f"{key}.toml").field.heights_np, dtype=np.float64)
    assert np.array_equal(heights["kept"], Q)
    assert np.abs(heights["smoothed"] - Q).max() <= 0.5 + 1e-6
    assert _equal_neighbours(heights["smoothed"], 1.0) < 0.1 < _equal_neighbours(Q, 1.0)
    (tmp_path / "bad.toml").write_text(scene + "dequantize = 1\n")
    with pytest.raises(SceneError, match="dequantize"):
        load_scene(tmp_path / "bad.toml")


def test_an_8_bit_heightmap_amplifies_without_its_terraces(tmp_path, capsys):
    """An 8-bit grey PNG (255 levels: a game engine's heightmap) through ``arches-render
    amplify --height-scale``: the header says the heights were on a lattice of
    ``scale / 255`` and smoothed; the heights written are within half a level of the
    image's and have lost their treads."""
    from PIL import Image
    from robust_helpers import cli_out
    S = _relief(64, 30.0)
    grey = np.round((S - S.min()) / np.ptp(S) * 255.0).astype(np.uint8)
    Image.fromarray(grey, mode="L").save(tmp_path / "heightmap.png")
    out = tmp_path / "scene.toml"
    rc, _, err = cli_out(capsys, "amplify", tmp_path / "heightmap.png", "-o", out, "--cell-size", "30",
                         "--height-scale", "255", "--preset", "river", "-q")
    assert rc == 0, err
    header = [line for line in out.read_text().splitlines() if line.startswith("# ")]
    assert any("heights on a 1 m lattice" in line for line in header), header
    Z = np.load(next(tmp_path.rglob("*heights.npy")), allow_pickle=False).astype(np.float64)
    assert np.abs(Z - grey).max() <= 0.5 + 1e-4
    # Measured: equal neighbours 10.6 % -> 3.3 %.
    assert _equal_neighbours(grey.astype(np.float64), 1.0) > 2 * _equal_neighbours(Z, 1.0)
