"""Bounding-box culling of expensive subtrees for ray queries.

Far from its box ``B`` a bounded node's field is at most ``-dist(p, B)`` (every node
of the language falls at least at unit rate away from its box, see
:attr:`Node.unit_falloff`). :class:`Culled` exploits it: where ``dist(p, B) > T`` it
skips the subtree and answers ``f' = -dist(p, B)`` with the distance bounds
``max(dist(p, B) - c, 0)``, which hold by that same inequality. The value ``f'`` is
not the subtree's, but it cannot change what a tracer decides:

* a hit needs the root value near 0, while ``f' < -T`` and ``T`` exceeds the hit
  tolerance;
* near any surface of the rest of the tree (value ``>= -tol``), ``f'`` and the
  true value both lie at least the largest blend radius ``k`` below it when
  ``T >= k + tol``, so unions, blends, intersections and differences return the
  same number.

Displacements and domain warps are also culled by value: where the child's own
value proves the result below ``-T`` (``f_child + max_offset < -T``), the noise is
skipped and ``f' = f_child + max_offset`` is returned, by the same argument. This
follows the shape instead of its box.

Dr.Jit's symbolic ``if_stmt`` skips a branch for a whole SIMD packet when no lane
takes it, so rays far from a noisy arch do not pay for its noise.
"""

from __future__ import annotations

import copy

import drjit as dr

from .node import Node, box_distance, box_gap, box_reach, finite_box, opaque_float
from .operators import Blend, SmoothIntersection

#: Relative cost (one exact primitive = 1) above which a bounded subtree is culled.
CULL_COST = 6.0


class Culled(Node):
    """``child`` evaluated only within ``margin`` of its box (see module docstring)."""

    kind = "culled"

    def __init__(self, child: Node, margin: float):
        self.children = (child,)
        lo, hi = child.bounds()
        self.lo_np, self.hi_np = lo, hi
        self._lo = [opaque_float(v) for v in lo]
        self._hi = [opaque_float(v) for v in hi]
        self._margin = opaque_float(margin)
        self.margin_np = float(margin)

    def eval(self, p):
        return self.children[0].eval(p)

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        dist = box_distance(p, self._lo, self._hi)

        def near(p, dist):
            return self.children[0].eval_bounds(p, levels, direction, footprint)

        def far(p, dist):
            return -dist, tuple(dr.maximum(dist - c, 0.0) for c in levels)

        return dr.if_stmt((p, dist), dist <= self._margin, near, far, label="culled")

    def bounds(self):
        return self.children[0].bounds()

    def box_range(self, lo, hi):
        # The values eval_bounds answers (what tracers see): the child's within the
        # margin of its box, -dist(p, B) beyond; a box may hold both.
        gap, far = box_gap(lo, hi, self._lo, self._hi), box_reach(lo, hi, self._lo, self._hi)
        a, b = self.children[0].box_range(lo, hi)
        beyond = gap > self._margin
        within = far <= self._margin
        lo_v = dr.select(beyond, -far, dr.select(within, a, dr.minimum(a, -far)))
        hi_v = dr.select(beyond, -gap, dr.select(within, b, dr.maximum(b, -self._margin)))
        return lo_v, hi_v

    @property
    def lipschitz(self):
        return self.children[0].lipschitz

    @property
    def cost(self):
        return 1.0


def _max_blend_radius(root: Node) -> float:
    radii = [n.radius_np for n in root.walk() if isinstance(n, (Blend, SmoothIntersection))]
    return max(radii, default=0.0)


def with_culling(root: Node, tolerance: float) -> Node:
    """Copy of the tree with :class:`Culled` around costly, bounded subtrees.

    Parameters
    ----------
    root : Node
        The construction tree (left unchanged).
    tolerance : float
        The largest hit tolerance of the tracer (``eps * t_max``), in metres.

    Returns
    -------
    Node
        A tree with the same field values near every surface.
    """
    margin = _max_blend_radius(root) + 2.0 * tolerance + 1e-3

    def visit(node: Node, is_root: bool) -> Node:
        new = node
        if node.children:
            kids = tuple(visit(c, False) for c in node.children)
            if any(a is not b for a, b in zip(kids, node.children)):
                new = copy.copy(node)
                new.children = kids
        bounded = finite_box(node) is not None
        if hasattr(node, "skip_margin"):
            new = copy.copy(new) if new is node else new
            new.skip_margin = margin
        if not is_root and bounded and node.unit_falloff and node.cost >= CULL_COST:
            return Culled(new, margin)
        return new

    return visit(root, True)
