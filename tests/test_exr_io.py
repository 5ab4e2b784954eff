"""EXR and PNG output: round trips, metadata, layers, atomic writes, read errors."""

from __future__ import annotations

import os

import numpy as np
import pytest

from arches_render.atomic import atomic_path, atomic_write
from arches_render.imaging.exr import ExrError, read_exr, write_exr
from arches_render.imaging.preview import encode_srgb, to_srgb8, write_png


HALF_ATOL = 2.0 ** -25


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if ".tmp-" in p.name)


@pytest.fixture
def rgb():
    rng = np.random.default_rng(7)
    # Spread over several octaves, as radiance is, to exercise half's exponent.
    return (rng.random((21, 34, 3)) * np.exp2(rng.integers(-6, 6, (21, 34, 3)))).astype(np.float32)


def test_round_trip_half_precision(tmp_path, rgb):
    path = write_exr(tmp_path / "img.exr", rgb)
    img = read_exr(path)
    assert img.rgb.dtype == np.float32 and img.rgb.shape == rgb.shape
    # half: 11 significant bits, round to nearest: relative error <= 2**-11
    # (absolute 2**-25 among the subnormals below 2**-14)
    np.testing.assert_allclose(img.rgb, rgb, rtol=2.0 ** -11, atol=HALF_ATOL)
    np.testing.assert_array_equal(img.rgb, rgb.astype(np.float16).astype(np.float32))
    assert img.layers == {}


def test_full_float_and_clipping(tmp_path, rgb):
    img = read_exr(write_exr(tmp_path / "f.exr", rgb, half=False))
    np.testing.assert_array_equal(img.rgb, rgb)
    big = rgb.copy()
    big[0, 0] = 1e6
    img = read_exr(write_exr(tmp_path / "h.exr", big))
    assert np.all(np.isfinite(img.rgb)) and img.rgb[0, 0, 0] == 65504.0


def test_header_attributes(tmp_path, rgb):
    header = {"scene": "arch_sunset", "seed": 3, "spp": 4096, "version": "0.1.0", "exposure": 0.5,
              "camera": "look_at(0, -4, 2) fov 40"}
    img = read_exr(write_exr(tmp_path / "h.exr", rgb, header=header))
    # every value comes back as its str(); 'version' survives although OpenEXR
    # reserves that attribute name (ours are stored as 'arches:<key>')
    assert img.header == {k: str(v) for k, v in header.items()}
    with pytest.raises(ValueError):
        write_exr(tmp_path / "bad.exr", rgb, header={"": "x"})


def test_layers(tmp_path, rgb):
    h, w = rgb.shape[:2]
    depth = np.linspace(0, 100, h * w, dtype=np.float32).reshape(h, w)
    normal = np.dstack([np.zeros((h, w)), np.ones((h, w)) * 0.6, np.ones((h, w)) * 0.8]).astype(np.float32)
    layers = {"albedo": rgb * 0.5, "depth": depth, "normal": (normal, "XYZ"), "aov.mask": depth[..., None] > 50}
    img = read_exr(write_exr(tmp_path / "aov.exr", rgb, layers=layers))
    assert set(img.layers) == {"albedo", "depth", "normal", "aov.mask"}
    assert img.layer_channels == {"albedo": ("R", "G", "B"), "depth": ("Y",), "normal": ("X", "Y", "Z"),
                                  "aov.mask": ("Y",)}
    np.testing.assert_allclose(img.layers["albedo"], rgb * 0.5, rtol=2.0 ** -11, atol=HALF_ATOL)
    np.testing.assert_allclose(img.layers["depth"], depth, rtol=2.0 ** -11, atol=HALF_ATOL)
    np.testing.assert_allclose(img.layers["normal"], normal, rtol=2.0 ** -11, atol=HALF_ATOL)
    np.testing.assert_array_equal(img.layers["aov.mask"], (depth > 50).astype(np.float32))
    with pytest.raises(ValueError, match="shape"):
        write_exr(tmp_path / "bad.exr", rgb, layers={"depth": depth[:-1]})
    with pytest.raises(ValueError, match="channels"):
        write_exr(tmp_path / "bad.exr", rgb, layers={"uv": np.zeros((h, w, 2))})
    assert not (tmp_path / "bad.exr").exists()


def test_shape_validation(tmp_path):
    with pytest.raises(ValueError, match="H x W x 3"):
        write_exr(tmp_path / "x.exr", np.zeros((4, 4)))


def test_atomic_write_leaves_nothing_when_writer_raises(tmp_path, rgb, monkeypatch):
    import OpenEXR

    target = tmp_path / "img.exr"

    class Exploding:
        """Writes half a file, then fails, like a writer running out of disk."""

        def __init__(self, header, channels):
            pass

        def write(self, f):
            f.write(b"v/1\x01" + b"\0" * 1000)
            raise OSError("disk full")

    monkeypatch.setattr(OpenEXR, "File", Exploding)
    with pytest.raises(OSError, match="disk full"):
        write_exr(target, rgb)
    assert not target.exists() and _leftovers(tmp_path) == []

    # An existing file survives a failed overwrite untouched.
    monkeypatch.undo()
    write_exr(target, rgb)
    before = target.read_bytes()
    monkeypatch.setattr(OpenEXR, "File", Exploding)
    with pytest.raises(OSError):
        write_exr(target, rgb * 2)
    assert target.read_bytes() == before and _leftovers(tmp_path) == []


def test_atomic_helpers(tmp_path):
    target = tmp_path / "notes.txt"
    with pytest.raises(RuntimeError):
        with atomic_write(target, "w", encoding="utf-8") as f:
            f.write("half")
            assert f.name.endswith(".txt") and os.path.dirname(f.name) == str(tmp_path)
            raise RuntimeError
    assert not target.exists() and _leftovers(tmp_path) == []
    with atomic_write(target, "w", encoding="utf-8") as f:
        f.write("whole")
    assert target.read_text() == "whole" and _leftovers(tmp_path) == []
    assert (target.stat().st_mode & 0o777) == 0o666 & ~_umask()

    out = tmp_path / "img.png"
    with atomic_path(out) as tmp:
        assert tmp.suffix == ".png" and tmp.name.startswith(".img.tmp-")
        tmp.write_bytes(b"by name")
    assert out.read_bytes() == b"by name" and _leftovers(tmp_path) == []
    from arches_render.atomic import OutputError
    with pytest.raises(OutputError, match="did not produce") as exc:  # one line naming the output
        with atomic_path(tmp_path / "none.png") as tmp:
            tmp.unlink()  # a writer that produced nothing
    assert "none.png" in str(exc.value)
    assert not (tmp_path / "none.png").exists() and _leftovers(tmp_path) == []
    with pytest.raises(ValueError):
        with atomic_write(target, "rb"):
            pass


def _umask():
    m = os.umask(0o022)
    os.umask(m)
    return m


def test_read_errors_name_the_file(tmp_path, rgb):
    missing = tmp_path / "missing.exr"
    with pytest.raises(ValueError, match="missing.exr"):
        read_exr(missing)
    junk = tmp_path / "junk.exr"
    junk.write_bytes(b"not an exr file" * 20)
    with pytest.raises(ExrError, match="junk.exr"):
        read_exr(junk)
    good = write_exr(tmp_path / "good.exr", rgb)
    cut = tmp_path / "cut.exr"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(ValueError, match="cut.exr"):
        read_exr(cut)


def test_read_rejects_non_rgb(tmp_path):
    import OpenEXR

    path = tmp_path / "grey.exr"
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {"Y": np.ones((4, 4), np.float32)}).write(str(path))
    with pytest.raises(ValueError, match="grey.exr.*no channel"):
        read_exr(path)


def test_srgb_preview():
    # sRGB: linear 0.2140 is about mid grey (0.4999 encoded = 127.49 / 255).
    px = to_srgb8(np.full((2, 2, 3), 0.2140))
    assert px.dtype == np.uint8 and px.shape == (2, 2, 3)
    assert abs(int(px[0, 0, 0]) - 128) <= 1
    np.testing.assert_array_equal(to_srgb8(np.array([0.0, 1.0, 7.0, -1.0, np.nan])), [0, 255, 255, 0, 0])
    np.testing.assert_allclose(encode_srgb([0.0031308, 0.5]), [0.04044994, 0.7353569], atol=1e-6)
    # one stop of exposure doubles the linear value
    np.testing.assert_array_equal(to_srgb8(np.array([0.1]), exposure=1.0), to_srgb8(np.array([0.2])))


def test_write_png_round_trip(tmp_path):
    image = pytest.importorskip("PIL.Image")
    lin = np.random.default_rng(1).random((9, 13, 3)).astype(np.float32)
    path = write_png(tmp_path / "p.png", lin)
    with image.open(path) as im:
        assert im.mode == "RGB" and im.size == (13, 9)
        np.testing.assert_array_equal(np.asarray(im), to_srgb8(lin))
    grey = np.arange(12, dtype=np.uint8).reshape(3, 4) * 20
    with image.open(write_png(tmp_path / "g.png", np.dstack([grey] * 3))) as im:
        np.testing.assert_array_equal(np.asarray(im)[..., 0], grey)
    assert _leftovers(tmp_path) == []
