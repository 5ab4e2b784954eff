"""Issue 38: a render process that dies by a signal is a one-line error naming scene, frame or tile,
and signal; never a hang, never a job retried in silence.

The crash is injected by the test-only kill point ``render.job@SIGSEGV``
(:mod:`arches_render.faults`): the process rendering a job sends itself SIGSEGV, as
Mitsuba or a kernel dies of one. A Dask worker renders in a child process
(:mod:`arches_render.render.isolated`), so the worker lives on and its job fails once.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from helpers import REPO, variant
from production_helpers import FLAT, write_scene

KILL = "ARCHES_TEST_KILL_AT"


def _cli(env_kill, *args):
    """``arches-render ARGS`` in a process of its own, with the kill point ``env_kill``."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path), **{KILL: env_kill})
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "arches_render.cli", *map(str, args)], cwd=REPO, env=env,
                       capture_output=True, text=True, timeout=300)
    return r.returncode, r.stderr, time.monotonic() - t0


def test_render_process_crash_is_an_error_and_the_next_job_gets_a_fresh_process(tmp_path, monkeypatch):
    from arches_render.render.isolated import RenderCrash, RenderProcess
    from arches_render.render.jobs import RenderJob
    from arches_render.scene import SceneError
    scene = write_scene(tmp_path, FLAT, "flat")
    job = RenderJob(scene=str(scene), width=16, height=9, spp=1, label="frame 1007")
    proc = RenderProcess()
    try:
        rgb, layers = proc.run(job)
        assert rgb.shape == (9, 16, 3) and "position" in layers
        first = proc.pid
        # A job's own error comes back as it was raised (the process lives on).
        bad = tmp_path / "bad.toml"
        bad.write_text("[camera]\norigin = 1\n")
        with pytest.raises(SceneError, match="camera"):
            proc.run(job.with_(scene=str(bad)))
        assert proc.pid == first
        # A crash: the next job starts a process that inherits the kill point, so it dies too.
        monkeypatch.setenv(KILL, "render.job@SIGSEGV")
        proc.close()
        with pytest.raises(RenderCrash) as crash:
            proc.run(job)
        msg = str(crash.value)
        assert "\n" not in msg and msg.startswith(f"{scene}: frame 1007 (field, AOVs): "), msg
        assert msg.endswith("the render process died by SIGSEGV (Segmentation fault)"), msg
        assert proc.pid is None
        monkeypatch.delenv(KILL)
        again, _ = proc.run(job)  # a fresh process, the same pixels
        assert proc.pid not in (None, first) and (again == rgb).all()
    finally:
        proc.close()


def test_cli_tiles_and_turntable_on_workers_report_a_sigsegv_in_one_line(tmp_path):
    scene = write_scene(tmp_path, FLAT, "flat")
    rc, err, took = _cli("render.job@SIGSEGV", "render", scene, "-o", tmp_path / "t.exr", "--tiles", "2",
                         "--workers", "1", "--spp", "1", "--resolution", "16x9", "-q")
    assert rc == 1 and err.count("\n") == 1, err
    assert err.startswith(f"arches-render: error: {scene}: tile 0 of 2 (x 0-7, y 0-8) (field, AOVs): "
                          "the render process died by SIGSEGV"), err
    assert not (tmp_path / "t.exr").exists()
    # The second frame's process dies (the first frame's lived): frame 1002, after 1001 was written.
    out = tmp_path / "tt"
    rc, err, took = _cli("render.job:2@SIGSEGV", "turntable", scene, "-o", out, "--frames", "3", "--workers", "1",
                         "--spp", "1", "--resolution", "16x9", "-q")
    assert rc == 1 and err.count("\n") == 1, err
    assert err.startswith(f"arches-render: error: {scene}: frame 1002 (field, AOVs): the render process died "
                          "by SIGSEGV"), err
    assert sorted(p.name for p in out.glob("*.exr")) == ["flat.1001.exr"]


def test_a_crash_on_a_worker_fails_its_job_once_and_the_worker_lives(tmp_path, monkeypatch):
    """No Dask retry: the worker process is the same before and after, and the error names the tile."""
    variant()
    from arches_render.render.distributed import dask_client, render_tiled
    from arches_render.render.isolated import RenderCrash
    from arches_render.render.jobs import RenderJob
    scene = write_scene(tmp_path, FLAT, "flat")
    monkeypatch.setenv(KILL, "render.job:2@SIGSEGV")  # the workers (and their render processes) inherit it
    job = RenderJob(scene=str(scene), width=16, height=9, spp=1)
    with dask_client(workers=1) as client:
        pid = client.run(os.getpid)
        with pytest.raises(RenderCrash, match=r": tile 1 of 3 \(x 5-10, y 0-8\) \(field, AOVs\): the render "
                                              r"process died by SIGSEGV"):
            render_tiled(job, 3, client)
        assert client.run(os.getpid) == pid


def test_a_worker_killed_from_outside_as_often_as_dask_allows_is_one_line_naming_the_frame(tmp_path, monkeypatch):
    """``KilledWorker`` (the worker process itself killed, here at its first task with no retry
    allowed) becomes the same one-line error."""
    variant()
    import dask
    from arches_render.render.distributed import dask_client
    from arches_render.render.isolated import RenderCrash
    from arches_render.render.turntable import plan_turntable, render_turntable
    from arches_render.scene import load_scene
    scene = write_scene(tmp_path, FLAT, "flat")
    plan = plan_turntable(load_scene(scene), scene, tmp_path, 2, 1, 16, 9)
    monkeypatch.setenv(KILL, "render.task@SIGKILL")
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}), dask_client(workers=1) as client:
        with pytest.raises(RenderCrash) as crash:
            render_turntable(plan, client=client)
    msg = str(crash.value)
    assert "\n" not in msg and f"{scene}: frame 100" in msg, msg
    assert "the Dask worker running it died, 1 time (the last was tcp://" in msg, msg
