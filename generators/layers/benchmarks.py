"""Layered terrain benchmarks (arches-layered-terrain-2009, section 3 and table 1).

``layers_memory_bytes``  bytes of the material stacks of a cave terrain at the effective
                         resolution of the paper's cave scene, 1000 x 750 x 8000 voxels
                         (6 billion); the canyon (1000 x 500 x 5000) and cliff (2000 x 500 x
                         4000) sizes of table 1 are reported beside it. The terrains are
                         synthetic (fBm ground, a sandstone band and sand cover, one cave
                         level under about 40 % of the columns and a second under about
                         10 %): the paper's scenes are not available. Baseline: the goal,
                         21 MB (paper: "less than 21 megabytes").
``layers_field_evals``   M evals/s of the convolution surface (Dr.Jit, warm kernels) of a
                         512 x 512 stack grid with caves, at uniform random points of its
                         box; the rate at points within two kernel sizes of the surface
                         (no fast path) is reported too. Baseline: the goal, 20.
``layers_stabilize_s``   seconds to stabilize a 1024 x 1024 grid of bedrock with 10 %
                         of its stacks carrying unstable sand or rock columns (warm numba
                         kernels); baseline: 1 s (a target; the paper gives no figure).
"""

from __future__ import annotations

import statistics
import time

import drjit as dr
import mitsuba as mi
import numpy as np
from scipy.ndimage import gaussian_filter

from arches_render.timing import random_points, timed_eval

from .convolution_surface import ConvolutionSurface
from .material_stacks import AIR, BEDROCK, ROCK, SAND, SANDSTONE, MaterialStacks
from .stabilization import slope_excess, stabilize


def _smooth_noise(shape, scale, seed):
    rng = np.random.default_rng(seed)
    f = gaussian_filter(rng.normal(size=shape), scale, mode="wrap")
    return f / f.std()


def cave_terrain(nx, ny, nz, seed=0, relief=None):
    """Synthetic stacks: fBm ground, up to two cave levels, sandstone and sand bands.

    Columns bottom-up: bedrock, [air, bedrock], [air, bedrock], sandstone, sand; built as
    a count matrix and folded where a cave is absent (vectorized, no Python per column).
    """
    H = (0.55 + 0.2 * _smooth_noise((ny, nx), max(nx, ny) / 16, seed)
         + 0.05 * _smooth_noise((ny, nx), max(nx, ny) / 64, seed + 1))
    H = np.clip(H, 0.1, 0.95)
    top = (H * nz).astype(np.int64).ravel()
    cave1 = _smooth_noise((ny, nx), max(nx, ny) / 40, seed + 2).ravel() > 0.25     # ~40 %
    cave2 = _smooth_noise((ny, nx), max(nx, ny) / 40, seed + 3).ravel() > 1.28     # ~10 %
    sand = np.where(_smooth_noise((ny, nx), 8, seed + 4).ravel() > 0, nz // 400, 0)
    stone = np.full_like(top, nz // 40)
    c1_lo, c1_h = (0.25 * top).astype(np.int64), np.where(cave1, nz // 100, 0)
    c2_lo, c2_h = (0.45 * top).astype(np.int64), np.where(cave2, nz // 150, 0)
    K = 7
    counts = np.zeros((len(top), K), dtype=np.int64)
    counts[:, 0] = c1_lo                                     # bedrock
    counts[:, 1] = c1_h                                      # air (cave 1)
    counts[:, 2] = c2_lo - c1_lo - c1_h                      # bedrock
    counts[:, 3] = c2_h                                      # air (cave 2)
    counts[:, 5] = stone                                     # sandstone
    counts[:, 6] = sand                                      # sand
    counts[:, 4] = top - counts[:, [0, 1, 2, 3, 5, 6]].sum(axis=1)   # bedrock
    # Fold bedrock bands that touch where a cave is absent.
    no1 = counts[:, 1] == 0
    counts[no1, 2] += counts[no1, 0]
    counts[no1, 0] = 0
    no2 = counts[:, 3] == 0
    counts[no2, 4] += counts[no2, 2]
    counts[no2, 2] = 0
    assert np.all(counts >= 0)
    mats = np.array([BEDROCK, AIR, BEDROCK, AIR, BEDROCK, SANDSTONE, SAND], dtype=np.uint8)
    keep = counts > 0
    off = np.concatenate([[0], np.cumsum(keep.sum(axis=1))]).astype(np.uint32)
    return MaterialStacks((ny, nx), 1.0, (0.0, 0.0, 0.0), 1.0, nz, off,
                          np.broadcast_to(mats, counts.shape)[keep], counts[keep])


TABLE1 = {"cave": (1000, 750, 8000, 21e6), "canyon": (1000, 500, 5000, 14e6), "cliff": (2000, 500, 4000, 26e6)}


def bench_layers_memory_bytes(repeat):
    out = {}
    for name, (nx, ny, nz, paper) in TABLE1.items():
        S = cave_terrain(nx, ny, nz, seed=1)
        out[name] = S
    cave = out["cave"]
    extra = {}
    for name, S in out.items():
        extra[f"{name}_bytes"] = S.nbytes()
        extra[f"{name}_effective_voxels"] = S.effective_voxels()
        extra[f"{name}_layers_per_stack"] = round(len(S.material) / S.ncol, 3)
        extra[f"{name}_paper_bytes"] = TABLE1[name][3]
    return dict(value=float(cave.nbytes()), unit="bytes", baseline=21e6, baseline_is="goal", **extra)


def bench_layers_field_evals(repeat):

    S = cave_terrain(512, 512, 4000, seed=2)
    S = type(S)((S.ny, S.nx), 0.5, (0.0, 0.0, 0.0), 0.05, S.n_levels, S.offsets, S.material, S.count)
    node = ConvolutionSurface(S)
    lo, hi = node.bounds()
    n = 1 << 21
    t = timed_eval(node.eval, random_points(n, lo, hi), repeat)
    # Near the surface: within two kernel sizes of the stacks' tops.
    rng = np.random.default_rng(3)
    xy = rng.uniform(lo[:2], hi[:2], (n, 2))
    H = S.heights()
    i = np.clip((xy[:, 0] / S.cell).astype(int), 0, S.nx - 1)
    j = np.clip((xy[:, 1] / S.cell).astype(int), 0, S.ny - 1)
    z = H[j, i] + rng.uniform(-2 * node.sigma, 2 * node.sigma, n)
    pts = np.stack([xy[:, 0], xy[:, 1], z], axis=1).astype(np.float32)
    p = mi.Point3f(*(mi.Float(pts[:, k]) for k in range(3)))
    t_near = timed_eval(node.eval, p, repeat)
    dr.sync_thread()
    return dict(value=n / t / 1e6, unit="M evals/s", baseline=20.0, baseline_is="goal",
                near_surface_mevals=n / t_near / 1e6, stacks=f"{S.nx}x{S.ny}", sigma=node.sigma,
                fast_path_cells=node.fast_path_fractions)


def bench_layers_stabilize_s(repeat):

    def grid(n, seed):
        H = 20.0 + 4.0 * _smooth_noise((n, n), n / 16, seed)
        S = MaterialStacks.from_heightfield(H, 0.5, z0=0.0, z1=60.0, dz=0.01)
        rng = np.random.default_rng(seed)
        cols = rng.choice(S.ncol, S.ncol // 10, replace=False)
        block = np.full((len(cols), 300), -1, dtype=np.int16)
        hgt = rng.integers(20, 300, len(cols))
        mat = rng.choice([SAND, ROCK], len(cols))
        block[np.arange(300)[None, :] < hgt[:, None]] = np.repeat(mat, hgt)
        tops = (S.heights().ravel()[cols] / S.dz).astype(int)
        # One window for all: write each column's pile just above its own top.
        lev0 = int(tops.min())
        w = int(tops.max()) - lev0 + 300
        wide = np.full((len(cols), w), -1, dtype=np.int16)
        for r in range(len(cols)):
            a = tops[r] - lev0
            wide[r, a:a + 300] = block[r]
        return S.rewrite(cols, lev0, wide)

    stabilize(grid(64, 0))                       # compile / load the numba kernels
    S = grid(1024, 1)
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        T, stats = stabilize(S)
        times.append(time.perf_counter() - t)
    return dict(value=statistics.median(times), unit="s", baseline=1.0, baseline_is="target",
                sweeps=stats["sweeps"], moved_m3=stats["moved_levels"] * S.dz * S.cell ** 2,
                max_slope_excess=float(slope_excess(T)))


BENCHMARKS = {
    "layers_memory_bytes": (bench_layers_memory_bytes, 1),
    "layers_field_evals": (bench_layers_field_evals, 5),
    "layers_stabilize_s": (bench_layers_stabilize_s, 3),
}
