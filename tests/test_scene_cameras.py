"""Named cameras (``[cameras.NAME]``), ``--camera`` of render and turntable, ``info``'s list, clip planes."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from helpers import variant
from test_scene_cli import MINIMAL, run_cli, write_scene

NAMED = MINIMAL.replace("""[camera]
origin = [0.0, -6.0, 2.0]
target = [0.0, 0.0, 0.5]
""", textwrap.dedent("""
    [cameras.wide]
    origin = [0.0, -6.0, 2.0]
    target = [0.0, 0.0, 0.5]
    fov = 60.0
    [cameras.close]
    origin = [2.5, -2.5, 1.0]
    target = [0.0, 0.0, 0.5]
    fov = 30.0
"""))


def test_named_cameras_load_in_file_order(tmp_path):
    variant()
    from arches_render.scene import SceneError, load_scene
    desc = load_scene(write_scene(tmp_path, NAMED))
    assert list(desc.cameras) == ["wide", "close"]
    assert desc.camera is desc.cameras["wide"] and desc.camera.fov == 60.0
    assert desc.select_camera("close").origin == [2.5, -2.5, 1.0] and desc.camera.fov == 30.0
    with pytest.raises(SceneError, match="has no camera 'far'.*wide, close"):
        desc.select_camera("far")
    # [camera] alone keeps working: one camera named "camera".
    plain = load_scene(write_scene(tmp_path, MINIMAL, "plain.toml"))
    assert list(plain.cameras) == ["camera"] and plain.camera.origin == [0.0, -6.0, 2.0]
    # Both: [camera] first.
    both = load_scene(write_scene(tmp_path, MINIMAL + NAMED[NAMED.index("[cameras.wide]"):NAMED.index("[[lights]]")],
                                  "both.toml"))
    assert list(both.cameras) == ["camera", "wide", "close"]


@pytest.mark.parametrize("text,key", [
    (NAMED.replace("fov = 30.0", "fov = 300.0"), "cameras.close.fov"),
    (NAMED.replace("[cameras.close]\norigin = [2.5, -2.5, 1.0]", "[cameras.close]\norigin = [0.0, 0.0, 0.5]"),
     "cameras.close.target"),
    (NAMED.replace("fov = 30.0", "fov = 30.0\nzoom = 2.0"), "cameras.close.zoom"),
    (MINIMAL.replace("[camera]\norigin = [0.0, -6.0, 2.0]\ntarget = [0.0, 0.0, 0.5]\n", ""), "camera"),
])
def test_bad_named_cameras_exit_2(tmp_path, text, key):
    path = write_scene(tmp_path, text)
    res = run_cli("render", path, "-o", tmp_path / "o.exr", "-q")
    assert res.returncode == 2 and key in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert not (tmp_path / "o.exr").exists()


def test_render_and_turntable_take_camera_and_info_lists_them(tmp_path):
    from arches_render.imaging.exr import read_exr
    path = write_scene(tmp_path, NAMED)
    info = run_cli("info", path)
    assert info.returncode == 0 and "wide: origin [0, -6, 2]" in info.stdout and "close: origin" in info.stdout
    res = run_cli("render", path, "-o", tmp_path / "c.exr", "--camera", "close", "-q")
    assert res.returncode == 0, res.stderr
    close = read_exr(tmp_path / "c.exr")
    assert close.header["camera_origin"].split() == ["2.5", "-2.5", "1"]
    res = run_cli("render", path, "-o", tmp_path / "w.exr", "-q")
    wide = read_exr(tmp_path / "w.exr")
    assert wide.header["camera_origin"].split() == ["0", "-6", "2"]
    assert not np.allclose(wide.rgb, close.rgb)
    bad = run_cli("render", path, "-o", tmp_path / "x.exr", "--camera", "top", "-q")
    assert bad.returncode == 2 and "has no camera 'top'" in bad.stderr and not (tmp_path / "x.exr").exists()
    tt = run_cli("turntable", path, "-o", tmp_path / "tt", "--frames", "2", "--camera", "close", "-q")
    assert tt.returncode == 0, tt.stderr
    frame = read_exr(sorted((tmp_path / "tt").glob("*.exr"))[0])
    assert frame.header["camera_origin"].split() == ["2.5", "-2.5", "1"]


def test_clip_planes_follow_the_scene_extent():
    from arches_render.render.renderer import clip_planes
    near, far = clip_planes([-5e5, -5e5, -1e4], [5e5, 5e5, 4e4])
    assert far > 2.8e6 and near == pytest.approx(0.01)
    near, far = clip_planes([0, 0, 0], [0.1, 0.1, 0.1])
    assert near < 1e-4 and 0.34 < far < 2.0
