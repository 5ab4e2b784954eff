"""Camera paths (issue 15, item 6): a C¹ Catmull–Rom flight through named cameras with
times, rendered by ``turntable --path`` with the orbit's frames, resume, AOVs and MP4."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import render_as_header_says, variant
from production_helpers import ROCK, write_scene

variant()

from arches_render.cli import main  # noqa: E402
from arches_render.imaging.exr import read_exr  # noqa: E402
from arches_render.render.camera_path import path_cameras, path_spline  # noqa: E402
from arches_render.scene import load_scene  # noqa: E402
from arches_render.scene.loader import Camera  # noqa: E402

PATH = ROCK + """
[cameras.side]
origin = [6.0, -1.0, 1.5]
target = [0.0, 0.0, 0.5]
fov = 40.0
[cameras.top]
origin = [1.0, 4.0, 6.0]
target = [0.0, 0.3, 0.4]
fov = 55.0
[camera_path]
fps = 1.0
keys = [{ camera = "camera", time = 0.0 }, { camera = "side", time = 1.0 },
        { camera = "top", time = 2.0 }]
"""


def _keys():
    rng = np.random.default_rng(3)
    times = [0.0, 0.7, 2.0, 2.4, 4.0]
    return [(t, Camera(list(rng.normal(size=3) * 5 + [0, 0, 8]), list(rng.normal(size=3)),
                       [0.0, 0.0, 1.0], float(30 + 20 * rng.random()))) for t in times]


def test_path_passes_through_keys_at_their_times_and_is_c1():
    keys = _keys()
    s = path_spline(keys)
    for t, c in keys:
        assert np.allclose(s(t), [*c.origin, *c.target, *c.up, c.fov], atol=1e-12)
    d = s.derivative()
    for t, _ in keys[1:-1]:  # velocity continuous across each interior key
        left, right = d(t - 1e-9), d(t + 1e-9)
        assert np.allclose(left, right, rtol=1e-5, atol=1e-5)
    # ... while the second derivative jumps there: the curve is C¹, not a global C² fit.
    dd = s.derivative(2)
    assert not np.allclose(dd(keys[1][0] - 1e-9), dd(keys[1][0] + 1e-9), atol=1e-3)
    # A Catmull–Rom tangent at an interior key: the chord of its neighbours over their time span.
    (t0, c0), (t2, c2) = keys[0], keys[2]
    assert np.allclose(d(keys[1][0])[:3], (np.array(c2.origin) - c0.origin) / (t2 - t0), atol=1e-12)
    # Frames: ends included, evenly spaced.
    cams = path_cameras(keys, frames=9)
    assert np.allclose(cams[0][0], keys[0][1].origin) and np.allclose(cams[-1][0], keys[-1][1].origin)
    assert all(abs(np.linalg.norm(c[2]) - 1.0) < 1e-12 for c in cams)
    assert len(path_cameras(keys, fps=2.0)) == 9


TOP, SIDE = '{ camera = "top", time = 2.0 }', '{ camera = "side", time = 1.0 }'


@pytest.mark.parametrize("bad,key", [
    (PATH.replace(TOP, '{ camera = "top", time = 1.0 }'), "camera_path.keys[2].time"),  # repeated time
    (PATH.replace(SIDE, '{ camera = "side", time = -1.0 }'), "camera_path.keys[1].time"),  # backwards
    (PATH.replace(TOP, '{ camera = "nowhere", time = 2.0 }'), "camera_path.keys[2].camera"),
    (PATH.replace(TOP, '{ camera = "top" }'), "camera_path.keys[2].time"),
    (PATH.replace("fps = 1.0", "fps = 0.0"), "camera_path.fps"),
    (PATH[:PATH.index("keys = [")] + 'keys = [{ camera = "top", time = 0.0 }]\n', "camera_path.keys"),  # one key
])
def test_bad_paths_exit_2_with_one_line(tmp_path, capsys, bad, key):
    path = write_scene(tmp_path, bad, "bad")
    out = tmp_path / "tt"
    assert main(["turntable", str(path), "-o", str(out), "--path", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0] and "Traceback" not in err[0], err
    assert not out.exists() or not list(out.iterdir())


def test_path_needs_a_camera_path_table(tmp_path, capsys):
    path = write_scene(tmp_path, ROCK, "rock")
    assert main(["turntable", str(path), "-o", str(tmp_path / "tt"), "--path", "-q"]) == 2
    assert "camera_path" in capsys.readouterr().err


def test_sequence_renders_the_keys_and_resumes(tmp_path, capsys):
    path = write_scene(tmp_path, PATH, "rock")
    desc = load_scene(path)
    assert desc.camera_path.keys == [(0.0, "camera"), (1.0, "side"), (2.0, "top")]
    out = tmp_path / "seq"
    args = ["turntable", str(path), "-o", str(out), "--path", "--resolution", "24x14", "-q"]
    assert main(args + ["--mp4"]) == 0
    frames = sorted(out.glob("rock.*.exr"))
    assert [p.name for p in frames] == ["rock.1001.exr", "rock.1002.exr", "rock.1003.exr"]
    imgs = [read_exr(p) for p in frames]
    # fps = 1 over [0, 2]: the frames are the three keyed cameras themselves, each rendered with
    # its own sample stream; the header says so, and a render of what it says gives the same bits.
    for k, (img, name) in enumerate(zip(imgs, ["camera", "side", "top"])):
        c = desc.cameras[name]
        assert img.header["camera_origin"] == " ".join(f"{v:.9g}" for v in c.origin)
        assert img.header["stream"] == str(k)
        assert "depth" in img.layers and img.shape == (14, 24) and np.isfinite(img.rgb).all()
        rgb, _ = render_as_header_says(path, img.header)
        assert np.array_equal(img.rgb, rgb), f"frame {1001 + k} is not the render its header names"
    assert (out / "rock.mp4").stat().st_size > 0
    capsys.readouterr()
    stamps = [p.stat().st_mtime_ns for p in frames]
    frames[2].write_bytes(frames[2].read_bytes()[:100])  # a crash truncated the last frame
    assert main(args) == 0
    assert "2 complete frames skipped" in capsys.readouterr().out
    assert [p.stat().st_mtime_ns for p in frames[:2]] == stamps[:2]
    assert np.array_equal(read_exr(frames[2]).rgb, imgs[2].rgb)


def test_sample_streams_are_independent_and_reproducible(tmp_path):
    """A frame's sample stream changes its samples, not its image, and shares none of them with
    another frame's stream.

    * Reproducible: stream 0 twice gives the same bits.
    * The same image: streams 0 and 1 of one view differ by noise only (the golden tests' Welch
      tests: pixels, windows, image mean, coverage and depth).
    * Independent: the per-pixel noise of stream 0 and that of stream 1 are uncorrelated. Each
      stream's noise is measured against the same stream of another base seed (``n_k = a_k - b_k``,
      expectation 0; ``b_0``, ``b_1`` share what ``a_0``, ``a_1`` share, so
      ``corr(n_0, n_1)`` is the streams' own correlation), scaled per pixel by the pixels' pooled
      standard error (that keeps bright, noisy pixels from dominating). For N independent pixel
      pairs the sample correlation has a spread of 1/sqrt(N) around 0 (measured: 0.040 over 30
      base seeds at the ~600 noisy pixels here, worst |r| 0.086); the bound is 5/sqrt(N) = 0.2.
      Four passes a render: streams that overlapped by one pass seed of four (say, a stream
      added to the pass index instead of mixed in) would correlate by 0.25, by three of four 0.75
      (measured 0.72-0.79), while their images still differ and pass Welch's tests, which assume
      independent renders and are then only too lenient.
    """
    from arches_render.imaging.welch import welch_compare
    from arches_render.render.renderer import build_scene, moments_of, render_layers
    desc = load_scene(write_scene(tmp_path, ROCK, "rock"))
    scene = build_scene(desc, "field", 48, 36, moments=True)
    spp, passes = 16, 4

    def render(seed, stream):
        return moments_of(*render_layers(scene, spp, seed=seed, passes=passes, stream=stream), spp)
    a0, a1, again, b0, b1 = render(3, 0), render(3, 1), render(3, 0), render(4, 0), render(4, 1)
    assert np.array_equal(a0.mean, again.mean) and np.array_equal(a0.m2, again.m2)
    assert not np.array_equal(a0.mean, a1.mean), "streams 0 and 1 drew the same samples"
    result = welch_compare(a0, a1)
    assert result.passed, result.summary()
    se = np.sqrt(sum(m.mean_variance()[..., 3] for m in (a0, a1, b0, b1)))
    noisy = se > 0  # the sky is a constant light: no noise to correlate there
    n0, n1 = ((a.mean4[..., 3] - b.mean4[..., 3])[noisy] / se[noisy] for a, b in ((a0, b0), (a1, b1)))
    assert noisy.sum() > 400, noisy.sum()
    r, bound = np.corrcoef(n0, n1)[0, 1], 5.0 / np.sqrt(noisy.sum())
    assert abs(r) < bound, f"the noise of streams 0 and 1 correlates by {r:.3f} (bound {bound:.3f})"
