"""Where a scene's slowest rays lose their steps, and which node's bound holds them back.

A sphere tracer steps ``r``, the free length its field grants; where ``-f / r`` (the
slope the bound assumes) is far above the field's true slope along the ray, some node
answers with a loose bound. For the slowest rays of one kind (those at or above the
99th percentile of :func:`ray_steps.traced_rays`' step counts), this walks one ray at a
time with the renderer's own step, prints where along the ray its steps fall, and at the
points of the walk where it crawls prints every node's value ``f`` and ``-f / r``: the
node whose ratio equals the root's is the one to tighten (the arch bridge's blend answered
27.9, its sum's global bound, where both operands were below 2.5 and 7.4).

By hand, for a sphere-traced scene::

    python benchmarks/bound_audit.py SCENE [--kind camera|shadow|bounce] [--rays N]
"""

from __future__ import annotations

import argparse
import os
import sys

import drjit as dr
import mitsuba as mi
import numpy as np


def tail_rays(rays, count, seed=0):
    """Lanes of ``rays`` (a :class:`ray_steps.TracedRays`) at or above the 99th
    percentile of steps, ``count`` of them drawn at random."""
    steps = np.broadcast_to(rays.result.steps.numpy(), rays.lanes.shape)
    cut = np.percentile(steps[rays.lanes], 99)
    tail = np.flatnonzero(rays.lanes & (steps >= cut))
    return np.random.default_rng(seed).choice(tail, min(count, len(tail)), replace=False)


def lane(value, i):
    """Lane ``i`` of a Dr.Jit array or vector (broadcast literals included) as a 1-lane copy."""
    if isinstance(value, (mi.Point3f, mi.Vector3f)):
        return type(value)(*(lane(c, i) for c in value))
    v = value.numpy()
    return mi.Float([float(v[i] if v.size > 1 else v.ravel()[0])])


def walk(tracer, o, d, cone, any_hit, max_steps=2000):
    """Step one ray with the tracer's own step: rows ``(t, f, r)`` of every step."""
    from arches_render.render.march import March, ShadowProbe, ray_box
    t_in, t_out = ray_box(o, d, tracer.lo_op, tracer.hi_op)
    march = March.start(dr.maximum(t_in, 0.0), tracer.omega)
    probe = ShadowProbe.start(1) if any_hit else None
    rows = []
    for _ in range(max_steps):
        t = march.t.numpy()[0]
        if any_hit:
            march, out, r, probe = tracer.step(o, d, march, t_out, cone, probe)
        else:
            march, out, r = tracer.step(o, d, march, t_out, cone)
        f = tracer.field.eval_bounds(o + d * mi.Float([t]), (0.0,), d, tracer.footprint(cone, mi.Float([t])))[0]
        dr.eval(march, out, probe, r, f)  # each step its own small kernel (no growing graph)
        rows.append((t, f.numpy()[0], r.numpy()[0]))
        if (out.hit | out.done | out.invalid).numpy()[0]:
            break
    return np.array(rows)


def node_ratios(node, points, direction, name="root", depth=0, max_depth=4):
    """Lines ``name kind f... -f/r...`` for ``node`` and its operands at ``points`` (not
    below a transform, whose operand is evaluated elsewhere)."""
    f, (r,) = node.eval_bounds(points, (0.0,), direction)
    dr.eval(f, r)
    f, r = f.numpy(), np.broadcast_to(r.numpy(), f.shape)
    ratio = np.where(r > 0, -f / np.maximum(r, 1e-30), np.inf)
    lines = ["  " * depth + f"{name} {type(node).__name__} (L {node.lipschitz:.3g})",
             "  " * depth + "   f    " + " ".join(f"{v:9.4f}" for v in f),
             "  " * depth + "   -f/r " + " ".join(f"{v:9.2f}" for v in ratio)]
    # A transform's operand sees other points than the world's: its line would mislead.
    if depth < max_depth and getattr(node, "kind", "") != "transform":
        kids = list(getattr(node, "children", ()) or ())
        if getattr(node, "child", None) is not None:
            kids.append(node.child)
        for k, child in enumerate(kids):
            lines += node_ratios(child, points, direction, f"{name}.{k}", depth + 1, max_depth)
    return lines


def audit(path, kind, count):
    """Print the walk and the node ratios of ``count`` slow rays of ``kind``."""
    from arches_render.render.heightfield_caster import make_tracer
    from arches_render.render.sphere_tracer import SphereTracer
    from arches_render.scene import load_scene
    from ray_steps import traced_rays
    desc = load_scene(path)
    r = desc.render
    tracer = make_tracer(desc.field, eps=r.eps, omega=r.omega, max_steps=r.max_steps)
    if not isinstance(tracer, SphereTracer):
        print(f"{path}: traced by {type(tracer).__name__}; the audit walks sphere-traced scenes")
        return
    rays = traced_rays(desc, tracer)[kind]
    for i in tail_rays(rays, count):
        o, d = lane(rays.origin, i), lane(rays.direction, i)
        cone = (lane(rays.cone[0], i), lane(rays.cone[1], i))
        rows = walk(tracer, o, d, cone, kind == "shadow")
        print(f"\n{kind} ray {i}: {len(rows)} steps, t {rows[0, 0]:.3g} .. {rows[-1, 0]:.4g}")
        edges = np.array([0, 0.01, 0.1, 1, 10, 100, 1e3, np.inf])
        hist = np.histogram(rows[:, 0], edges)[0]
        print("  steps by t: " + ", ".join(f"<{e:g}: {h}" for e, h in zip(edges[1:], hist) if h))
        # The crawl: where the steps are shortest against the distance travelled.
        picks = np.unique(np.linspace(0, len(rows) - 1, 6).astype(int))
        ts = rows[picks, 0]
        print("  t      " + " ".join(f"{t:9.4g}" for t in ts))
        pts = mi.Point3f(*(mi.Float(np.float32(o[k].numpy()[0]) + np.float32(d[k].numpy()[0]) * ts.astype(np.float32))
                           for k in range(3)))
        dv = mi.Vector3f(*(mi.Float(np.full(len(ts), d[k].numpy()[0], np.float32)) for k in range(3)))
        print("\n".join("  " + line for line in node_ratios(desc.field, pts, dv)))


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--kind", choices=("camera", "shadow", "bounce"), default="shadow")
    parser.add_argument("--rays", type=int, default=3)
    args = parser.parse_args(argv)
    from arches_render import backend
    backend.set_variant()
    audit(args.scene, args.kind, args.rays)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    sys.exit(main(sys.argv[1:]))
