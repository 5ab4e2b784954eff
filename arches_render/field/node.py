"""The node protocol of the field language.

A field ``f : R^3 -> R`` is positive inside matter, zero on the surface and negative
in air (see :mod:`arches_render`). Every node of a construction tree answers three
questions:

``eval(p)``
    ``f`` on a batch of points (``mi.Point3f``), as Dr.Jit code that can be traced
    into any kernel: the sphere tracer's loop or a plain evaluation for generators.
``bounds()``
    an axis-aligned box outside of which ``f <= 0`` (no matter), as two numpy
    3-vectors; infinite components are allowed for unbounded nodes (a plane).
``lipschitz``
    a guaranteed bound ``L`` with ``|f(a) - f(b)| <= L |a - b|`` for all ``a, b``,
    derived from the math of the node and of its children, never measured from
    samples (a measured bound can tunnel through thin features).
``box_range(lo, hi)``
    ``(f_min, f_max)``: bounds of the node's (full-detail) values over the boxes
    ``[lo, hi]`` (``mi.Point3f`` each, one box a lane), from interval arithmetic
    through the operators and what leaves know of their values (a heightfield its
    maximum mipmap, a primitive set its empty cells); the default is Hart's, the
    value at the box's centre plus or minus the slope bound in the ball around it.
    A structure that classifies cells (:mod:`~arches_render.field.surface_cells`)
    asks it.
``eval_bounds(p, levels)``
    ``(f, ds)``: the value and, for each ``c`` in ``levels``, a *local* lower bound
    ``d >= 0`` of the distance from ``p`` to the super-level set ``{f >= -c}``
    (``c = 0``: the solid). The default is Hart's ``max(-f - c, 0) / L``; operators
    compose their operands' bounds (a union is as far as its nearest operand, an
    intersection as far as its farthest, a smooth blend is handled in
    :mod:`~arches_render.field.operators`), so a ray far from a noisy feature is not
    slowed by that feature's large ``L``. Every composition is a set inclusion,
    hence as rigorous as the global bound. All levels are answered from one
    evaluation of the node, so the kernel holds each node's code once.

    With ``direction`` (a unit ``mi.Vector3f``), ``d`` may instead bound the
    distance *along the line* ``p + s direction`` before it meets the set, on both
    sides (``|s| < d`` is free): a free ball is one such bound, and nodes that know
    better (heightfields) return more. Two-sided intervals are what over-relaxed
    sphere tracing needs to check that consecutive steps overlap.

    *Ahead.* Inside :func:`one_sided`, the lanes it names may be answered with a
    length ``d`` free *ahead* only (``0 < s < d``). A tracer asks so where it needs
    no backward extent (a ray's first point, a verified point), since a ray that
    leaves a surface has a two-sided length of ~0 there whatever its direction. Every
    two-sided answer is also a one-sided one, and every composition above (a union
    as far as its nearest operand, set inclusions, balls) holds for intervals that
    start at ``p`` as for intervals around it, so operators need not know; only
    nodes that bound their value along the line answer differently
    (:mod:`generators.terrain.elevation_line`).

    With ``footprint`` (a :class:`~arches_render.field.lod.Footprint`: the ray cone's
    radius at ``p`` and its rate), the value and the bounds are those of the node's
    *footprint field*, where octaves finer than the cone are skipped
    (:mod:`arches_render.field.lod`); operators pass it to their operands, nodes
    without octaves ignore it. ``None``: full detail, the field of ``eval``.
"""

from __future__ import annotations

import contextlib

import drjit as dr
import mitsuba as mi
import numpy as np

from ..backend import variant


def opaque_float(value):
    """A scalar parameter as an opaque ``mi.Float`` (edited without recompiling)."""
    variant()
    return dr.opaque(mi.Float, float(value))


def jit_floats(values):
    """``values`` as a flat ``mi.Float`` in 64-byte-aligned memory.

    ``mi.Float(ndarray)`` wraps the array's memory rather than copying it, and the
    code Dr.Jit generates depends on that memory's alignment: an aligned input is
    loaded with aligned vector loads, an unaligned one byte by byte, and a packet
    gather (``dr.gather(mi.Vector4f, ...)``: four adjacent floats at once) is emitted
    only from 64-byte-aligned memory. numpy aligns to 16 bytes, so where ``malloc``
    happened to put an array decided the kernel: the same scene traced one of two
    render kernels from one process to the next (four, with two such arrays; a field
    evaluation on numpy points one of eight), and a warm kernel cache missed whenever
    another came up (seconds of LLVM for a render kernel). An aligned copy makes the
    kernel one.
    """
    variant()
    a = np.ascontiguousarray(values, dtype=np.float32).reshape(-1)
    if a.ctypes.data % 64:
        buf = np.empty(a.size + 16, np.float32)
        start = (-buf.ctypes.data % 64) // 4
        buf[start:start + a.size] = a
        a = buf[start:start + a.size]
    return mi.Float(a)


def jit_points(points):
    """``(N, 3)`` numpy positions as an ``mi.Point3f`` of aligned coordinates (:func:`jit_floats`)."""
    points = np.asarray(points).reshape(-1, 3)
    return mi.Point3f(*(jit_floats(points[:, i]) for i in range(3)))


def opaque_point(value):
    """A 3-vector parameter as an opaque ``mi.Point3f``."""
    variant()
    v = [float(x) for x in np.asarray(value, dtype=np.float64).reshape(3)]
    return mi.Point3f(*(dr.opaque(mi.Float, x) for x in v))


class Node:
    """Base class of every field node.

    Subclasses set ``self.children`` (a tuple of nodes), implement :meth:`eval`,
    :meth:`bounds` and :attr:`lipschitz`, and may override :meth:`nbytes` when they
    hold arrays.
    """

    #: Name used in scene files and by ``arches-render info``.
    kind = "node"

    children: tuple = ()

    def __new__(cls, *args, **kwargs):
        # A node holds Dr.Jit arrays of the active variant: building one selects
        # the default variant on first use (a leaf: no plugin is registered).
        variant()
        return super().__new__(cls)

    def eval(self, p):
        """Field value at the points ``p`` (``mi.Point3f``) as ``mi.Float``."""
        raise NotImplementedError

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        """``(f, ds)``: value and lower bounds of the distances to ``{f >= -c}``, c in levels
        (module docstring; this default ignores ``footprint``: full detail)."""
        f = self.eval(p)
        return f, hart_bounds(f, levels, self.lipschitz)

    def box_range(self, lo, hi):
        """``(f_min, f_max)`` of :meth:`eval` over the boxes ``[lo, hi]`` (module docstring):
        this default is ``f(c) -+ S R`` with ``c`` the box's centre, ``R`` its
        half-diagonal and ``S`` the node's slope bound in the ball ``B(c, R)``, which
        holds the box."""
        from .local_slopes import eval_local  # (it knows nodes only through this protocol)
        c = (lo + hi) * 0.5
        R = dr.norm(hi - lo) * 0.5
        f, _, (S,) = eval_local(self, mi.Point3f(c), (), None, None, (R,))
        return f - S * R, f + S * R

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box ``(lo, hi)`` containing every point where ``f > 0``."""
        raise NotImplementedError

    @property
    def lipschitz(self) -> float:
        """Guaranteed Lipschitz bound of :meth:`eval`."""
        raise NotImplementedError

    def nbytes(self) -> int:
        """Memory held by this node alone (arrays and parameters), in bytes."""
        return 64

    #: Whether ``f(p) <= -dist(p, bounds())`` outside the box (true for exact
    #: distances, heightfield prisms, Boolean and blend operators, displacements with
    #: grown boxes, rigid and uniformly scaled transforms).
    unit_falloff = True

    @property
    def lod_kappa(self) -> float:
        """``kappa`` of :mod:`~arches_render.field.lod`: with a footprint of rate ``s`` the
        node's footprint field is ``L (1 + kappa s)``-Lipschitz (0: no level of detail
        in this subtree, the field is the full one)."""
        return max((c.lod_kappa for c in self.children), default=0.0)

    def lod_error(self, radius: float) -> float:
        """A bound of ``|F_fp - F|``, how far the node's footprint field
        (:mod:`~arches_render.field.lod`) can lie from its full field for any
        footprint of radius at most ``radius`` (metres), as a Python float; 0 without
        level of detail in the subtree.

        This default sums the children's: right for every operator whose value moves
        by at most the sum of its operands' moves (max, min, smooth maxima, sums,
        differences, offsets, culling). Nodes that scale their children's values or
        warp their points, and leaves with octaves of their own, override it."""
        if not self.lod_kappa:
            return 0.0
        return sum(c.lod_error(radius) for c in self.children)

    def local_lod_error(self, p, reach: float, radius: float):
        """:meth:`lod_error` near ``p``: a bound of ``|F_fp - F|`` within ``reach`` of the
        points ``p`` (``mi.Point3f``), per lane (``mi.Float``, or a float where it is
        the same everywhere). Nodes whose octaves act in a small region (a primitive
        set's noise) answer 0 away from it; operators that sum their operands' errors
        sum these; other nodes answer their global bound."""
        if not self.lod_kappa:
            return 0.0
        if type(self).lod_error is not Node.lod_error:
            return self.lod_error(radius)
        total = 0.0
        for c in self.children:
            total = total + c.local_lod_error(p, reach, radius)
        return total

    @property
    def cost(self) -> float:
        """Relative evaluation cost (an exact primitive is 1); guides culling."""
        return 1.0 + sum(c.cost for c in self.children)

    # -- tree helpers --------------------------------------------------------------
    def walk(self):
        """Yield this node and all its descendants, depth first."""
        yield self
        for c in self.children:
            yield from c.walk()

    def count(self) -> int:
        """Number of nodes in the tree rooted here (primitive sets count once)."""
        return sum(1 for _ in self.walk())

    def tree_nbytes(self) -> int:
        """Memory of the whole tree rooted here, in bytes."""
        return sum(n.nbytes() for n in self.walk())

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(repr(c) for c in self.children)})"


def clip_index(x, lo, hi):
    """``x`` clipped to ``[lo, hi]`` with a NaN taken as ``lo``: a float that converts to an
    integer index inside the range.

    ``dr.clip`` keeps a NaN, and LLVM converts a NaN (or a float beyond the integer
    range) to an arbitrary integer: a gather indexed by it reads anywhere, and a
    mesh whose shading normal was NaN sent such points into a field lookup and
    crashed the renderer with a segmentation fault (issue 38). A NaN point gets a
    meaningless value this way, but from inside the arrays.

    Parameters
    ----------
    x : mi.Float
        Positions in cell units (any float, NaN and infinities included).
    lo, hi : float
        The range.

    Returns
    -------
    mi.Float
    """
    return dr.clip(dr.select(dr.isnan(x), lo, x), lo, hi)


def cell_index(x, n: int, kind=None):
    """Index of the cell ``floor(x)`` of ``n`` cells along an axis, clamped to ``[0, n - 1]``,
    for any float ``x`` (NaN and infinities included: :func:`clip_index`).

    Parameters
    ----------
    x : mi.Float
        Position in cell units from the grid's first cell.
    n : int
        Cells along the axis.
    kind : type, optional
        The integer array type (default ``mi.UInt32``).

    Returns
    -------
    mi.UInt32 or ``kind``
    """
    return (kind or mi.UInt32)(clip_index(x, 0.0, n - 1.0))


#: The lanes :func:`one_sided` names while a tracer's query is traced (``None``: none).
_ONE_SIDED = None


@contextlib.contextmanager
def one_sided(lanes):
    """Trace the ``eval_bounds`` calls inside this block with one-sided answers allowed
    for ``lanes`` (a per-lane ``mi.Bool``; module docstring, "Ahead").

    Dr.Jit traces the Python of a loop body once into its kernel, so the mask is read
    by the nodes while the block is traced and selects, per lane, which bound the
    kernel computes. Nested blocks restore the outer mask when they end.
    """
    global _ONE_SIDED
    outer, _ONE_SIDED = _ONE_SIDED, lanes
    try:
        yield
    finally:
        _ONE_SIDED = outer


def one_sided_lanes():
    """The lanes of the enclosing :func:`one_sided` block, or ``None`` outside one."""
    return _ONE_SIDED


#: Whether a :func:`shading_normals` block is being traced.
_SHADING = False


@contextlib.contextmanager
def shading_normals():
    """Trace the evaluations inside this block for a shading normal: nodes whose
    surface is only C0 by construction answer with a C1 stand-in of it (a heightfield:
    its bilinear elevation averaged over a cell, see
    :meth:`.heightfield.Heightfield.height`), so that the normal turns smoothly
    across the DEM's cell edges, as a mesh's interpolated vertex normals do, while
    hits stay on the exact surface. Read at trace time, as :func:`one_sided` is."""
    global _SHADING
    outer, _SHADING = _SHADING, True
    try:
        yield
    finally:
        _SHADING = outer


def shading_normals_traced() -> bool:
    """Whether a :func:`shading_normals` block encloses the code being traced."""
    return _SHADING


def refill(answers, skipped, fill=0.0):
    """``answers`` (one per level not ``skipped``, in order, then any extra items) with
    ``mi.Float(fill)`` put back at the ``skipped`` levels: for nodes that answer levels
    known before tracing without bounding them (a level holding every point)."""
    found = iter(answers)
    return [mi.Float(fill) if skip else next(found) for skip in skipped] + list(found)


def hart_bounds(f, levels, lipschitz):
    """Hart's bounds ``max(-f - c, 0) / L`` for each level ``c``."""
    inv = 1.0 / lipschitz
    return tuple(dr.maximum(-f - c, 0.0) * inv for c in levels)


def box_distance(p, lo, hi):
    """Euclidean distance from ``p`` to the box ``[lo, hi]`` (0 inside); ``lo``, ``hi``
    are sequences of three ``mi.Float`` (opaque parameters)."""
    return dr.norm(mi.Vector3f(*(dr.maximum(dr.maximum(lo[i] - p[i], p[i] - hi[i]), 0.0)
                                 for i in range(3))))


def finite_box(node) -> tuple[np.ndarray, np.ndarray] | None:
    """``node.bounds()`` when every component is finite (the box may be empty), else ``None``.

    Parameters
    ----------
    node : Node or any object with ``bounds() -> (lo, hi)``

    Returns
    -------
    (numpy.ndarray, numpy.ndarray) or None
    """
    lo, hi = node.bounds()
    if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)):
        return lo, hi
    return None


def box_gap(lo, hi, box_lo, box_hi):
    """Euclidean distance between the boxes ``[lo, hi]`` (``mi.Point3f``, per lane) and
    ``[box_lo, box_hi]`` (three ``mi.Float`` each): 0 where they touch."""
    return dr.norm(mi.Vector3f(*(dr.maximum(dr.maximum(box_lo[i] - hi[i], lo[i] - box_hi[i]), 0.0)
                                 for i in range(3))))


def box_reach(lo, hi, box_lo, box_hi):
    """Largest distance from a point of the boxes ``[lo, hi]`` (``mi.Point3f``, per lane)
    to the box ``[box_lo, box_hi]`` (three ``mi.Float``): the distance to a box is
    convex, so it is the largest over the eight corners."""
    far = mi.Float(0.0)
    for x in (lo.x, hi.x):
        for y in (lo.y, hi.y):
            for z in (lo.z, hi.z):
                far = dr.maximum(far, box_distance(mi.Point3f(x, y, z), box_lo, box_hi))
    return far


def box_union(boxes):
    """Smallest box containing all ``(lo, hi)`` boxes."""
    los, his = zip(*boxes)
    return np.min(los, axis=0), np.max(his, axis=0)


def box_intersection(boxes):
    """Intersection of ``(lo, hi)`` boxes (may be empty: lo > hi)."""
    los, his = zip(*boxes)
    return np.max(los, axis=0), np.min(his, axis=0)


def evaluate(node: Node, points: np.ndarray, batch: int = 1 << 20) -> np.ndarray:
    """Evaluate a field on numpy points (the generators' entry point).

    Parameters
    ----------
    node : Node
        Root of the construction tree.
    points : numpy.ndarray
        ``(N, 3)`` array of positions.
    batch : int
        Points per Dr.Jit launch; bounds the memory of one evaluation.

    Returns
    -------
    numpy.ndarray
        ``(N,)`` float32 field values.
    """
    variant()
    pts = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    out = np.empty(len(pts), dtype=np.float32)
    for s in range(0, len(pts), batch):
        chunk = pts[s:s + batch]
        v = node.eval(jit_points(chunk))
        dr.eval(v)
        out[s:s + len(chunk)] = v.numpy()
    return out


def gradient(node: Node, p, h: float | None = None, culled: bool = False, footprint=None):
    """Field gradient at ``p`` by the tetrahedron technique (four evaluations).

    Central differences with 4 taps along the vertices of a tetrahedron
    ``k_i in {(1,-1,-1), (-1,-1,1), (-1,1,-1), (1,1,1)}``:
    ``grad f ~= sum_i k_i f(p + h k_i) / (4 h)``.

    Parameters
    ----------
    node : Node
        The field.
    p : mi.Point3f
        Points (typically surface hits).
    h : float or mi.Float
        Step; default 1e-3 m.
    culled : bool
        Evaluate through ``eval_bounds`` so that culled subtrees are skipped (the
        values agree near surfaces, see :mod:`arches_render.field.culling`).
    footprint : Footprint, optional
        The gradient of the footprint field (through ``eval_bounds``), as the tracer
        that found the hit saw it.

    Returns
    -------
    mi.Vector3f
        Unnormalized gradient (points *into* matter, since f > 0 inside).
    """
    h = 1e-3 if h is None else h
    g = mi.Vector3f(0.0)
    for k in ((1, -1, -1), (-1, -1, 1), (-1, 1, -1), (1, 1, 1)):
        kv = mi.Vector3f(*k)
        q = p + kv * h
        through = culled or footprint is not None
        g += kv * (node.eval_bounds(q, (), footprint=footprint)[0] if through else node.eval(q))
    return g / (4.0 * h)
