"""arches-render benchmarks: one figure a line, each beside a baseline from the same run.

    python benchmarks/run.py [--json] [--repeat N] [NAME ...]

This file holds the foundation's benchmarks, ``bench_production.py`` the
production ones (turntables, Dask), ``bench_dask_scale.py`` Dask at scale
(a tiled 1280x720 still, a 24-frame turntable), ``bench_heightfield.py`` the heightfield cast,
``bench_lookdev.py`` the gallery's cost and the look's (on the field and on the default scene's mesh),
``bench_tracing.py`` the direct tracer's (level of detail, pruning). Each generator keeps its own in its package
(``generators/NAME/benchmarks.py``), declared as ``BENCHMARKS = {name: (fn, repeat)}``
with ``fn(repeat) -> dict(value, unit, baseline, baseline_is, ...)`` in the
registry (:mod:`arches_render.extensions`) and documented in its docstring; they
are listed here in registry order. Names are stable: scripts and notes refer to them.

Figures (medians over ``--repeat`` runs, warm kernels unless stated):

``field_evals_tree20``   M evals/s of a ~20-node tree (heightfield, blends, capsules,
                         displacement, transforms); baseline: the issue's goal, 80.
``field_evals_set10k``   M evals/s of a 10,000-capsule ``capsule_set`` through its
                         grid; baseline: the same capsules as a brute-force loop.
``field_evals_scaling``  M evals/s of capsule sets of 10^4, 10^5 and 10^6 primitives at
                         constant density (the set10k capsules over 200 x 200 m, the
                         area growing with the count); value: the 10^6 rate over the
                         10^4 rate, points in random order (every evaluation a cache
                         miss); baseline: the goal, 0.5. Extra fields per size: rate,
                         rate for the same points in cell order (as a tracer's coherent
                         packets), build seconds (numba kernels warm), MB of the arrays.
``render_field_vs_mesh`` sphere-traced time / marching-cubes mesh time (stock
                         ``path``), default scene, same camera, spp and resolution;
                         baseline: the goal, 2. Extra fields: the field at full
                         detail (level of detail off) in the same run, the load.
``render_default_s``     ``arches-render render scenes/default.toml`` (the README's first
                         image: the scene's own 640x360, 16 spp, denoised) in a fresh
                         process with an empty kernel cache, JIT included; baseline: the
                         goal, 30 s.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# arches_render first: importing it chooses the libLLVM that Dr.Jit loads on import.
from arches_render import backend, extensions, field as F  # isort: skip
import drjit as dr
import mitsuba as mi
import numpy as np

import bench_dask_scale
import bench_heightfield  # benchmarks/ is on sys.path as the script's folder
import bench_lookdev
import bench_production
import bench_tracing
from arches_render.render.renderer import build_scene
from arches_render.scene import load_scene
from arches_render.timing import REPO, median_renders, random_points, timed_eval


def tree20():
    """A ~20-node tree typical of a hand-written scene."""
    x = np.linspace(0, 1, 129)
    X, Y = np.meshgrid(x, x)
    ground = F.Heightfield(8 * np.sin(5 * X) * np.cos(3 * Y) + 4 * X, (-50, -50, 50, 50))
    arch = F.Blend(*[F.Capsule([20 * np.cos(a), 0, 20 * np.sin(a)], [20 * np.cos(a + 0.4), 0, 20 * np.sin(a + 0.4)], 4)
                     for a in np.linspace(0, np.pi - 0.4, 6)], radius=2.0)
    rocks = F.Union(F.Sphere([10, 10, 3], 4), F.Box([-15, 5, 2], [3, 4, 5], rounding=0.5),
                    F.Transform.rotate(F.Capsule([0, 0, 0], [5, 0, 0], 1.5), [0, 0, 1], 30, [0, 0, 0]))
    cave = F.Transform.translate(F.Sphere([0, 0, 0], 5), [-20, -20, 2])
    return F.Difference(F.Blend(ground, F.Displace(arch, 0.5, 5.0, 2, seed=3), rocks, radius=3.0), cave)


def bench_field_evals_tree20(repeat):
    node = tree20()
    n = 1 << 21
    t = timed_eval(node.eval, random_points(n, [-50, -50, -5], [50, 50, 30]), repeat)
    return dict(value=n / t / 1e6, unit="M evals/s", baseline=80.0, baseline_is="goal",
                nodes=node.count())


def bench_field_evals_set10k(repeat):
    rng = np.random.default_rng(1)
    a = rng.uniform(-100, 100, (10_000, 3)) * [1, 1, 0.1]
    b = a + rng.normal(0, 1.0, a.shape)
    r = rng.uniform(0.3, 1.2, 10_000)
    node = F.CapsuleSet(a, b, r)
    n = 1 << 21
    t = timed_eval(node.eval, random_points(n, [-100, -100, -10], [100, 100, 10]), repeat)
    # Baseline: the same capsules looped over without the grid (fewer points).
    A = [mi.Float(a[:, i].astype(np.float32)) for i in range(3)]
    B = [mi.Float(b[:, i].astype(np.float32)) for i in range(3)]
    R = mi.Float(r.astype(np.float32))

    def brute(p):
        def body(i, f):
            pa = p - mi.Point3f(*(dr.gather(mi.Float, c, i) for c in A))
            ba = mi.Vector3f(*(dr.gather(mi.Float, c, i) for c in B)) - mi.Vector3f(
                *(dr.gather(mi.Float, c, i) for c in A))
            t_ = dr.clip(dr.dot(pa, ba) / dr.maximum(dr.squared_norm(ba), 1e-20), 0.0, 1.0)
            return i + 1, dr.maximum(f, dr.gather(mi.Float, R, i) - dr.norm(pa - ba * t_))
        return dr.while_loop((mi.UInt32(0), mi.Float(-1e30) + 0 * p.x), lambda i, f: i < len(r), body)[1]

    m = 1 << 13
    tb = timed_eval(brute, random_points(m, [-100, -100, -10], [100, 100, 10]), max(1, repeat // 2))
    return dict(value=n / t / 1e6, unit="M evals/s", baseline=m / tb / 1e6, baseline_is="brute-force loop",
                goal=20.0, cells=int(np.prod(node.res)), max_per_cell=node.max_per_cell)


def capsules_at_constant_density(n, seed=1):
    """``n`` capsules at the density of ``field_evals_set10k`` (10^4 over 200 x 200 x 20 m)."""
    s = np.sqrt(n / 10_000)
    rng = np.random.default_rng(seed)
    a = rng.uniform(-100, 100, (n, 3)) * [s, s, 0.1]
    return a, a + rng.normal(0, 1.0, a.shape), rng.uniform(0.3, 1.2, n), s


def bench_field_evals_scaling(repeat):
    from arches_render.field.brick_grid import BrickGrid
    F.CapsuleSet(*capsules_at_constant_density(100)[:3])  # loads the compiled grid kernels
    out, m = {}, 1 << 21
    for n, label in ((10_000, "10k"), (100_000, "100k"), (1_000_000, "1M")):
        a, b, r, s = capsules_at_constant_density(n)
        t = time.perf_counter()
        node = F.CapsuleSet(a, b, r)
        out[f"build_s_{label}"] = time.perf_counter() - t
        out[f"MB_{label}"] = node.nbytes() / 1e6
        pts = np.random.default_rng(0).uniform([-100 * s, -100 * s, -10], [100 * s, 100 * s, 10], (m, 3))
        pts = pts.astype(np.float32)
        coherent = pts[np.argsort(BrickGrid.cell_order(pts, node.grid_lo, node.cell, node.res), kind="stable")]
        for order, p in (("", pts), ("coherent_", coherent)):
            t = timed_eval(node.eval, mi.Point3f(*(mi.Float(p[:, i]) for i in range(3))), repeat)
            out[f"{order}Mevals_{label}"] = m / t / 1e6
        del node
    return dict(value=out["Mevals_1M"] / out["Mevals_10k"], unit="x", baseline=0.5, baseline_is="goal",
                coherent_ratio=out["coherent_Mevals_1M"] / out["coherent_Mevals_10k"], **out,
                load=os.getloadavg()[0])


def bench_render_field_vs_mesh(repeat):
    desc = load_scene(REPO / "scenes" / "default.toml")
    w, h, spp = 320, 180, 16
    out, scenes = {}, []
    load0 = os.getloadavg()[0]
    for geometry in ("field", "mesh"):
        t0 = time.perf_counter()
        scenes.append(build_scene(desc, geometry, w, h))
        out[geometry + "_setup"] = time.perf_counter() - t0
    # The same field at full detail (footprint level of detail off), in the same run.
    scenes.append(build_scene(desc, "field", w, h))
    scenes[-1].integrator().lod = False
    out["field"], out["mesh"], out["full"] = median_renders(scenes, spp, repeat)
    return dict(value=out["field"] / out["mesh"], unit="x", baseline=2.0, baseline_is="goal",
                field_s=out["field"], mesh_s=out["mesh"], mesh_setup_s=out["mesh_setup"],
                field_full_detail_s=out["full"], ratio_full_detail=out["full"] / out["mesh"],
                resolution=f"{w}x{h}", spp=spp, load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


def bench_render_default_s(repeat):
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeat):
            home = Path(tmp) / f"home{i}"  # Dr.Jit caches kernels under $HOME/.drjit
            home.mkdir()
            env = dict(os.environ, HOME=str(home))
            t = time.perf_counter()
            subprocess.run([sys.executable, "-m", "arches_render.cli", "render", "scenes/default.toml",
                            "-o", str(Path(tmp) / "default.exr"), "-q"], cwd=REPO, env=env, check=True,
                           stdout=subprocess.DEVNULL)
            times.append(time.perf_counter() - t)
    desc = load_scene(REPO / "scenes" / "default.toml")
    return dict(value=statistics.median(times), unit="s", baseline=30.0, baseline_is="goal",
                resolution=f"{desc.render.width}x{desc.render.height}", spp=desc.render.spp,
                denoised=desc.render.denoise, cold_kernel_cache=True, load=round(os.getloadavg()[0], 2))


BENCHMARKS = {
    "field_evals_tree20": (bench_field_evals_tree20, 5),
    "field_evals_set10k": (bench_field_evals_set10k, 5),
    "field_evals_scaling": (bench_field_evals_scaling, 3),
    "render_field_vs_mesh": (bench_render_field_vs_mesh, 3),
    "render_default_s": (bench_render_default_s, 1),
}


def all_benchmarks() -> dict:
    """The benchmarks above, the production ones and every generator's (the registry)."""
    core = {**BENCHMARKS, **bench_production.BENCHMARKS, **bench_dask_scale.BENCHMARKS, **bench_heightfield.BENCHMARKS,
            **bench_tracing.BENCHMARKS, **bench_lookdev.BENCHMARKS}
    return {**core, **extensions.benchmarks(core=core)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("names", nargs="*", metavar="NAME", help="benchmarks to run (default: all)")
    p.add_argument("--json", action="store_true", help="one JSON object a line")
    p.add_argument("--repeat", type=int, default=0, help="repetitions (default: per benchmark)")
    args = p.parse_args(argv)
    benchmarks = all_benchmarks()
    unknown = [n for n in args.names if n not in benchmarks]
    if unknown:
        p.error(f"unknown benchmark {unknown[0]!r} (choose from {', '.join(benchmarks)})")
    backend.set_variant()
    for name in args.names or benchmarks:
        fn, default_repeat = benchmarks[name]
        res = fn(args.repeat or default_repeat)
        res["ratio"] = res["value"] / res["baseline"]
        if args.json:
            print(json.dumps({"name": name, **{k: (round(v, 4) if isinstance(v, float) else v)
                                                for k, v in res.items()}}), flush=True)
        else:
            extra = ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                              for k, v in res.items() if k not in ("value", "unit", "baseline", "ratio"))
            print(f"{name}: {res['value']:.3g} {res['unit']} (baseline {res['baseline']:.3g}, "
                  f"ratio {res['ratio']:.3g}; {extra})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
