"""Production benchmarks: turntable frames, serially and on Dask.

``turntable_frame_s``       seconds per frame of a turntable of ``scenes/default.toml``
                            at 320x180, 16 spp, with the AOV layers, written as EXR
                            (warm kernels: a first frame compiles and is not timed);
                            median of the per-frame times of an 8-frame orbit.
                            Baseline: the same 7 views rendered as plain stills (no
                            AOVs, no files): the per-frame overhead of AOVs, camera
                            edit and EXR writing.
``dask_speedup_2workers``   frames per second of an 8-frame turntable (default scene,
                            160x90, 8 spp) on a Dask LocalCluster of 2 worker
                            processes (1 Dr.Jit thread each) over that of 1 worker
                            (2 Dr.Jit threads), cluster start-up excluded, warm
                            workers (the same turntable rendered once first).
                            Baseline: 2, ideal scaling on the 2 cores.
``mesh_uv_bake_s``          seconds of ``arches-render mesh scenes/default.toml -o d.glb
                            --voxel 2 --uv --bake`` in a fresh process (the command a
                            layout artist runs: polygonization in atlas pieces, xatlas,
                            the bake, the GLB and its normal map written), median of the
                            runs. Baseline: the goal, 30 s (it took over 5 minutes on one
                            core in one piece). Extra fields: triangles, atlas size, load.

The figures are noisy when other processes share the machine.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

from arches_render.render.distributed import dask_client
from arches_render.render.jobs import set_camera
from arches_render.render.renderer import build_scene, render_image
from arches_render.render.turntable import plan_turntable, render_turntable
from arches_render.scene import load_scene
from arches_render.timing import REPO

SCENE = REPO / "scenes" / "default.toml"


def bench_turntable_frame_s(repeat):
    desc = load_scene(SCENE)
    w, h, spp, frames = 320, 180, 16, 8
    per_frame = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(max(1, repeat)):
            plan = plan_turntable(desc, SCENE, tmp, frames, spp, w, h, seed=r)
            render_turntable(plan.__class__(plan.jobs[:1], plan.paths[:1], plan.headers[:1], [0], plan.layers))
            plan.todo = plan.todo[1:]
            stamps = [time.perf_counter()]
            render_turntable(plan, progress=lambda done, total: stamps.append(time.perf_counter()))
            per_frame += [b - a for a, b in zip(stamps[1:], stamps[2:])]
    # Baseline: the same views as plain stills (no AOVs, no files).
    scene = build_scene(desc, "field", w, h)
    render_image(scene, 4, seed=99)
    still = []
    for job in plan.jobs[1:]:
        set_camera(scene, *job.camera)
        t = time.perf_counter()
        render_image(scene, spp, seed=0)
        still.append(time.perf_counter() - t)
    return dict(value=statistics.median(per_frame), unit="s/frame", baseline=statistics.median(still),
                baseline_is="same views as stills without AOVs", resolution=f"{w}x{h}", spp=spp,
                frames=len(per_frame))


def _fps(workers, plan_fn):
    with dask_client(workers=workers) as client, tempfile.TemporaryDirectory() as tmp:
        render_turntable(plan_fn(Path(tmp) / "warm"), client=client)  # start, build, compile
        plan = plan_fn(Path(tmp) / "timed")
        t = time.perf_counter()
        render_turntable(plan, client=client)
        return len(plan.todo) / (time.perf_counter() - t)


def bench_dask_speedup_2workers(repeat):
    desc = load_scene(SCENE)

    def plan_fn(folder):
        folder.mkdir(parents=True, exist_ok=True)
        return plan_turntable(desc, SCENE, folder, 8, 8, 160, 90)

    one, two = [], []
    for _ in range(max(1, repeat)):
        one.append(_fps(1, plan_fn))
        two.append(_fps(2, plan_fn))
    f1, f2 = statistics.median(one), statistics.median(two)
    return dict(value=f2 / f1, unit="x", baseline=2.0, baseline_is="ideal (2 cores)", fps_1worker=f1,
                fps_2workers=f2, resolution="160x90", spp=8, frames=8)


def bench_mesh_uv_bake_s(repeat):
    import os
    import re
    import subprocess
    import sys
    load0 = os.getloadavg()[0]
    times, line = [], ""
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(max(1, repeat)):
            t = time.perf_counter()
            out = subprocess.run([sys.executable, "-m", "arches_render.cli", "mesh", str(SCENE), "-o",
                                  str(Path(tmp) / "d.glb"), "--voxel", "2", "--uv", "--bake", "-q"],
                                 capture_output=True, text=True, check=True)
            times.append(time.perf_counter() - t)
            line = out.stdout.strip()
    found = re.search(r"(\d+) triangles, (\d+x\d+) atlas", line)
    return dict(value=statistics.median(times), unit="s", baseline=30.0, baseline_is="goal",
                runs_s=[round(x, 2) for x in times], triangles=int(found.group(1)) if found else None,
                atlas=found.group(2) if found else None, load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


BENCHMARKS = {
    "mesh_uv_bake_s": (bench_mesh_uv_bake_s, 3),
    "turntable_frame_s": (bench_turntable_frame_s, 1),
    "dask_speedup_2workers": (bench_dask_speedup_2workers, 1),
}
