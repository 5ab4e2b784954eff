"""`arches-render turntable`: seamless orbit, atomic numbered frames, resume after a
crash, MP4 preview, and a Dask LocalCluster run that equals the serial run bit for bit."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from helpers import variant
from production_helpers import ROCK, write_scene

variant()

from arches_render.cli import main  # noqa: E402
from arches_render.imaging.exr import read_exr  # noqa: E402
from arches_render.render.turntable import FIRST_FRAME, orbit_camera  # noqa: E402


@pytest.fixture(scope="module")
def rock(tmp_path_factory):
    return write_scene(tmp_path_factory.mktemp("rock"), ROCK, "rock")


def test_orbit_is_seamless_and_uniform():
    origin, target, up = [0.0, -6.0, 2.5], [0.0, 0.0, 0.6], [0.0, 0.0, 1.0]
    n = 7
    cams = np.array([orbit_camera(origin, target, up, k, n) for k in range(n + 1)])
    assert np.array_equal(cams[n], cams[0])           # frame N+1 is frame 1, bit for bit
    assert np.array_equal(cams[0], np.array(origin))  # frame 1 is the scene's camera
    v = cams - np.array(target)
    r = np.linalg.norm(v[:, :2], axis=1)
    assert np.allclose(r, 6.0, rtol=1e-12) and np.allclose(cams[:, 2], 2.5, atol=1e-12)
    ang = np.diff(np.unwrap(np.arctan2(v[:, 1], v[:, 0])))
    assert np.allclose(ang, 2 * math.pi / n, atol=1e-12)
    # A tilted up axis: the orbit stays on a circle about that axis.
    tilted = [orbit_camera(origin, target, [0.0, 0.3, 1.0], k, 5) for k in range(6)]
    assert np.array_equal(tilted[5], tilted[0])


def test_turntable_frames_resume_and_mp4(rock, tmp_path, capsys):
    import imageio_ffmpeg
    out = tmp_path / "tt"
    args = ["turntable", str(rock), "-o", str(out), "--frames", "3", "--resolution", "33x19", "-q"]
    assert main(args + ["--mp4"]) == 0
    frames = [out / f"rock.{FIRST_FRAME + k}.exr" for k in range(3)]
    assert [p.name for p in frames] == ["rock.1001.exr", "rock.1002.exr", "rock.1003.exr"]
    imgs = [read_exr(p) for p in frames]
    for k, img in enumerate(imgs):
        assert img.shape == (19, 33) and "depth" in img.layers
        assert img.header["frame"] == str(FIRST_FRAME + k) and img.header["scene_name"] == "rock"
        assert img.header["camera_origin"] == " ".join(
            f"{v:.9g}" for v in orbit_camera([0, -6, 2.5], [0, 0, 0.6], [0, 0, 1], k, 3))
    assert not np.array_equal(imgs[0].rgb, imgs[1].rgb)  # the camera moved
    assert not list(out.glob(".*"))  # no temporary files left
    # The MP4 (odd size padded to even) holds the three frames.
    reader = imageio_ffmpeg.read_frames(str(out / "rock.mp4"))
    meta = next(reader)
    assert tuple(meta["size"]) == (34, 20)
    assert sum(1 for _ in reader) == 3

    # Rerun: every frame is complete and is skipped.
    stamps = [p.stat().st_mtime_ns for p in frames]
    capsys.readouterr()
    assert main(args) == 0
    assert "3 complete frames skipped" in capsys.readouterr().out
    assert [p.stat().st_mtime_ns for p in frames] == stamps

    # A crash left frame 1002 truncated: only that frame is rendered again.
    data = frames[1].read_bytes()
    frames[1].write_bytes(data[: len(data) // 2])
    os.utime(frames[0], ns=(stamps[0], stamps[0]))
    assert main(args) == 0
    assert "2 complete frames skipped" in capsys.readouterr().out
    assert frames[0].stat().st_mtime_ns == stamps[0] and frames[2].stat().st_mtime_ns == stamps[2]
    again = read_exr(frames[1])
    assert np.array_equal(again.rgb, imgs[1].rgb)  # deterministic: the same bits as before

    # A frame of another render (other spp) is not taken as complete.
    assert main(args[:-1] + ["--spp", "1", "-q"]) == 0
    assert "skipped" not in capsys.readouterr().out


def test_turntable_on_dask_localcluster_equals_serial(rock, tmp_path, dask_cluster):
    from arches_render.render.turntable import plan_turntable, render_turntable
    from arches_render.scene import load_scene
    desc = load_scene(rock)
    serial = plan_turntable(desc, rock, tmp_path / "serial", 4, 2, 32, 18)
    (tmp_path / "serial").mkdir()
    render_turntable(serial)
    (tmp_path / "dask").mkdir()
    dist = plan_turntable(desc, rock, tmp_path / "dask", 4, 2, 32, 18)
    client = dask_cluster
    assert len(client.scheduler_info()["workers"]) == 2
    written = render_turntable(dist, client=client)
    # The CLI on a running cluster (--scheduler ADDRESS).
    assert main(["turntable", str(rock), "-o", str(tmp_path / "cli"), "--frames", "4", "--spp", "2",
                 "--resolution", "32x18", "--scheduler", client.scheduler.address, "-q"]) == 0
    # Golden regeneration on the same cluster: the same reference bits as serially,
    # and as the golden tests' own renderer (render_moments).
    from arches_render.render.distributed import regenerate_goldens
    kw = dict(width=24, height=16, ref_spp=64, test_spp_of=lambda name: 16)
    g_dask = regenerate_goldens([rock], tmp_path / "g_dask", client=client, **kw)[0]
    g_serial = regenerate_goldens([rock], tmp_path / "g_serial", **kw)[0]
    from arches_render.imaging.golden import load_golden
    from arches_render.render.renderer import build_scene, render_moments
    direct = render_moments(build_scene(desc, "field", 24, 16, moments=True), 64, seed=0)
    stored = load_golden("rock", tmp_path / "g_dask").ref
    assert np.array_equal(stored.mean, np.float32(direct.mean))
    for name in ("mean", "m2", "coverage", "depth", "depth_m2"):
        assert np.array_equal(getattr(g_dask.ref, name), getattr(g_serial.ref, name)), name
        assert np.array_equal(getattr(g_dask.ref, name), getattr(stored, name)), name
    assert sorted(p.name for p in written) == [f"rock.{FIRST_FRAME + k}.exr" for k in range(4)]
    for a, b in zip(serial.paths, dist.paths):
        x, y = read_exr(a), read_exr(b)
        assert np.array_equal(x.rgb, y.rgb), a.name
        for name in x.layers:
            assert np.array_equal(x.layers[name], y.layers[name]), (a.name, name)
        assert x.header == y.header
        z = read_exr(tmp_path / "cli" / a.name)
        assert np.array_equal(x.rgb, z.rgb) and z.header["camera_origin"] == x.header["camera_origin"]


def test_turntable_bad_input(rock, tmp_path, capsys):
    assert main(["turntable", str(rock), "-o", str(tmp_path / "x.exr")]) == 2
    assert "folder" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["turntable", str(rock), "-o", str(tmp_path), "--frames", "0"])
    assert main(["turntable", str(tmp_path / "missing.toml"), "-o", str(tmp_path)]) == 2


def test_turntable_of_a_mesh_only_scene(tmp_path):
    """Scenes without a [field] (evolved G-map volumes, say) orbit their camera target too."""
    from helpers import SCENES
    assert main(["turntable", str(SCENES / "gmaps_arch.toml"), "-o", str(tmp_path), "--frames", "2",
                 "--spp", "1", "--resolution", "16x9", "-q"]) == 0
    frames = sorted(tmp_path.glob("gmaps_arch.*.exr"))
    assert [f.name for f in frames] == ["gmaps_arch.1001.exr", "gmaps_arch.1002.exr"]
    a, b = (read_exr(f).rgb for f in frames)
    assert a.mean() > 0 and not np.array_equal(a, b)
