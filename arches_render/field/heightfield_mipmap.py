"""Maximum mipmaps of a heightfield, and which trees a heightfield ray cast can answer.

Two things a renderer needs before it can ray-cast a :class:`~.heightfield.Heightfield`
exactly instead of sphere-tracing it; both are field math, so they live here and
import no renderer.

**The pyramids** (:class:`MaxMipmap`). Level 0 holds, for each bilinear cell
``(j, i)`` (samples ``i..i+1`` by ``j..j+1``), the largest and smallest of its four
corner samples: a bilinear patch is a convex combination of its corners, so it
lies between them. Level ``l + 1`` holds the maximum (minimum) of 2x2 blocks of
level ``l`` (odd sizes padded with -inf / +inf), up to a single cell. The samples
are the float32 values the field evaluates, and the bounds are widened by a few
ulps (``2^-20`` relative) so that they also hold for float32 ``lerp`` results, which
may round a hair outside their operands.

**Cast plans** (:func:`heightfield_cast_plan`). Let ``a`` be a heightfield's field
``min(h(x, y) - z, box)`` (positive inside). Inside its prism box the solid is
exactly ``{g >= 0}`` with ``g = h(x, y) - z``, so the first hit of a ray is the first
``t`` of the ray's interval in the box with ``g(t) >= 0``, which the maximum-mipmap
traversal finds exactly. A plan covers three shapes of tree:

1. the heightfield alone;
2. its intersection with sharp axis-aligned boxes (the ray interval is clipped to
   the boxes: inside all of them the intersection is ``{g >= 0}`` again);
3. a ``union`` or ``blend`` (radius ``k``, ``n`` operands) of one such operand ``a`` with
   3-D operands ``b_i`` that are bounded and fall off at unit rate outside their
   box (``b_i <= -dist(p, B_i)``, :attr:`Node.unit_falloff`).

For (3) let ``T = k + m`` with a margin ``m > 0``. Wherever every ``b_i <= -T``, the
root equals ``a`` where ``a >= -m`` and is ``<= -m`` elsewhere. The blend folds
``g_j = smax_k(g_{j-1}, b_j)`` from ``g = a`` (with ``a`` the first or second operand:
the polynomial ``smax`` of two values is bitwise symmetric). Induction: where
``g_{j-1} = a >= -m``, ``a - b_j >= k`` so the seam is inactive and ``g_j = a``; where
``g_{j-1} <= -m``, either ``b_j > g_{j-1}`` and ``g_j <= b_j + k/4 < -m``, or with
``delta = g_{j-1} - b_j in [0, k)``, ``g_j <= -T + delta + (k - delta)^2 / (4k) <= -m``
(convex in ``delta``, equal to ``-m`` at ``delta = k``). A union is the case ``k = 0``.
So on any stretch of a ray where all ``b_i <= -T`` the root's surface is ``a``'s and
the exact cast answers it; elsewhere a sphere tracer takes over.

Certifying ``b_i <= -T``: outside the union box of the ``B_i`` grown by ``T`` it holds
by unit falloff. Inside, :func:`far_leaves` splits each ``b_i`` into leaves with
offsets, ``b_i <= max_l (f_l + G_l)``, using

* union: ``max``; difference ``a - b <= a``; displacement: ``+ max_offset``;
* an ``n``-operand blend of radius ``k``: ``+ e_n(k)`` (:func:`blend_excess`), the
  tight excess of the fold over its largest operand, ``e_n < k`` for every ``n``,

so ``b_i <= -T`` on the stretch ``|s| < min_l d_l`` where ``d_l`` is leaf ``l``'s own
distance bound to its level ``T + G_l`` (``Node.eval_bounds``).

``e_n``: ``smax_k`` is non-decreasing in both arguments (partial derivatives in
``[0, 1]``). If every operand is ``<= M`` and ``g_{j-1} <= M + e_{j-1}``, then
``g_j <= smax_k(M + e_{j-1}, M) = M + phi(e_{j-1})`` with
``phi(e) = e + max(k - e, 0)^2 / (4k)``; from ``e_1 = 0``: ``e_2 = k/4``,
``e_3 = 0.39 k``, ..., increasing towards ``k`` (``phi(e) < k`` for ``e < k``).
Tighter than the ``(n - 1) k / 4`` of summing every seam's bump.

References
----------
Tevs, A., Ihrke, I., Seidel, H.-P. (2008). Maximum mipmaps for fast, accurate, and
scalable dynamic height field rendering. Proc. I3D 2008, 183-190.
Quilez, I. (2013). Smooth minimum. https://iquilezles.org/articles/smin/
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .culling import Culled
from .heightfield import Heightfield
from .node import Node
from .operators import Blend, Difference, Intersection, Union
from .primitives import Box
from .warps import Displace

#: Relative widening of the pyramid bounds (covers float32 ``lerp`` rounding).
WIDEN = 2.0 ** -20


def _reduce(a: np.ndarray, op, fill: float) -> np.ndarray:
    """2x2 reduction of a 2-D array with ``op`` (odd sizes padded with ``fill``)."""
    ny, nx = a.shape
    py, px = ny % 2 if ny > 1 else 0, nx % 2 if nx > 1 else 0
    if py or px:
        a = np.pad(a, ((0, py), (0, px)), constant_values=fill)
    ny, nx = a.shape
    by, bx = (2, ny // 2) if ny > 1 else (1, 1), (2, nx // 2) if nx > 1 else (1, 1)
    return op(op(a.reshape(by[1], by[0], bx[1], bx[0]), axis=3), axis=1)


class MaxMipmap:
    """Maximum and minimum pyramids of a bilinear heightfield's cells.

    Parameters
    ----------
    heights : array_like
        ``(ny, nx)`` samples, ``ny, nx >= 2``; converted to float32 (the values the
        field interpolates).

    Attributes
    ----------
    shapes : list of (int, int)
        ``(rows, cols)`` of each level; level 0 is ``(ny - 1, nx - 1)``, the last
        level is ``(1, 1)``.
    offsets : numpy.ndarray
        uint32 start of each level in the flat arrays (row-major levels).
    max_flat, min_flat : numpy.ndarray
        float32 bounds of all levels, concatenated.
    corners : numpy.ndarray
        ``(ny - 1, nx - 1, 4)`` float32 corner samples ``h00, h10, h01, h11`` of each
        cell, side by side so that one packet gather fetches a patch.
    """

    def __init__(self, heights):
        H = np.asarray(heights, dtype=np.float32)
        if H.ndim != 2 or min(H.shape) < 2:
            raise ValueError("heights must be a 2-D array of at least 2x2 samples")
        corners = (H[:-1, :-1], H[:-1, 1:], H[1:, :-1], H[1:, 1:])
        self.corners = np.ascontiguousarray(np.stack(corners, axis=-1))
        hi = np.maximum.reduce(corners).astype(np.float64)
        lo = np.minimum.reduce(corners).astype(np.float64)
        his, los = [hi], [lo]
        while hi.shape != (1, 1):
            hi = _reduce(hi, np.max, -np.inf)
            lo = _reduce(lo, np.min, np.inf)
            his.append(hi)
            los.append(lo)
        self.shapes = [a.shape for a in his]
        sizes = [a.size for a in his]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.uint32)
        mx = np.concatenate([a.ravel() for a in his])
        mn = np.concatenate([a.ravel() for a in los])
        # Widen outward so the bounds hold for float32 interpolation results.
        self.max_flat = (mx + (np.abs(mx) + 1.0) * WIDEN).astype(np.float32)
        self.min_flat = (mn - (np.abs(mn) + 1.0) * WIDEN).astype(np.float32)

    @property
    def levels(self) -> int:
        """Number of levels (the top one is a single cell)."""
        return len(self.shapes)

    def level(self, l: int, which: str = "max") -> np.ndarray:
        """Level ``l`` as a 2-D array (``which`` = ``'max'`` or ``'min'``)."""
        flat = self.max_flat if which == "max" else self.min_flat
        n = int(np.prod(self.shapes[l]))
        return flat[self.offsets[l]:self.offsets[l] + n].reshape(self.shapes[l])

    def nbytes(self) -> int:
        """Memory of both pyramids, in bytes."""
        return self.max_flat.nbytes + self.min_flat.nbytes + self.offsets.nbytes + self.corners.nbytes


@dataclass
class CastPlan:
    """How a tree reduces to a heightfield ray cast (see module docstring).

    Attributes
    ----------
    heightfield : Heightfield
        The operand cast exactly.
    clip_lo, clip_hi : numpy.ndarray
        The box inside which the operand's solid is ``{h - z >= 0}`` (the prism
        box, intersected with the clipping boxes).
    others : tuple of Node
        The 3-D operands ``b_i`` of a union or blend (empty for shapes 1 and 2).
    others_lo, others_hi : numpy.ndarray or None
        Union box of ``others``.
    radius : float
        Blend radius ``k`` (0 for a union).
    leaves : tuple of (Node, float)
        :func:`far_leaves` of every operand in ``others``.
    """

    heightfield: Heightfield
    clip_lo: np.ndarray
    clip_hi: np.ndarray
    others: tuple = ()
    others_lo: np.ndarray | None = None
    others_hi: np.ndarray | None = None
    radius: float = 0.0
    leaves: tuple = ()

    def zone(self, margin: float):
        """Box outside which every ``b_i <= -(radius + margin)`` (the union box of
        ``others`` grown by that much), or ``None`` without others."""
        if not self.others:
            return None
        grow = self.radius + float(margin)
        return self.others_lo - grow, self.others_hi + grow


def blend_excess(n: int, k: float) -> float:
    """``e_n(k)``: how far an ``n``-operand polynomial blend of radius ``k`` can rise
    above its largest operand (module docstring); 0 for ``n = 1``, below ``k``."""
    e = 0.0
    for _ in range(int(n) - 1):
        e = e + max(k - e, 0.0) ** 2 / (4.0 * k)
    return e


#: Above this many leaves an operand is certified by its own bound instead.
MAX_LEAVES = 32


def far_leaves(node: Node, offset: float = 0.0) -> list:
    """Leaves ``(f_l, G_l)`` with ``node <= max_l (f_l + G_l)`` everywhere.

    Parameters
    ----------
    node : Node
        A bounded subtree.
    offset : float
        ``G`` accumulated above ``node``.

    Returns
    -------
    list of (Node, float)
        At most :data:`MAX_LEAVES` pairs (else ``[(node, offset)]``).
    """
    def walk(n, g):
        if isinstance(n, Culled):
            return walk(n.children[0], g)
        if type(n) is Union:
            return [x for c in n.children for x in walk(c, g)]
        if type(n) is Blend:
            e = blend_excess(len(n.children), n.radius_np)
            return [x for c in n.children for x in walk(c, g + e)]
        if type(n) is Difference:
            return walk(n.children[0], g)
        if type(n) is Displace:
            return walk(n.children[0], g + n.max_offset)
        return [(n, g)]

    leaves = walk(node, float(offset))
    return leaves if len(leaves) <= MAX_LEAVES else [(node, float(offset))]


def _clipped_heightfield(node: Node):
    """``(heightfield, lo, hi)`` if ``node`` is a plain heightfield, possibly
    intersected with sharp axis-aligned boxes; else ``None``."""
    if type(node) is Heightfield:  # subclasses (implicit heightfields) differ in value
        lo, hi = node.bounds()
        return node, np.asarray(lo, float), np.asarray(hi, float)
    if type(node) is Intersection:
        found, lo, hi = None, None, None
        boxes = []
        for c in node.children:
            sub = _clipped_heightfield(c)
            if sub is not None and found is None:
                found, lo, hi = sub
            elif type(c) is Box and c.round_np == 0.0:
                boxes.append(c.bounds())
            else:
                return None
        if found is None:
            return None
        for blo, bhi in boxes:
            lo, hi = np.maximum(lo, blo), np.minimum(hi, bhi)
        return found, lo, hi
    return None


def heightfield_cast_plan(root: Node) -> CastPlan | None:
    """The :class:`CastPlan` of a tree, or ``None`` when a heightfield cast cannot
    answer its ray queries (see the module docstring for the three shapes).

    Parameters
    ----------
    root : Node
        Root of the construction tree (unculled).

    Returns
    -------
    CastPlan or None
    """
    sub = _clipped_heightfield(root)
    if sub is not None:
        return CastPlan(*sub)
    if type(root) not in (Union, Blend):
        return None
    kids = root.children
    found = [i for i, c in enumerate(kids) if _clipped_heightfield(c) is not None]
    if len(found) != 1:
        return None
    pos = found[0]
    # A blend is a left fold; only its first two operands commute bitwise.
    if type(root) is Blend and pos > 1:
        return None
    others = tuple(c for i, c in enumerate(kids) if i != pos)
    boxes = []
    for c in others:
        lo, hi = c.bounds()
        if not (c.unit_falloff and np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return None
        boxes.append((np.asarray(lo, float), np.asarray(hi, float)))
    k = root.radius_np if type(root) is Blend else 0.0
    hf, lo, hi = _clipped_heightfield(kids[pos])
    leaves = tuple(x for c in others for x in far_leaves(c))
    return CastPlan(hf, lo, hi, others, np.min([b[0] for b in boxes], axis=0),
                    np.max([b[1] for b in boxes], axis=0), k, leaves)
