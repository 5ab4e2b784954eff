"""A cluster as a multi-machine user starts one: a ``dask scheduler`` process and two
``dask worker`` processes (subprocesses of the test, not a LocalCluster); the CLI's
``--scheduler`` renders tiles and a turntable on it, bit for bit as serial runs."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from helpers import variant
from production_helpers import FLAT, ROCK, write_scene

variant()

from arches_render.cli import main  # noqa: E402
from arches_render.imaging.exr import read_exr  # noqa: E402


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """``tcp://127.0.0.1:PORT`` of a scheduler with two worker processes (one with two
    Dask threads, as ``dask worker`` gives by default on two cores)."""
    from dask.distributed import Client
    d = tmp_path_factory.mktemp("cluster")
    addr = f"tcp://127.0.0.1:{_free_port()}"
    dask = [sys.executable, "-m", "dask"]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))  # workers import as we do
    logs = [open(d / f"{n}.log", "w") for n in ("scheduler", "w1", "w2")]
    procs = [subprocess.Popen([*dask, "scheduler", "--host", "127.0.0.1", "--port", addr.rsplit(":", 1)[1],
                               "--no-dashboard"], stdout=logs[0], stderr=subprocess.STDOUT, env=env)]
    try:
        for i, threads in ((1, 1), (2, 2)):
            procs.append(subprocess.Popen([*dask, "worker", addr, "--host", "127.0.0.1", "--nworkers", "1",
                                           "--nthreads", str(threads), "--no-dashboard", "--local-directory",
                                           str(d / f"w{i}")], stdout=logs[i], stderr=subprocess.STDOUT, env=env))
        deadline = time.monotonic() + 60
        while True:  # the scheduler takes a moment to listen
            try:
                client = Client(addr, timeout=5)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        with client:
            client.wait_for_workers(2, timeout=60)
            yield addr, client
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        for f in logs:
            f.close()


def _same_image(a, b):
    assert np.array_equal(a.rgb, b.rgb)
    assert sorted(a.layers) == sorted(b.layers)
    for name in a.layers:
        assert np.array_equal(a.layers[name], b.layers[name]), name


def _cli(*args):
    """``arches-render ARGS`` in a process of its own, as a user runs it."""
    r = subprocess.run([sys.executable, "-m", "arches_render.cli", *args], capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)), timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]


def test_scheduler_and_worker_processes_render_tiles_and_turntables_as_serial(cluster, tmp_path):
    addr, client = cluster
    pids = set(client.run(os.getpid).values())
    assert len(pids) == 2 and os.getpid() not in pids  # two worker processes of their own
    scene = write_scene(tmp_path, FLAT, "flat")
    assert main(["render", str(scene), "-o", str(tmp_path / "serial.exr"), "--spp", "2", "--tiles", "4",
                 "--resolution", "48x27", "-q"]) == 0
    _cli("render", str(scene), "-o", str(tmp_path / "dist.exr"), "--spp", "2", "--tiles", "4",
         "--resolution", "48x27", "--scheduler", addr, "-q")
    serial, dist = read_exr(tmp_path / "serial.exr"), read_exr(tmp_path / "dist.exr")
    _same_image(serial, dist)
    assert dist.header["tiles"] == "4" and float(np.mean(dist.rgb)) > 0

    rock = write_scene(tmp_path, ROCK, "rock")
    assert main(["turntable", str(rock), "-o", str(tmp_path / "ts"), "--frames", "4", "--spp", "2",
                 "--resolution", "32x18", "-q"]) == 0
    _cli("turntable", str(rock), "-o", str(tmp_path / "td"), "--frames", "4", "--spp", "2",
         "--resolution", "32x18", "--scheduler", addr, "-q")
    frames = sorted(p.name for p in (tmp_path / "ts").glob("*.exr"))
    assert len(frames) == 4 and frames == sorted(p.name for p in (tmp_path / "td").glob("*.exr"))
    images = [read_exr(tmp_path / "td" / f).rgb for f in frames]
    assert not np.array_equal(images[0], images[1])  # the orbit moves: a frame mix-up would show
    for f in frames:
        _same_image(read_exr(tmp_path / "ts" / f), read_exr(tmp_path / "td" / f))
    # Two worker processes on two cores: one Dr.Jit thread each, wherever a job ran.
    from arches_render.render.distributed import drjit_threads
    threads = [t for t in drjit_threads(client).values() if t is not None]
    from dask.system import CPU_COUNT
    assert threads and set(threads) == {max(1, CPU_COUNT // 2)}
