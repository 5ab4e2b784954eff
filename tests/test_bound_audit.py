"""The bound audit (``benchmarks/bound_audit.py``): its walk is the renderer's march, step
for step, and its table names every node of the tree it descends."""

from __future__ import annotations

import os
import sys

import numpy as np
from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.render.sphere_tracer import SphereTracer  # noqa: E402

from test_shadow_probes import _query, _rays_leaving  # noqa: E402
from test_surface_cells import TREES  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
import bound_audit  # noqa: E402


def test_the_walk_takes_the_tracers_steps():
    tracer, pts, d = _rays_leaving("arch")
    for any_hit in (False, True):
        res = _query(tracer, pts, d, any_hit)
        # Two rays of 6-30 steps each (a walk runs a kernel a step: seconds a ray).
        chosen = np.flatnonzero((res["steps"] >= 6) & (res["steps"] <= 30))[:2]
        assert len(chosen) == 2
        for i in chosen:
            o = mi.Point3f(*(mi.Float([float(v)]) for v in pts[i]))
            u = mi.Vector3f(*(mi.Float([float(v)]) for v in d[i]))
            rows = bound_audit.walk(tracer, o, u, None, any_hit)
            assert len(rows) == res["steps"][i], (i, any_hit)


def test_node_ratios_name_every_node():
    """Three lines a node (name, values, ratios), operands indented under their node."""
    tree = TREES["sculpted"]
    p = mi.Point3f(mi.Float([0.0, 1.0]), mi.Float([0.0, 1.0]), mi.Float([0.5, 0.5]))
    u = mi.Vector3f(mi.Float([1.0, 1.0]), mi.Float([0.0, 0.0]), mi.Float([0.0, 0.0]))
    lines = bound_audit.node_ratios(tree, p, u)

    def names(node, name, depth):
        kids = list(getattr(node, "children", ()) or ())
        if getattr(node, "child", None) is not None:
            kids.append(node.child)
        below = [] if depth == 4 or node.kind == "transform" else kids
        return [name] + [n for k, c in enumerate(below) for n in names(c, f"{name}.{k}", depth + 1)]
    expected = names(tree, "root", 0)
    assert len(expected) > 1 and len(lines) == 3 * len(expected)
    assert [line.split()[0] for line in lines[::3]] == expected
