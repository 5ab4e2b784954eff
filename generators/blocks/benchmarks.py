"""Benchmarks of the implicit blocks (implicit-blocks-2020, issue 6).

``blocks_tile_s``      seconds to generate one block tile (s = 20 m, Poisson radius
                       0.7 m: ~13,000 samples as in Table 1), the largest median
                       over the six structure types; per-type medians in the extras
                       (``s_<structure>``), with blocks and fractures per type.
                       Baseline: the goal, 2 s per tile (the paper: 6.9-25.4 s).
``blocks_tile_bytes``  MB of the arrays that define a tile's block functions (planes,
                       per-block ranges, anchors), the largest over the structure
                       types; extras: per type, and the tile-local lookup grid.
                       Baseline: the goal and the paper, 0.6 MB.
``blocks_field_evals`` M evals/s of a replicated block field over a terrain: an
                       equidimensional tile (smoothness 0.25 m, warp 0.05 m)
                       replicated on the steep part of a 120 m heightfield with a
                       20 m cliff, ``max(f, t)``, at random points of its box; the
                       extra ``near_mevals`` is the rate at random points within
                       2 m of the surface of the cliff. Baseline: the goal, 20.
"""

from __future__ import annotations

import statistics
import time

import mitsuba as mi
import numpy as np

from arches_render import field as F
from arches_render.timing import random_points, timed_eval

from .block_field import BlockField
from .replication import replicate
from .tile_cache import TileParams, build_tile

STRUCTURES = ("equidimensional", "rhombohedral", "polyhedral", "tabular", "columnar", "prismatic")
PAPER_S = {"equidimensional": 6.9, "rhombohedral": 12.0, "polyhedral": 25.4, "tabular": 16.3}


def _tile(structure, seed=1):
    return build_tile(TileParams(structure=structure, size=20.0, point_radius=0.7, seed=seed))


def bench_blocks_tile_s(repeat):
    _tile("tabular")  # numba compilation (cached on disk) and imports
    out, extra = {}, {}
    for st in STRUCTURES:
        times = []
        for i in range(repeat):
            t = time.perf_counter()
            tile = _tile(st, seed=1 + i)
            times.append(time.perf_counter() - t)
        out[st] = statistics.median(times)
        extra[f"s_{st}"] = out[st]
        extra[f"blocks_{st}"] = tile.n_blocks
        extra[f"discs_{st}"] = tile.stats["discs"]
    extra["points"] = tile.stats["points"]
    return dict(value=max(out.values()), unit="s", baseline=2.0, baseline_is="goal",
                paper="6.9-25.4 s (Table 1)", **extra)


def bench_blocks_tile_bytes(repeat):
    sizes, extra = {}, {}
    for st in STRUCTURES:
        tile = _tile(st)
        sizes[st] = tile.nbytes() / 1e6
        extra[f"mb_{st}"] = sizes[st]
        field = BlockField(tile, smoothness=0.25, warp=0.05, warp_wavelength=0.5)
        extra[f"grid_mb_{st}"] = (field.nbytes() - tile.nbytes()) / 1e6
    return dict(value=max(sizes.values()), unit="MB", baseline=0.6, baseline_is="goal",
                paper="< 0.6 MB (Table 2)", **extra)


def _terrain():
    x = np.linspace(-60, 60, 241)
    X, Y = np.meshgrid(x, x)
    # A 20 m escarpment (steep where |x - 5 sin(y/15)| < 3) on gentle ground.
    u = (X - 5 * np.sin(Y / 15.0)) / 3.0
    H = 10 * np.tanh(u) + 0.5 * np.sin(X / 7.0) * np.cos(Y / 9.0) + 10.0
    host = F.Heightfield(H, (-60, -60, 60, 60), base=-2.0)
    tile = _tile("equidimensional")
    node = replicate(host, tile, [-15, -60, -2], [15, 60, 25], distance_range=(-3.0, 2.0),
                     min_slope=55.0, smoothness=0.25, warp=0.05, warp_wavelength=0.5, seed=1)
    return node, H


def bench_blocks_field_evals(repeat):
    node, H = _terrain()
    lo, hi = node.bounds()
    n = 1 << 20
    t_box = timed_eval(node.eval, random_points(n, lo, hi, seed=2), repeat)
    # Points within 2 m of the cliff's surface.
    rng = np.random.default_rng(3)
    y = rng.uniform(-60, 60, n)
    z = rng.uniform(0.5, 19.5, n)
    x0 = 5 * np.sin(y / 15.0) + 3.0 * np.arctanh(np.clip((z - 10.0) / 10.0, -0.999, 0.999))
    x = x0 + rng.uniform(-2, 2, n)
    pts = mi.Point3f(*(mi.Float(np.asarray(v, np.float32)) for v in (x, y, z)))
    t_near = timed_eval(node.eval, pts, repeat)
    blocks = node.children[1]
    return dict(value=n / t_box / 1e6, unit="M evals/s", baseline=20.0, baseline_is="goal",
                near_mevals=n / t_near / 1e6, copies=int(blocks.n_present),
                lipschitz=float(node.lipschitz))


BENCHMARKS = {
    "blocks_tile_s": (bench_blocks_tile_s, 3),
    "blocks_tile_bytes": (bench_blocks_tile_bytes, 1),
    "blocks_field_evals": (bench_blocks_field_evals, 5),
}
