"""SIGKILL at the moments that matter, and a Dask worker lost mid-turntable (issues 17 and 23, "Faults").

For each of ``render``, ``turntable``, ``amplify``, ``rocks``, ``blocks`` and
``layers``: an uninterrupted run in this process records the kill points it passes
(:mod:`arches_render.faults`: every atomic publish, every cache build, every
turntable frame). A chain of subprocesses then dies by SIGKILL at those points
(:func:`_kill_plan`), each run starting from what the previous ones left: between two
turntable frames, holding a cache entry's build lock or with its first output cut to
half its bytes, with its last output complete but not renamed. After every kill the
output folder holds only complete outputs (the same bytes as the uninterrupted run)
and temporary files of the dead processes, the cache holds only sealed, valid
entries, and what earlier kills left finished is untouched. A rerun then completes,
uses sealed cache entries and finished frames as they are (not made again), leaves
the output folder and the cache exactly as an uninterrupted run does and writes the
same bits. The six chains run two at a time (their runs are mostly start-up, on one
core each).

Killing after random delays (the earlier form of this test) mostly landed in the
start-up of the subprocess and cost a whole run per kill that came too late.
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
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from arches_render import atomic, cache
from helpers import REPO, variant
from robust_helpers import BASE_SCENE, cli, listing, write

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


_TEMP = re.compile(r"(?:^|/)\.[^/]*\.tmp-(?P<host>[A-Za-z0-9_]+)-(?P<pid>[0-9]+)-")


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


def _trace(monkeypatch) -> list:
    """Record the kill points this process passes: ``(point, bytes of the temporary file or None)``."""
    from arches_render import faults
    trace = []
    monkeypatch.setattr(faults, "point", lambda name, path=None: trace.append(
        (name, os.path.getsize(path) if path is not None else None)))
    return trace


def _kill_plan(trace: list) -> list:
    """The chain of kill points (``$ARCHES_TEST_KILL_AT`` values) for a command that passed ``trace``.

    Each run of the chain starts from what the runs before it left: a frame finished
    before the kill (nothing rendered twice after it), then a build lock held (nothing
    published) or else the first publish cut to half its bytes (nothing published),
    then the last publish complete but not renamed, counted from where the chain
    stands. A command that builds a cache entry publishes that entry first, inside the
    build lock: the lock kill stands for the cut there (the cut itself is the atomic
    writer's, which the other commands' first publishes exercise).
    """
    names = [name for name, _ in trace]
    sizes = [size for name, size in trace if name == "atomic.written"]
    plan, done = [], 0
    if "turntable.after_frame" in names:
        plan.append("turntable.after_frame:1")
        done = names[:names.index("turntable.after_frame")].count("atomic.before_replace")
    plan.append("cache.locked:1" if "cache.locked" in names else f"atomic.written:{sizes[done] // 2}")
    plan.append(f"atomic.before_replace:{len(sizes) - done}")
    return plan


def _temporaries(folder: Path, pid: int) -> list:
    """Sizes of the temporary files (also inside temporary folders) of process ``pid`` below ``folder``."""
    return [p.stat().st_size for p in folder.rglob("*") if p.is_file()
            and any((m := _TEMP.match(part)) and int(m["pid"]) == pid for part in p.relative_to(folder).parts)]


def _killed_at(spec: str, cmd: list, env=None) -> int:
    """Run ``cmd`` with the kill point ``spec``; assert that it died there; return its pid."""
    from arches_render import faults
    p = subprocess.Popen(cmd, cwd=REPO, env=dict(env or os.environ, **{faults.ENV: spec}),
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _, err = p.communicate(timeout=300)
    assert p.returncode == -signal.SIGKILL, f"{spec}: not killed there (exit {p.returncode}): {err}"
    return p.pid


def _stamps(paths) -> dict:
    return {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in paths}


COMMANDS = ("render", "turntable", "amplify", "rocks", "blocks", "layers")


def _finished(command: str, folder: Path) -> dict:
    """Stamps (:func:`_stamps`) of what a rerun must use as it is: sealed cache entries, finished frames."""
    entries = [e for e in (folder / "cache").rglob("*.npz") if not e.name.startswith(".")]
    frames = [f for f in (folder / "out").rglob("*.exr") if not _TEMP.search(str(f))] if command == "turntable" else []
    return _stamps(entries + frames)


def _kill_chain(command: str, argv, folder: Path, ref: dict, trace: list) -> dict:
    """Kill ``command`` at every point of its :func:`_kill_plan`, one subprocess after the other, writing
    into ``folder/out`` with the cache ``folder/cache``; check what each kill left. Returns
    :func:`_finished` after the last kill."""
    out, fault_cache = folder / "out", folder / "cache"
    env = dict(os.environ, **{cache.ENV: str(fault_cache)}, PYTHONUNBUFFERED="1")
    cmd = [sys.executable, "-m", "arches_render.cli", *map(str, argv(out))]
    sizes = [size for name, size in trace if name == "atomic.written"]
    dead, kept = set(), {}
    for spec in _kill_plan(trace):
        pid = _killed_at(spec, cmd, env)
        dead.add(pid)
        _check_after_kill(out, ref, dead, fault_cache)
        assert _stamps(kept) == kept, f"{command} {spec}: a finished frame or a sealed cache entry was made again"
        kept = _finished(command, folder)
        point, _, n = spec.partition(":")
        left = _temporaries(out, pid) + _temporaries(fault_cache, pid)
        if point == "atomic.written":  # the cut-short file is there, and hidden
            assert int(n) in left, (command, spec, left)
        elif point == "atomic.before_replace":  # so is the last output, complete, not renamed
            assert sizes[-1] in left, (command, spec, left)
        elif point == "turntable.after_frame":  # one finished frame, published
            assert len([f for f in _files(out) if f.endswith(".exr") and not _TEMP.search(f)]) == 1, command
    return kept


def test_sigkill_at_every_kind_of_kill_point_leaves_nothing_partial_and_a_rerun_gives_the_same_bits(
        tmp_path, capsys, monkeypatch):
    variant()
    from arches_render import faults
    from arches_render.generators.rocks import tile_cache
    from arches_render.render.jobs import clear_cache
    inputs = _inputs(tmp_path)

    # The uninterrupted runs (in this process: same code, same bits as a subprocess), tracing the kill points.
    refs = {}
    for command in COMMANDS:
        folder = tmp_path / command
        (folder / "ref").mkdir(parents=True)
        (folder / "out").mkdir()
        monkeypatch.setenv(cache.ENV, str(folder / "cache_ref"))
        with monkeypatch.context() as m:
            trace = _trace(m)
            rc, err = cli(capsys, *inputs[command](folder / "ref"))
        assert rc == 0, (command, err)
        assert {name for name, _ in trace} <= set(faults.POINTS), trace
        refs[command] = (_files(folder / "ref"), trace)
        assert refs[command][0], command

    # The kill chains, two at a time: a chain's runs follow one another, most of each is a start-up
    # (imports) on one core.
    with ThreadPoolExecutor(2) as pool:
        kept = dict(zip(COMMANDS, pool.map(lambda c: _kill_chain(c, inputs[c], tmp_path / c, *refs[c]), COMMANDS)))

    # The reruns complete, sweep what the kills left, keep what the killed runs finished, and write
    # the same bits.
    for command in COMMANDS:
        folder = tmp_path / command
        monkeypatch.setenv(cache.ENV, str(folder / "cache"))
        tile_cache.clear_memory()
        clear_cache()
        rc, err = cli(capsys, *inputs[command](folder / "out"))
        assert rc == 0, (command, err)
        assert listing(folder / "out") == listing(folder / "ref"), command
        assert _files(folder / "out") == refs[command][0], command
        assert listing(folder / "cache") == listing(folder / "cache_ref"), command
        assert _files(folder / "cache") == _files(folder / "cache_ref"), command
        assert _stamps(kept[command]) == kept[command], f"{command} rerun: a finished frame or a sealed cache entry was made again"


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
    """The temporary names the kill checks rely on: a writer killed mid-write leaves ``.NAME.tmp-HOST-PID-*``
    holding what it had written."""
    code = textwrap.dedent(f"""
        from arches_render.atomic import atomic_write
        with atomic_write({str(tmp_path / 'x.bin')!r}) as f:
            f.write(b"half and the rest")
    """)
    pid = _killed_at("atomic.written:4", [sys.executable, "-c", code])
    (left,) = [q.name for q in tmp_path.iterdir()]
    m = _TEMP.match(left)
    assert m and int(m["pid"]) == pid and m["host"] == atomic._HOST and left.endswith(".bin")
    assert (tmp_path / left).read_bytes() == b"half"
    assert atomic.sweep_stale(tmp_path) == [left] and not list(tmp_path.iterdir())
