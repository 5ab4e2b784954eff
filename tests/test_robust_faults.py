"""SIGKILL at random moments, and a Dask worker lost mid-turntable (issue 17, "Faults").

For each of ``render``, ``turntable``, ``amplify``, ``rocks``, ``blocks`` and
``layers``: a subprocess is killed (SIGKILL: no handler runs) after a random delay,
several times. After every kill the output folder holds only complete outputs
(the same bytes as an uninterrupted run) and temporary files of the dead process,
and the cache holds only sealed, valid entries. A rerun then completes, leaves the
folder exactly as an uninterrupted run does and writes the same bits.

Kills per command: ``$ARCHES_FAULT_KILLS`` (default 2, which keeps the file near a
minute on two idle cores); ``ARCHES_FAULT_KILLS=20 pytest tests/test_robust_faults.py``
for a thorough run. The delays come from ``$ARCHES_FAULT_SEED`` (default 17).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from arches_render import atomic, cache
from helpers import REPO, variant
from robust_helpers import BASE_SCENE, cli, listing, write

KILLS = int(os.environ.get("ARCHES_FAULT_KILLS", "2"))
SEED = int(os.environ.get("ARCHES_FAULT_SEED", "17"))

ROCKS = """
[camera]
origin = [0.0, -9.0, 3.0]
target = [0.0, 0.0, 0.0]
[[lights]]
type = "constant"
[[rock_piles]]
support = { shape = "box", center = [0, 0, 0], size = [2, 2, 1] }
rock_size = 0.3
tiling = "periodic"
poisson_radius = 0.15
seed = 8
erosion = { steps = 3 }
"""

BLOCKS = """
[camera]
origin = [12.0, -6.0, 4.0]
target = [0.0, 0.0, 2.5]
[[lights]]
type = "constant"
[field]
root = "b"
[nodes.b]
type = "blocks"
host = { type = "box", center = [-3.0, 0.0, 2.5], size = [6.0, 8.0, 5.0] }
tile_size = 6.0
point_radius = 0.35
seed = 1
"""

LAYERS = """
[camera]
origin = [-10.0, -10.0, 6.0]
target = [4.0, 4.0, 1.0]
[[lights]]
type = "constant"
[field]
root = "land"
[nodes.land]
type = "layers"
source = "flat"
extent = [0.0, 0.0, 8.0, 8.0]
cell = 0.5
elevation = 1.0
z_range = [-1.0, 5.0]
dz = 0.01
column = [{ material = "sand", thickness = 0.2 }, { material = "bedrock" }]
[[nodes.land.operations]]
tool = "deposit"
center = [4.0, 4.0]
radius = 2.0
amount = 1.5
"""


def _inputs(tmp_path):
    """name -> argv(out_dir) of the six commands on tiny inputs."""
    scene = write(tmp_path / "in", BASE_SCENE.replace("resolution = [16, 12]", "resolution = [40, 30]"))
    y, x = np.mgrid[0:32, 0:32]
    np.save(tmp_path / "in" / "dem.npy", (8 * np.sin(x / 5.0) + 6 * np.cos(y / 7.0) + 0.5 * x).astype(np.float32))
    rocks, blocks, layers = (write(tmp_path / "in", t, f"{n}.toml") for n, t in
                             (("rocks", ROCKS), ("blocks", BLOCKS), ("layers", LAYERS)))
    return {
        "render": lambda out: ["render", scene, "-o", out / "still.exr", "--spp", "8", "-q"],
        "turntable": lambda out: ["turntable", scene, "-o", out / "frames", "--frames", "3",
                                  "--resolution", "16x12", "--spp", "2", "-q"],
        "amplify": lambda out: ["amplify", tmp_path / "in" / "dem.npy", "-o", out / "terrain.toml",
                                "--preset", "hoodoos", "-q"],
        "rocks": lambda out: ["rocks", rocks, "-o", out / "tiles.npz", "-q"],
        "blocks": lambda out: ["blocks", blocks, "-o", out / "tile.npz", "-q"],
        "layers": lambda out: ["layers", layers, "-o", out / "stacks.npz", "-q"],
    }


def _files(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


_TEMP = re.compile(r"^\..*\.tmp-(?P<host>[A-Za-z0-9_]+)-(?P<pid>[0-9]+)-")


def _check_after_kill(out: Path, ref: dict, dead: set, cache_dir: Path):
    """Only complete outputs and temporary files of killed processes; only valid cache entries.

    A run killed before it reached its first atomic write has not yet swept the
    temporaries of the run killed before it, so ``dead`` holds every killed pid;
    the final rerun must sweep them all (checked by the caller).
    """
    for rel, data in _files(out).items():
        name = Path(rel).name
        m = _TEMP.match(name) or next((_TEMP.match(part) for part in Path(rel).parts if _TEMP.match(part)), None)
        if m:
            assert int(m["pid"]) in dead, f"temporary file of a live or unknown process left: {rel}"
            continue
        assert rel in ref, f"unexpected output {rel}"
        assert data == ref[rel], f"partial or different output {rel}"
    if (out / "terrain.toml").exists():  # amplify publishes its data first, the scene last
        assert all((out / rel).is_file() for rel in ref), "a scene whose data is missing"
    for entry in cache_dir.rglob("*.npz"):
        if not entry.name.startswith("."):
            assert cache._unseal(entry)[1] is None, f"corrupt cache entry {entry}"


@pytest.mark.parametrize("command", ["render", "turntable", "amplify", "rocks", "blocks", "layers"])
def test_sigkill_at_random_moments_leaves_nothing_partial_and_a_rerun_gives_the_same_bits(
        tmp_path, capsys, monkeypatch, command):
    variant()
    from arches_render.generators.rocks import tile_cache
    from arches_render.render.jobs import clear_cache
    argv = _inputs(tmp_path)[command]
    rng = np.random.default_rng([SEED, sum(map(ord, command))])

    # The uninterrupted run (in this process: same code, same bits as a subprocess).
    monkeypatch.setenv("ARCHES_RENDER_CACHE", str(tmp_path / "cache_ref"))
    (tmp_path / "ref").mkdir()
    rc, err = cli(capsys, *argv(tmp_path / "ref"))
    assert rc == 0, err
    ref = _files(tmp_path / "ref")
    assert ref

    out, fault_cache = tmp_path / "out", tmp_path / "cache"
    out.mkdir()
    env = dict(os.environ, ARCHES_RENDER_CACHE=str(fault_cache), PYTHONUNBUFFERED="1")
    cmd = [sys.executable, "-m", "arches_render.cli", *map(str, argv(out))]
    window, killed, finished, dead = 10.0, 0, 0, set()
    for _ in range(3 * KILLS):
        if killed >= KILLS:
            break
        delay = float(rng.uniform(0.5, window))
        t0 = time.monotonic()
        p = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            _, err = p.communicate(timeout=delay)
            assert p.returncode == 0, err
            finished += 1
            window = max(1.0, 0.95 * (time.monotonic() - t0))  # later kills land inside a whole run
        except subprocess.TimeoutExpired:
            p.send_signal(signal.SIGKILL)
            p.communicate()
            killed += 1
            dead.add(p.pid)
        _check_after_kill(out, ref, dead, fault_cache)
    assert killed >= min(KILLS, 1), f"no kill landed before the command finished ({finished} finished)"

    # The rerun completes, sweeps what the kills left, and writes the same bits.
    monkeypatch.setenv("ARCHES_RENDER_CACHE", str(fault_cache))
    tile_cache.clear_memory()
    clear_cache()
    rc, err = cli(capsys, *argv(out))
    assert rc == 0, err
    assert listing(out) == listing(tmp_path / "ref")
    assert _files(out) == ref
    print(f"{command}: {killed} kills, {finished} runs finished before their kill")


def test_a_dask_worker_killed_during_a_turntable_has_its_frames_rerun(tmp_path):
    """SIGKILL one worker of a LocalCluster while it renders: the scheduler re-runs its frames on the
    restarted or surviving worker, and the frames equal a serial run bit for bit."""
    variant()
    from arches_render.render.distributed import dask_client
    from arches_render.render.turntable import plan_turntable, render_turntable
    from arches_render.scene import load_scene
    scene = write(tmp_path, BASE_SCENE)
    desc = load_scene(scene)
    serial = plan_turntable(desc, scene, tmp_path / "serial", 4, 2, 16, 12)
    (tmp_path / "serial").mkdir()
    render_turntable(serial)
    (tmp_path / "dask").mkdir()
    plan = plan_turntable(desc, scene, tmp_path / "dask", 4, 2, 16, 12)
    victims = []
    with dask_client(workers=2) as client:
        pids = client.run(os.getpid)

        def kill_a_busy_worker():
            deadline = time.monotonic() + 300
            while time.monotonic() < deadline and not victims:
                busy = [w for w, tasks in client.processing().items() if tasks]
                if busy:
                    victims.append((busy[0], len(client.processing()[busy[0]])))
                    os.kill(pids[busy[0]], signal.SIGKILL)
                    return
                time.sleep(0.05)
        killer = threading.Thread(target=kill_a_busy_worker, daemon=True)
        killer.start()
        written = render_turntable(plan, client=client)
        killer.join(timeout=5)
    assert victims and victims[0][1] >= 1, "no worker was killed while it held frames"
    assert sorted(written) == sorted(plan.paths)
    for a, b in zip(serial.paths, plan.paths):
        assert a.read_bytes() == b.read_bytes()


def test_kill_leftovers_are_only_hidden_temporaries_named_after_the_dead_process(tmp_path):
    """The temporary names the kill checks rely on: a writer killed mid-write leaves ``.NAME.tmp-HOST-PID-*``."""
    code = textwrap.dedent(f"""
        import os, time
        from arches_render.atomic import atomic_write
        with atomic_write({str(tmp_path / 'x.bin')!r}) as f:
            f.write(b"half")
            f.flush()
            print(os.getpid(), flush=True)
            time.sleep(600)
    """)
    p = subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE, text=True)
    pid = int(p.stdout.readline())
    p.kill()
    p.wait(timeout=60)
    (left,) = [q.name for q in tmp_path.iterdir()]
    m = _TEMP.match(left)
    assert m and int(m["pid"]) == pid and m["host"] == atomic._HOST and left.endswith(".bin")
    assert atomic.sweep_stale(tmp_path) == [left] and not list(tmp_path.iterdir())
