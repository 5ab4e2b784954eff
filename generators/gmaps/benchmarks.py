"""Benchmarks of the 3-G-map terrain evolution (generators/gmaps, Bezin et al.).

``gmaps_bytes_per_dart``  bytes a dart of the map's arrays: four int32 involutions
                          plus one int32 packing the vertex index and volume
                          label (``GMap.dart_bytes``); baseline: the paper's 20
                          (goal ≤ 20). ``with_points``: the same with the vertex
                          positions (float64, per vertex orbit) spread over the
                          darts, for the final arch.
``gmaps_arch_bytes``      KB of the final arch map (seed 0), compacted: dart arrays
                          plus vertex positions; baseline: the paper's < 16 KB
                          (§4.1, "less than 16 Kb").
``gmaps_events_per_s``    queue events a second in the drilling scenario (seed 0,
                          default length, validity check after each event as in
                          the CLI default): every displacement taken off the
                          priority queue counts (free moves and topological
                          events); ``topological_per_s`` counts only holes,
                          splits, slides, contractions and pinches. Baseline: the
                          same run with ``check=False`` (the cost of checking).
                          Median over ``repeat`` runs; pure Python, single thread.
"""

from __future__ import annotations

import statistics
import time

from . import events, scenarios


def _arch():
    res = scenarios.run("arch", seed=0, check=False)
    res.gmap.compact()
    return res


def bench_bytes_per_dart(repeat):
    g = _arch().gmap
    return dict(value=g.dart_bytes(), unit="B/dart", baseline=20.0, baseline_is="paper",
                with_points=round(g.nbytes() / g.n_darts, 2), darts=g.n_darts)


def bench_arch_bytes(repeat):
    g = _arch().gmap
    return dict(value=round(g.nbytes() / 1024, 2), unit="KB", baseline=16.0, baseline_is="paper",
                darts=g.n_darts, vertices=g.n_points, dart_kb=round(g.n_darts * g.dart_bytes() / 1024, 2))


def _drill_rate(check):
    popped = {"n": 0}
    orig = events.EventQueue._apply

    def counting(self, it, ev):
        popped["n"] += 1
        return orig(self, it, ev)
    events.EventQueue._apply = counting
    try:
        t = time.perf_counter()
        res = scenarios.run("drilling", seed=0, check=check)
        dt = time.perf_counter() - t
    finally:
        events.EventQueue._apply = orig
    return popped["n"] / dt, res.events / dt, popped["n"], res.events


def bench_events_per_s(repeat):
    runs = [_drill_rate(True) for _ in range(max(1, repeat))]
    base = [_drill_rate(False) for _ in range(max(1, repeat))]
    return dict(value=round(statistics.median(r[0] for r in runs), 1), unit="events/s",
                baseline=round(statistics.median(r[0] for r in base), 1), baseline_is="check=False",
                topological_per_s=round(statistics.median(r[1] for r in runs), 2),
                queue_events=runs[0][2], topological_events=runs[0][3])


BENCHMARKS = {
    "gmaps_bytes_per_dart": (bench_bytes_per_dart, 1),
    "gmaps_arch_bytes": (bench_arch_bytes, 1),
    "gmaps_events_per_s": (bench_events_per_s, 3),
}
