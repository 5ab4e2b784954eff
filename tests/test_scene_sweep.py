"""Issue 38: no native crash goes unseen. Every shipped and gallery scene renders in every mode.

``every_generator`` died by SIGSEGV in mesh mode with AOVs, one mode of one scene
that no test rendered. This sweep renders every scene of ``scenes/`` and
``scenes/gallery/`` in the four modes {field, mesh} x {AOVs, no AOVs}, tiny (32x18,
1 spp), in render processes (:class:`~arches_render.render.isolated.RenderProcess`)
apart from pytest's: a scene's four modes one after the other in one process, so
that its description and mesh are built once. Each of the two processes renders
scene after scene and drops a scene's builds before the next
(:meth:`~arches_render.render.isolated.RenderProcess.forget`; kept alive, they slow
every later render several times over). A child's start-up with the ``Debug`` flag
costs ~2 s of one core (Dr.Jit rewrites every ``dr.syntax`` function on import),
and a scene's first render in a fresh child traces and loads its kernels from
scratch: a child per scene made the sweep ~2.5 times as long. A crash fails the job
in flight, which names scene and mode, and the next job gets a fresh process: every
mode is tried whatever dies before it. Each render must come back with a finite
beauty and finite AOV layers.

The children run with Dr.Jit's ``Debug`` flag, which checks the index of every
gather and scatter: a read outside an array does not always crash (the every_generator
read was 4 GB out; the same bug read 5 kB before an array, silently, in a smaller
scene), so an ``out-of-bounds`` report fails the mode too. Dr.Jit 1.5 reports its own
expanded scatter-reductions (the film's accumulation, per thread) as out of bounds
when a process runs several threads (``docs/upstream/drjit_debug_expanded_scatter``):
the children run one Dr.Jit thread each, two at a time.
"""

from __future__ import annotations

import os
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO

SCENES = sorted((REPO / "scenes").glob("*.toml")) + sorted((REPO / "scenes" / "gallery").glob("*.toml"))
MODES = (("field", True), ("field", False), ("mesh", True), ("mesh", False))
WIDTH, HEIGHT = 32, 18
PROCESSES = 2
JOB_TIMEOUT_S = 600

pytestmark = pytest.mark.slow


def _mode(geometry, aovs) -> str:
    return f"{geometry}{'+aovs' if aovs else ''}"


def _problems(rgb, layers) -> list:
    out = []
    if not np.isfinite(rgb).all():
        out.append(f"beauty: {int((~np.isfinite(rgb)).any(axis=-1).sum())} non-finite pixels")
    for name, (arr, _) in sorted(layers.items()):
        if not np.isfinite(arr).all():
            out.append(f"{name}: {int((~np.isfinite(arr)).any(axis=-1).sum())} non-finite pixels")
    return out


class _Renderer(threading.local):
    """A pool thread's render process and the file its standard error goes to, kept from
    scene to scene (``RenderProcess`` starts a fresh child after a crash)."""

    def __init__(self):
        from arches_render.render.isolated import RenderProcess
        self.err = tempfile.TemporaryFile("w+")
        self.proc = RenderProcess(stderr=self.err, jit_debug=True)
        with _OPENED_LOCK:
            _OPENED.append(self)

    def close(self):
        try:
            self.proc.close()
        finally:
            self.err.close()


_OPENED: list = []
_OPENED_LOCK = threading.Lock()


def _sweep_scene(path: Path, renderer: _Renderer) -> dict:
    """``{mode: [problems]}`` of one scene, rendered by this thread's process, plus ``"seconds"``."""
    from arches_render.render.isolated import RenderCrash
    from arches_render.render.jobs import RenderJob
    result, t0, err, proc = {}, time.perf_counter(), renderer.err, renderer.proc
    for geometry, aovs in MODES:
        job = RenderJob(scene=str(path), width=WIDTH, height=HEIGHT, spp=1, geometry=geometry, aovs=aovs,
                        threads=1, label="sweep")
        err.seek(0, os.SEEK_END)
        start = err.tell()
        try:
            problems = _problems(*proc.run(job, timeout=JOB_TIMEOUT_S))
        except RenderCrash as exc:
            problems = [str(exc)]
        except Exception as exc:  # the scene or mode does not render: as bad
            problems = [f"{type(exc).__name__}: {exc}"]
        # What the child wrote during this job only: the out-of-bounds reports of this mode.
        err.flush()
        err.seek(start)
        problems += sorted({line.strip() for line in err.read().splitlines() if "out-of-bounds" in line})
        result[_mode(geometry, aovs)] = problems
    # The next scene starts from no kept builds, as in a fresh process. Dropping them is
    # native code too: should the child die here, that fails this scene.
    try:
        proc.forget()
        result["forget"] = []
    except Exception as exc:
        result["forget"] = [f"{type(exc).__name__}: {exc}"]
    result["seconds"] = time.perf_counter() - t0
    return result


@pytest.fixture(scope="module")
def sweep():
    """``{scene stem (gallery/ prefixed): result of _sweep_scene}`` for every scene."""
    t0 = time.perf_counter()
    renderer = _Renderer()  # one per pool thread (threading.local): __init__ runs in each
    try:
        with ThreadPoolExecutor(PROCESSES) as pool:
            results = dict(zip(SCENES, pool.map(lambda p: _sweep_scene(p, renderer), SCENES)))
    finally:
        for r in _OPENED:
            r.close()
        _OPENED.clear()
    total = time.perf_counter() - t0
    slowest = sorted(results.items(), key=lambda kv: -kv[1]["seconds"])[:5]
    print(f"\nsweep: {len(SCENES)} scenes x {len(MODES)} modes in {total:.0f} s; slowest: "
          + ", ".join(f"{p.stem} {r['seconds']:.0f} s" for p, r in slowest))
    return results


def test_the_sweep_covers_every_scene():
    names = {p.relative_to(REPO / "scenes").as_posix() for p in SCENES}
    assert "gallery/every_generator.toml" in names and "default.toml" in names
    assert len([n for n in names if n.startswith("gallery/")]) >= 5 and len(names) >= 25, names


@pytest.mark.parametrize("path", SCENES, ids=[p.relative_to(REPO / "scenes").as_posix() for p in SCENES])
def test_scene_renders_in_every_mode_without_a_crash(sweep, path):
    result = sweep[path]
    bad = {mode: problems for mode, problems in result.items() if mode != "seconds" and problems}
    assert not bad, f"{path.relative_to(REPO)}: " + "; ".join(f"{m}: {', '.join(p)}" for m, p in bad.items())
