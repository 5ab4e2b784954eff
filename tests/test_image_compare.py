"""The golden-image harness: comparison metrics, calibration, reports, and the proof on real renders.

The proof uses real Monte Carlo noise: a 48 x 48 Mitsuba scene (diffuse sphere on
a diffuse rectangle, constant sky plus a directional sun, stock ``path``
integrator, ``box`` filter, ``independent`` sampler) is made into a golden in a
temporary folder (reference 4096 spp, calibration at 32 spp with seeds 1-4), and
then

* a render with a new seed passes,
* the same render 1 % brighter fails on the global mean,
* the same render with one 8 x 8 patch at an unaligned offset changed by 25 %
  fails on the window check, at that patch,

and a failure leaves a report (index.html, diff.png, test.exr, ...).
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from arches_render.imaging import golden as gold
from arches_render.imaging.compare import (CalibrationWarning, Thresholds, calibrate, compare, mean_noise,
                                           mean_shift, window_error)
from arches_render.imaging.exr import read_exr
from arches_render.imaging.report import REPORT_FILES, heatmap

RES = 48
REF_SPP, TEST_SPP = 4096, 32
PATCH = (21, 13)  # (y, x): top-left of the changed 8 x 8 patch, on no multiple of 8


# --------------------------------------------------------------------------- synthetic checks

def _smooth_image(shape=(40, 56), seed=0):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[: shape[0], : shape[1]] / 10.0
    base = 0.6 + 0.3 * np.sin(y)[..., None] * np.cos(x)[..., None] + 0.05 * rng.random(shape + (3,))
    return base * np.array([1.0, 0.8, 0.6])


def test_window_error_catches_unaligned_patch_fully():
    ref = _smooth_image()
    test = ref.copy()
    test[13:21, 27:35] *= 1.25  # rows 13-20, columns 27-34: straddles the 8-pixel grid both ways
    err = window_error(ref, test)
    assert err.shape == (40 - 7, 56 - 7)
    assert np.unravel_index(np.argmax(err), err.shape) == (13, 27)
    eps = 0.01 * (ref @ [0.2126, 0.7152, 0.0722]).mean()
    window = (ref[13:21, 27:35] @ [0.2126, 0.7152, 0.0722]).mean()
    assert err.max() == pytest.approx(0.25 * window / (window + eps), rel=1e-9)
    # The aligned 8 x 8 tiles would each see only part of the patch.
    assert err[8::8, 24::8].max() < 0.6 * err.max()


def test_window_error_dark_windows_do_not_explode():
    ref = _smooth_image()
    ref[:8, :8] = 0.0
    test = ref.copy()
    test[:8, :8] = 1e-4  # an absolute error that is invisible next to the image mean
    # 1e-4 over eps = 1 % of the image mean (~0.5): 2 %, not infinity
    assert window_error(ref, test)[0, 0] < 0.05


def test_mean_shift_is_signed_and_per_channel():
    ref = _smooth_image()
    np.testing.assert_allclose(mean_shift(ref, ref * 1.02), 0.02, rtol=2e-3)
    tint = ref * [1.02, 1.0, 0.97]
    np.testing.assert_allclose(mean_shift(ref, tint), [0.02, 0.0, -0.03], rtol=1e-2, atol=1e-9)
    th = Thresholds(tile=1.0, flip=1.0)
    res = compare(ref, tint, th)
    assert not res.passed and res.mean_shift == pytest.approx(-0.03, rel=1e-2)
    assert "channel B" in res.failures[0]


def test_thresholds_json_round_trip():
    th = Thresholds(tile=0.061, flip=0.043, mean_rel=0.01, mean_guard=0.0033, calibration={"renders": 4})
    again = Thresholds.from_json(th.to_json())
    assert again == th and again.mean_limit == pytest.approx(0.0067)
    assert Thresholds.from_dict({**th.to_dict(), "future_field": 1}) == th


def test_compare_rejects_mismatch_and_flags_nan():
    ref = _smooth_image()
    th = Thresholds(tile=0.5, flip=1.0)
    with pytest.raises(ValueError, match="differ"):
        compare(ref, ref[:-1], th)
    bad = ref.copy()
    bad[5, 7] = np.nan
    res = compare(ref, bad, th)
    assert not res.passed and res.nonfinite == 1 and "y=5, x=7" in res.failures[0]
    assert compare(ref, ref, th).passed


def test_mean_noise_estimate_matches_spread():
    rng = np.random.default_rng(3)
    ref = _smooth_image()
    noisy = [ref + rng.normal(0, 0.1, ref.shape) for _ in range(400)]
    spread = np.std([mean_shift(ref, n) for n in noisy], axis=0)
    estimate = np.mean([mean_noise(ref, n) for n in noisy[:4]], axis=0)
    np.testing.assert_allclose(estimate, spread, rtol=0.15)


def test_calibrate_warns_when_too_noisy():
    rng = np.random.default_rng(5)
    ref = np.full((16, 16, 3), 0.5)
    renders = [ref * (1 + rng.normal(0, 0.4, ref.shape)) for _ in range(4)]
    with pytest.warns(CalibrationWarning) as rec:
        th = calibrate(ref, renders)
    text = " ".join(str(w.message) for w in rec)
    assert "mean rule is unreliable" in text and "patch may pass" in text
    assert th.mean_guard == pytest.approx(0.005) and len(th.calibration["warnings"]) == 2


def test_heatmap_ramp():
    hm = heatmap(np.array([[0.0, 0.5, 1.0, 9.0, np.nan]]), 1.0)
    assert hm.dtype == np.uint8 and hm.shape == (1, 5, 3)
    np.testing.assert_array_equal(hm[0, 0], [0, 0, 0])
    np.testing.assert_array_equal(hm[0, 2], [255, 255, 255])
    np.testing.assert_array_equal(hm[0, 3], hm[0, 2])
    assert np.all(np.diff(hm[0, :3].astype(int).sum(axis=1)) > 0)


# --------------------------------------------------------------------------- real Monte Carlo renders

def _mitsuba():
    from arches_render import backend
    try:
        backend.set_variant()
    except ImportError:
        # set_variant selects the variant before registering our plugins; a
        # plugin module that does not import (edited concurrently) must not
        # stop these tests, which use stock plugins only.
        import mitsuba as mi
        mi.set_variant("llvm_ad_rgb")
    import mitsuba as mi
    return mi


@pytest.fixture(scope="module")
def render():
    mi = _mitsuba()
    T = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4},
        "sensor": {
            "type": "perspective", "fov": 40,
            "to_world": T().look_at(origin=[0, -4.5, 2.2], target=[0, 0, 0.45], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": RES, "height": RES, "rfilter": {"type": "box"},
                     "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": 4},
        },
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.8, 0.85, 1.0]}},
        "sun": {"type": "directional", "direction": [0.4, 0.6, -1.0],
                "irradiance": {"type": "rgb", "value": [2.0, 1.9, 1.7]}},
        "sphere": {"type": "sphere", "center": [0, 0, 0.6], "radius": 0.6,
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}}},
        "floor": {"type": "rectangle", "to_world": T().scale([2.0, 2.0, 1.0]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.45, 0.45, 0.45]}}},
    })

    def render(seed: int, spp: int) -> np.ndarray:
        return np.array(mi.render(scene, seed=seed, spp=spp), dtype=np.float32)

    return render


@pytest.fixture(scope="module")
def made(render, tmp_path_factory):
    root = tmp_path_factory.mktemp("golden_harness")
    with warnings.catch_warnings():
        warnings.simplefilter("error", CalibrationWarning)  # the test spp must be adequate
        g = gold.update_golden("sphere", render, ref_spp=REF_SPP, test_spp=TEST_SPP, golden_dir=root / "golden",
                               meta={"scene": "test sphere", "camera": [0, -4.5, 2.2]})
    return g, root / "golden", root / "reports"


def _patched(render, factor):
    def patched(seed, spp):
        img = render(seed, spp)
        y, x = PATCH
        img[y:y + 8, x:x + 8] *= factor
        return img
    return patched


def test_box_filter_renders_are_deterministic(render):
    a, b = render(5, 8), render(5, 8)
    assert a.tobytes() == b.tobytes()
    assert render(6, 8).tobytes() != a.tobytes()


def test_golden_files(made):
    g, golden_dir, _ = made
    record = json.loads((golden_dir / "sphere.json").read_text())
    assert record["test_spp"] == TEST_SPP and record["calib_seeds"] == [1, 2, 3, 4]
    assert record["reference"]["spp"] == REF_SPP and record["resolution"] == [RES, RES]
    assert "mitsuba" in record["versions"] and record["meta"]["scene"] == "test sphere"
    th = Thresholds.from_dict(record["thresholds"])
    assert th == g.thresholds and th.mean_rel == 0.01
    # Calibrated from real noise: loose enough to pass noise, tight enough for a 25 % patch.
    assert 0.0 < th.tile < 0.2 and 0.0 < th.mean_guard < 0.005 and th.flip > 0
    img = read_exr(golden_dir / "sphere.exr")
    assert img.header["spp"] == str(REF_SPP) and img.header["seed"] == "0"
    assert img.header["resolution"] == f"{RES}x{RES}" and img.header["version.arches_render"]
    np.testing.assert_array_equal(img.rgb, g.ref)


def test_new_seed_passes(made, render):
    g, golden_dir, reports = made
    (reports / "sphere").mkdir(parents=True, exist_ok=True)
    (reports / "sphere" / "index.html").write_text("stale")
    res = gold.check_golden("sphere", render, golden_dir=golden_dir, report_dir=reports)
    assert res.passed and res.failures == []
    assert abs(res.mean_shift) < g.thresholds.mean_limit and res.tile_max < g.thresholds.tile
    assert not (reports / "sphere").exists()  # the stale report went away
    for seed in (23, 99):
        assert gold.check_golden("sphere", render, golden_dir=golden_dir, report_dir=reports, seed=seed).passed
    with pytest.raises(ValueError, match="seed 3"):
        gold.check_golden("sphere", render, golden_dir=golden_dir, report_dir=reports, seed=3)


def test_one_percent_global_shift_fails(made, render):
    g, _, reports = made
    with pytest.raises(AssertionError, match="global mean") as exc:
        _check_renamed(made, "shift", lambda s, n: render(s, n) * 1.01)
    assert "report:" in str(exc.value) and "--update-goldens" in str(exc.value)
    assert (reports / "shift" / "index.html").is_file()


def _check_renamed(made, name, render_fn):
    """Check ``render_fn`` against golden 'sphere' stored under another name, so reports do not collide."""
    g, golden_dir, reports = made
    for suffix in (".exr", ".json"):
        dst = golden_dir / f"{name}{suffix}"
        if not dst.exists():
            dst.write_bytes((golden_dir / f"sphere{suffix}").read_bytes())
    return gold.check_golden(name, render_fn, golden_dir=golden_dir, report_dir=reports)


@pytest.mark.parametrize("factor", [1.25, 0.75])
def test_unaligned_patch_change_fails_on_windows(made, render, factor):
    g, _, reports = made
    name = f"patch_{factor}"
    with pytest.raises(AssertionError, match=r"8x8 window at \(y=21, x=13\)") as exc:
        _check_renamed(made, name, _patched(render, factor))
    # The full comparison finds the patch itself, and the global mean alone would not have.
    test = _patched(render, factor)(gold.DEFAULT_CHECK_SEED, TEST_SPP)
    res = compare(g.ref, test, g.thresholds)
    assert res.tile_where == PATCH and res.tile_max > 2 * g.thresholds.tile
    assert abs(res.mean_shift) < 0.01
    assert str(reports / name) in str(exc.value)


def test_failure_report_contents(made, render):
    g, _, reports = made
    with pytest.raises(AssertionError):
        _check_renamed(made, "report", _patched(render, 1.25))
    folder = reports / "report"
    assert sorted(p.name for p in folder.iterdir()) == sorted(REPORT_FILES)
    page = (folder / "index.html").read_text()
    assert "FAIL" in page and "window at (y=21, x=13)" in page and 'src="diff.png"' in page
    assert "<script" not in page and "http" not in page  # self-contained
    saved = read_exr(folder / "test.exr").rgb
    expected = _patched(render, 1.25)(gold.DEFAULT_CHECK_SEED, TEST_SPP)
    np.testing.assert_allclose(saved, expected, rtol=2.0 ** -11, atol=2.0 ** -25)
    assert (folder / "diff.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    numbers = json.loads((folder / "result.json").read_text())
    assert numbers["passed"] is False and numbers["tile_where"] == list(PATCH)


def test_missing_and_stale_goldens(made, render, tmp_path):
    _, golden_dir, reports = made
    with pytest.raises(gold.GoldenMissingError, match="--update-goldens"):
        gold.check_golden("nope", render, golden_dir=golden_dir, report_dir=reports)
    with pytest.raises(gold.GoldenError, match="stale.*test_spp 64"):
        gold.check_golden("sphere", render, golden_dir=golden_dir, report_dir=reports, test_spp=64)
    with pytest.raises(gold.GoldenError, match="render is 24x48"):
        gold.check_golden("sphere", lambda s, n: render(s, n)[:, :24], golden_dir=golden_dir, report_dir=reports)
    # An EXR swapped without re-calibration is noticed.
    for suffix in (".exr", ".json"):
        (tmp_path / f"sphere{suffix}").write_bytes((golden_dir / f"sphere{suffix}").read_bytes())
    from arches_render.imaging.exr import write_exr
    write_exr(tmp_path / "sphere.exr", read_exr(tmp_path / "sphere.exr").rgb * 1.5)
    with pytest.raises(gold.GoldenError, match="does not match"):
        gold.load_golden("sphere", tmp_path)


@pytest.fixture
def golden_dir(made):
    """This module's golden fixture works on the temporary golden folder."""
    return made[1]


@pytest.fixture
def report_dir(made):
    return made[2]


def test_golden_fixture(golden, render, update_goldens, made, tmp_path):
    before = tmp_path / "before.exr"
    before.write_bytes((made[1] / "sphere.exr").read_bytes())
    # Under --update-goldens this re-makes the temporary golden first: with the
    # box filter the renders repeat exactly, so the pixels must not change.
    assert golden("sphere", render, ref_spp=REF_SPP, test_spp=TEST_SPP).passed
    np.testing.assert_array_equal(read_exr(made[1] / "sphere.exr").rgb, read_exr(before).rgb)
    if not update_goldens:
        with pytest.raises(pytest.fail.Exception, match="--update-goldens"):
            golden("absent", render, ref_spp=REF_SPP, test_spp=TEST_SPP)
