"""Render jobs as a render farm meets them: the in-process scene cache sees every edit of a
scene's inputs, and `render --tiles/--workers/--scheduler` give the same image as a
serial tiled render (bit for bit) and the untiled image within its noise."""

from __future__ import annotations

import os

import numpy as np
import pytest

from helpers import variant
from production_helpers import FLAT, write_scene

variant()

from arches_render.cli import main  # noqa: E402
from arches_render.imaging.exr import read_exr  # noqa: E402

# The FLAT scene with its mesh ball read from a file next to the scene.
WITH_FILE = FLAT.replace('shape = "sphere"\ntranslate = [0.0, 0.0, 1.0]',
                         'file = "ball.ply"\ntranslate = [0.0, 0.0, 0.0]')


def _ball(path, center):
    import trimesh
    trimesh.creation.icosphere(subdivisions=2, radius=1.0).apply_translation(center).export(path)


def test_scene_cache_sees_edits_of_files_the_scene_names(tmp_path):
    from arches_render.render.jobs import RenderJob, clear_cache, run_job, scene_inputs
    assert WITH_FILE != FLAT
    scene = write_scene(tmp_path, WITH_FILE, "flat")
    _ball(tmp_path / "ball.ply", (0.0, 0.0, 1.0))
    job = RenderJob(scene=str(scene), width=32, height=18, spp=1, aovs=True)
    clear_cache()
    _, before = run_job(job)
    key = scene_inputs(scene)
    st = scene.stat()
    # Move the ball 3 m along +x in its file; the scene file itself keeps its bytes and times.
    _ball(tmp_path / "ball.ply", (-3.0, 0.0, 1.0))
    os.utime(scene, ns=(st.st_atime_ns, st.st_mtime_ns))
    _, after = run_job(job)
    clear_cache()
    _, fresh = run_job(job)
    cov = {k: after["coverage"][0][..., i] for i, k in enumerate(after["coverage"][1])}
    old = {k: before["coverage"][0][..., i] for i, k in enumerate(before["coverage"][1])}
    # The mesh covers other pixels now (it moved), exactly as a cold build renders it.
    assert np.abs(cov["mesh"] - old["mesh"]).sum() > 20
    for name in fresh:
        assert np.array_equal(after[name][0], fresh[name][0]), name
    assert scene_inputs(scene) != key
    # Unrelated strings (material names, presets) are not files; an unchanged scene keeps its key.
    assert scene_inputs(scene) == scene_inputs(scene)


def test_modes_of_one_scene_load_and_polygonize_it_once(tmp_path, monkeypatch):
    """Field and mesh, with and without AOVs: one load of the scene (its generators run
    once), one marching-cubes mesh and one built scene per geometry (the modes with and
    without AOVs differ by their integrator only); each mode renders as from a cold process."""
    from arches_render.render import jobs, renderer
    from arches_render.render.jobs import RenderJob, clear_cache, run_job
    scene = write_scene(tmp_path, FLAT, "flat")
    loads, meshes, builds = [], [], []
    load, polygonize, build = jobs.load_scene, renderer.polygonize, jobs.build_scene
    monkeypatch.setattr(jobs, "load_scene", lambda path: loads.append(path) or load(path))
    monkeypatch.setattr(jobs, "build_scene", lambda *a, **k: builds.append(a[1]) or build(*a, **k))
    monkeypatch.setattr(renderer, "polygonize", lambda *a, **k: meshes.append(a) or polygonize(*a, **k))
    clear_cache()
    modes = [dict(geometry=g, aovs=a) for g in ("field", "mesh") for a in (True, False)]
    warm = [run_job(RenderJob(scene=str(scene), width=32, height=18, spp=1, **m)) for m in modes]
    assert len(loads) == 1 and len(meshes) == 1 and builds == ["field", "mesh"]
    for m, (rgb, layers) in zip(modes, warm):
        clear_cache()
        cold_rgb, cold_layers = run_job(RenderJob(scene=str(scene), width=32, height=18, spp=1, **m))
        assert np.array_equal(rgb, cold_rgb), m
        assert sorted(layers) == sorted(cold_layers) and all(
            np.array_equal(layers[k][0], cold_layers[k][0]) for k in layers), m
    assert len(loads) == 5 and len(meshes) == 3
    # An edit of the scene loads it anew.
    clear_cache()
    run_job(RenderJob(scene=str(scene), width=32, height=18, spp=1))
    scene.write_text(FLAT.replace("elevation = 50.0", "elevation = 51.0"))
    run_job(RenderJob(scene=str(scene), width=32, height=18, spp=1))
    assert len(loads) == 7


def test_scene_inputs_follow_the_scene_text(tmp_path):
    from arches_render.render.jobs import scene_inputs
    scene = write_scene(tmp_path, FLAT, "flat")
    a = scene_inputs(scene)
    st = scene.stat()
    scene.write_text(FLAT.replace("elevation = 50.0", "elevation = 51.0"))
    os.utime(scene, ns=(st.st_atime_ns, st.st_mtime_ns))  # same mtime: the text decides
    assert scene_inputs(scene) != a


@pytest.fixture(scope="module")
def tiled(tmp_path_factory):
    """`render --tiles 4` of the flat scene, serially: the reference for the cluster runs."""
    d = tmp_path_factory.mktemp("tiles")
    scene = write_scene(d, FLAT, "flat")
    out = d / "serial.exr"
    assert main(["render", str(scene), "-o", str(out), "--spp", "4", "--tiles", "4", "-q"]) == 0
    return scene, read_exr(out)


def _same_image(a, b):
    assert np.array_equal(a.rgb, b.rgb)
    assert sorted(a.layers) == sorted(b.layers)
    for name in a.layers:
        assert np.array_equal(a.layers[name], b.layers[name]), name


def test_render_tiles_on_workers_and_on_a_scheduler_equal_the_serial_tiles(tiled, tmp_path, dask_cluster):
    scene, serial = tiled
    assert serial.header["tiles"] == "4"
    assert main(["render", str(scene), "-o", str(tmp_path / "w.exr"), "--spp", "4", "--workers", "1", "-q"]) == 0
    _same_image(serial, read_exr(tmp_path / "w.exr"))  # --workers alone means 4 tiles
    assert main(["render", str(scene), "-o", str(tmp_path / "s.exr"), "--spp", "4", "--tiles", "4",
                 "--scheduler", dask_cluster.scheduler.address, "-q"]) == 0
    _same_image(serial, read_exr(tmp_path / "s.exr"))
    # Another tiling is other sample streams: other bits, the same coverage of every pixel.
    assert main(["render", str(scene), "-o", str(tmp_path / "t3.exr"), "--spp", "4", "--tiles", "3", "-q"]) == 0
    t3 = read_exr(tmp_path / "t3.exr")
    assert not np.array_equal(t3.rgb, serial.rgb)
    assert np.allclose(t3.layers["coverage"].sum(axis=-1), 1.0)


def test_render_tile_options_reject_bad_values(tiled, tmp_path, capsys):
    scene, _ = tiled
    out = tmp_path / "x.exr"
    assert main(["render", str(scene), "-o", str(out), "--tiles", "2", "--geometry", "mesh", "-q"]) == 2
    assert "--tiles/--workers/--scheduler" in capsys.readouterr().err
    for bad in (["--tiles", "0"], ["--workers", "0"], ["--workers", "2", "--scheduler", "tcp://x:1"]):
        with pytest.raises(SystemExit) as exc:
            main(["render", str(scene), "-o", str(out), *bad, "-q"])
        assert exc.value.code == 2
        assert capsys.readouterr().err.strip().splitlines()[-1].startswith("arches-render render: error:")
    assert not out.exists()


ONE_CORE = """
import os, sys
os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # before Dr.Jit starts its pool
from arches_render.backend import set_variant
set_variant()
import drjit as dr
from arches_render.render.jobs import RenderJob, run_job
print("threads", dr.thread_count(), flush=True)
for scene in sys.argv[1:]:  # each scene loaded after a one-thread job
    rgb, _ = run_job(RenderJob(scene=scene, width=16, height=9, spp=1, aovs=False, threads=1))
    print("rendered", float(rgb.mean()), dr.thread_count(), flush=True)
"""


def test_scenes_that_read_exr_files_load_on_one_core_and_in_one_thread_jobs(tmp_path):
    """Mitsuba's EXR reading runs OpenEXR's tasks on Dr.Jit's thread pool and waits for
    them: with one thread in the pool (a one-core machine, or a job given one thread, as
    two Dask workers on two cores get) an environment map's load hung for ever. A
    process pinned to one core renders two such scenes in one-thread jobs, each loaded
    after the last job left the pool one thread; it hangs (the timeout fails it) without
    ``backend.io_threads``."""
    import subprocess
    import sys
    from arches_render.imaging.exr import write_exr
    env = np.zeros((16, 32, 3), np.float32)
    env[4:6, 10:12] = 50.0
    env += 0.2
    write_exr(tmp_path / "sky.exr", env, half=False)
    lit = FLAT.replace('type = "sunsky"\nelevation = 50.0\nazimuth = 30.0', 'type = "envmap"\nfile = "sky.exr"')
    assert lit != FLAT
    scenes = [str(write_scene(tmp_path, lit, "a")), str(write_scene(tmp_path, lit.replace("[0.2, 0.4, 0.6]",
                                                                                   "[0.6, 0.4, 0.2]"), "b"))]
    out = subprocess.run([sys.executable, "-c", ONE_CORE, *scenes], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.split("\n")
    assert lines[0] == "threads 2"  # raised from the one core's one thread
    rendered = [line.split() for line in lines if line.startswith("rendered")]
    assert len(rendered) == 2 and all(float(r[1]) > 0 and r[2] == "1" for r in rendered), out.stdout
