"""Surface cells: where a field's surface may lie, and the empty space a ray may skip.

A sparse hierarchical grid over a field's box (a Lipschitz octree, stored as a
brick grid) classifies each leaf cell ``C`` of edge ``h`` (centre ``c``, half-diagonal
``R = sqrt(3) h / 2``):

*air* for footprint class ``k``
    no point of ``C`` is in the solid of any footprint field whose footprint radius
    is at most ``rho_k``, nor within a tracer's hit tolerance of it (a slack added
    to ``E_k``: a tracer finds the same hits with the cells as without). The footprint field ``F_fp`` differs from the full field
    ``F`` by at most ``E_k`` there (:meth:`Node.local_lod_error
    <arches_render.field.node.Node.local_lod_error>`), so ``F_fp >= 0`` needs
    ``F >= -E_k``, and the node's own distance bound ``d(c)`` to ``{F >= -E_k}``
    (``eval_bounds``) proves the cell free when ``d(c) > R``: every point of ``C`` is
    within ``R`` of ``c``. (The bound is asked at the smallest level of a fixed
    ladder at or above ``E_k``: ``d`` only grows as the level falls.) Or the upper
    end of ``F``'s value range over ``C`` (:meth:`Node.box_range
    <arches_render.field.node.Node.box_range>`, interval arithmetic through the
    tree: tight over a heightfield, whose maximum mipmap bounds it) is below ``-E_k``.
*solid* for class ``k``
    ``F - S R > E_k`` at ``c``, with ``S`` the node's slope bound in the ball of radius
    ``R`` (:func:`~arches_render.field.local_slopes.eval_local`), or the lower end of
    the value range over ``C`` above ``E_k``: matter throughout for every footprint
    of the class. It stops refining (memory follows the surface, not the rock
    below it), and a shadow ray any of whose points is in such a cell is occluded.
*candidate*
    neither: the surface may cross ``C``; a tracer evaluates the field there.

A cell is refined (into its eight children) only while it is neither air for
every class nor solid, from a coarse top level down to the leaves, so the
evaluations follow the surface: about eight per candidate leaf.

For each class ``k`` and each leaf that is air for it, the chessboard distance
transform ``D_k`` (in leaves, at most 255) to the nearest leaf that is not gives a
cube of ``(2 D_k - 1)^3`` leaves, all air: a ray may jump to where it leaves that
cube. Bricks of ``8^3`` leaves that are uniformly air (or solid) are not stored
(:class:`~arches_render.field.brick_grid.BrickLayout`); an air brick keeps the same
distance at brick scale.

Each leaf is one 32-bit word: the number of classes it is air for (bits 0-3), solid
for (bits 4-7), and ``D_1 .. D_3`` (bits 8-31), so a lookup is two gathers (brick
slot, word).

References
----------
Barbier, W., Sanchez, M., Paris, A., Michel, É., Lambert, T., Boubekeur, T., Paulin,
M., Thonat, T. (2025). Lipschitz pruning: hierarchical simplification of
primitive-based SDFs. Computer Graphics Forum 44(2) (cells refined while
``|f(c)| <= L R``).
Museth, K. (2013). VDB: High-resolution sparse volumes with dynamic topology. ACM
TOG 32(3) (bricks of 8^3 leaves).
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
"""

from __future__ import annotations

import math
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from ..backend import variant
from .brick_grid import BRICK, NO_SLOT, BrickLayout
from .local_slopes import eval_local
from .node import cell_index, jit_points, opaque_float

__all__ = ["SurfaceCells", "FOOTPRINT_CLASSES", "LEVEL_LADDER"]

#: Footprint radii of the classes, in leaf edges: camera and shadow rays, then wide
#: bounce cones (a ray whose footprint exceeds the last class evaluates the field).
FOOTPRINT_CLASSES = (0.25, 4.0)
#: Levels at which the distance bounds are asked (metres of field value).
LEVEL_LADDER = (0.0, 0.01, 0.04, 0.15, 0.6, 2.5, 10.0, 40.0)
#: Cells of the top level of the refinement, at most.
TOP_CELLS = 4096
#: Points a Dr.Jit launch classifies, at most (bounds the memory of one launch).
BATCH = 1 << 20
#: A leaf's word: air classes in bits 0-3, solid ones in 4-7, D_k in the next bytes.
MAX_CLASSES = 3
#: Brick codes of the top grid (below the stored slots).
AIR_BRICK, ROCK_BRICK = np.uint32(0xFFFFFFFF), np.uint32(0xFFFFFFFE)


def _ladder_index(err):
    """Index in :data:`LEVEL_LADDER` of the smallest level at or above ``err`` (numpy),
    ``len`` where none is."""
    return np.searchsorted(np.asarray(LEVEL_LADDER), np.asarray(err, dtype=np.float64), side="left")


def classify(root, centres, edge, radii, slack=0.0):
    """Air classes and solidity of the cubic cells of edge ``edge`` around ``centres``
    (module docstring): a cell is proven air by the value range over it
    (:meth:`Node.box_range <arches_render.field.node.Node.box_range>`) or by the
    distance bound at its centre, solid by either too.

    Parameters
    ----------
    root : Node
        The field.
    centres : numpy.ndarray
        ``(N, 3)`` cell centres.
    edge : float
        The cells' edge.
    radii : sequence of float
        The classes' footprint radii (metres), increasing.
    slack : float
        Added to every class's error: a tracer's largest hit tolerance, so that a
        point it would count as a hit (``F > -tol``) never lies in an air cell.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        ``air`` and ``solid`` (uint8 each: the number of leading classes the cell is
        air, or solid, for).
    """
    variant()
    n = len(centres)
    air = np.zeros(n, dtype=np.uint8)
    solid = np.zeros(n, dtype=np.uint8)
    R = 0.5 * math.sqrt(3.0) * float(edge)
    half = 0.5 * float(edge)

    def lanes(x, m):
        return np.broadcast_to(x.numpy() if not isinstance(x, (int, float)) else np.float32(x), (m,)).astype(np.float64)

    for s in range(0, n, BATCH):
        c = np.ascontiguousarray(centres[s:s + BATCH], dtype=np.float32)
        m = len(c)
        p = jit_points(c)
        f, ds, (slope,) = eval_local(root, p, LEVEL_LADDER, None, None, (R,))
        f_min, f_max = root.box_range(p - half, p + half)
        errors = [root.local_lod_error(p, R, rho) + slack for rho in radii]
        dr.eval(f, ds, slope, f_min, f_max, *[e for e in errors if not isinstance(e, (int, float))])
        f, slope, f_min, f_max = (lanes(x, m) for x in (f, slope, f_min, f_max))
        d = np.stack([lanes(x, m) for x in ds])  # (levels, points)
        low = np.maximum(f - slope * R, f_min)
        count, rock = np.zeros(m, dtype=np.uint8), np.zeros(m, dtype=np.uint8)
        free_so_far, rock_so_far = np.ones(m, dtype=bool), np.ones(m, dtype=bool)
        for e in errors:
            e = lanes(e, m)
            j = _ladder_index(e)
            ok = j < len(LEVEL_LADDER)
            free = f_max < -e
            free[ok] |= d[j[ok], np.flatnonzero(ok)] > R
            free_so_far &= free
            count += free_so_far
            # Matter for every footprint of the class (no slack: a hit is a hit).
            rock_so_far &= low > e - slack
            rock += rock_so_far
        air[s:s + m], solid[s:s + m] = count, rock
    return air, solid


def _chessboard(air):
    """Per ``True`` voxel of ``air``, the chessboard distance to the nearest ``False`` one
    (outside the array counts as air), capped at 255; 0 elsewhere."""
    from scipy.ndimage import distance_transform_cdt  # on use: keeps `import arches_render.field` light
    if air.all():
        return np.full(air.shape, 255, dtype=np.uint8)
    padded = np.pad(air, 1, constant_values=True)
    d = distance_transform_cdt(padded, metric="chessboard")[1:-1, 1:-1, 1:-1]
    return np.minimum(d, 255).astype(np.uint8)


class SurfaceCells:
    """The surface cells of a field over a box (module docstring).

    Parameters
    ----------
    root : Node
        The field (the tree a tracer evaluates).
    lo, hi : array_like
        The box to cover (outside it the tracer proves rays free by itself).
    leaf : float
        Leaf edge in metres.
    classes : sequence of float, optional
        Footprint radii of the classes in leaf edges (:data:`FOOTPRINT_CLASSES`).
    slack : float, optional
        Field value added to every class's error (a tracer's largest hit tolerance).
    keep_not_air : bool, optional
        Keep the dense mask of the leaves that are not air (``not_air``; a byte a leaf).

    Attributes
    ----------
    radii : tuple of float
        The classes' footprint radii in metres.
    stats : dict
        Build seconds, leaves by kind, evaluations, bytes.
    """

    def __init__(self, root, lo, hi, leaf, classes=FOOTPRINT_CLASSES, slack=0.0, keep_not_air=False):
        if not 1 <= len(classes) <= MAX_CLASSES:
            raise ValueError(f"1 to {MAX_CLASSES} footprint classes (got {len(classes)})")
        t0 = time.perf_counter()
        self.leaf = float(leaf)
        self.slack = float(slack)
        self.radii = tuple(float(c) * self.leaf for c in classes)
        self.grid_lo = np.asarray(lo, dtype=np.float64)
        self.res = np.maximum(np.ceil((np.asarray(hi, np.float64) - self.grid_lo) / self.leaf), 1).astype(np.int64)
        air, solid, evaluations = self._refine(root)
        K = len(self.radii)
        #: With ``keep_not_air``, the leaves that are not air for every class ((z, y, x)
        #: booleans, dense): where a surface may be (a cover's voxels); else None.
        self.not_air = air < K if keep_not_air else None
        words = air.astype(np.uint32) | (solid.astype(np.uint32) << np.uint32(4))
        for k in range(1, K + 1):
            words |= _chessboard(air >= k).astype(np.uint32) << np.uint32(8 * k)
        # Bricks: stored unless uniformly air for every class, or uniformly solid.
        uniform_air = BrickLayout._bricked(air >= K, self.res, True).all(axis=(1, 2, 3))
        uniform_rock = BrickLayout._bricked(solid >= K, self.res, False).all(axis=(1, 2, 3))
        keep = ~(uniform_air | uniform_rock)
        bz, by, bx = (int(v) for v in (-(-self.res[::-1] // BRICK)))
        slots = np.full(len(keep), AIR_BRICK, dtype=np.uint32)
        slots[uniform_rock & ~uniform_air] = ROCK_BRICK
        slots[keep] = np.arange(int(keep.sum()), dtype=np.uint32)
        brick_words = np.zeros(len(keep), dtype=np.uint32)
        brick_words[uniform_air] = K
        brick_words[uniform_rock & ~uniform_air] = K << 4
        for k in range(1, K + 1):
            brick_words |= _chessboard(uniform_air.reshape(bz, by, bx)).reshape(-1).astype(np.uint32) \
                << np.uint32(8 * k)
        self.layout = BrickLayout(np.where(keep, slots, NO_SLOT), self.grid_lo, self.leaf, self.res)
        self._slots = mi.UInt32(slots)
        self._words = mi.UInt32(self.layout.compact(words))
        self._brick_words = mi.UInt32(brick_words)
        self._leaf = opaque_float(self.leaf)
        self._brick = opaque_float(self.leaf * BRICK)
        self._lo = [opaque_float(v) for v in self.grid_lo]
        self._radii = [opaque_float(r) for r in self.radii]
        n = int(air.size)
        self.stats = dict(build_s=time.perf_counter() - t0, leaf=self.leaf, leaves=n,
                          candidate=int(np.count_nonzero((air == 0) & (solid == 0))),
                          air=[int(np.count_nonzero(air >= k)) for k in range(1, K + 1)],
                          solid=[int(np.count_nonzero(solid >= k)) for k in range(1, K + 1)],
                          evaluations=int(evaluations),
                          stored_bricks=int(keep.sum()), bytes=self.nbytes())

    # -- build -------------------------------------------------------------------------
    def _refine(self, root):
        """Dense leaf arrays ``(air, solid)`` in ``(z, y, x)`` order, refined top-down."""
        res = self.res
        K = len(self.radii)
        top = 0
        while int(np.prod(-(-res // (1 << top)))) > TOP_CELLS:
            top += 1
        evaluations = 0
        air = solid = None
        for level in range(top, -1, -1):
            size = self.leaf * (1 << level)
            shape = tuple(int(v) for v in -(-res[::-1] // (1 << level)))  # (z, y, x)
            if air is None:
                todo = np.ones(shape, dtype=bool)
                air, solid = np.zeros(shape, dtype=np.uint8), np.zeros(shape, dtype=np.uint8)
            else:
                # Children of the cells still undecided; the others inherit.
                up = lambda a: np.repeat(np.repeat(np.repeat(a, 2, 0), 2, 1), 2, 2)[  # noqa: E731
                    :shape[0], :shape[1], :shape[2]]
                todo = up((air < K) & (solid < K))
                air, solid = up(air), up(solid)
            idx = np.argwhere(todo)  # (z, y, x)
            if len(idx):
                centres = self.grid_lo + (idx[:, ::-1] + 0.5) * size
                a, s = classify(root, centres, size, self.radii, self.slack)
                air[todo], solid[todo] = a, s
                evaluations += len(idx)
        return air, solid, evaluations

    # -- queries -----------------------------------------------------------------------
    def lookup(self, p):
        """``(air, solid, reach, lo, hi)`` of the points ``p``: the classes their leaf (or
        unstored brick) is air, and solid, for, and the empty cube around it per class: ``reach``
        is a list of ``D_k`` (``mi.UInt32``) and ``lo``, ``hi`` that leaf's (or brick's)
        box, so the cube of class ``k`` is the box grown by ``(D_k - 1)`` of its
        edges. Points outside the grid read a solid-free, air-free cell (0 classes)."""
        rx, ry, rz = (int(v) for v in self.res)
        f = [(p[i] - self._lo[i]) * dr.rcp(self._leaf) for i in range(3)]
        inside = (f[0] >= 0.0) & (f[1] >= 0.0) & (f[2] >= 0.0) & (f[0] < rx) & (f[1] < ry) & (f[2] < rz)
        ix, iy, iz = (cell_index(v, n) for v, n in zip(f, (rx, ry, rz)))
        bx, by = int(self.layout.bricks[0]), int(self.layout.bricks[1])
        brick = ((iz >> 3) * by + (iy >> 3)) * bx + (ix >> 3)
        slot = dr.gather(mi.UInt32, self._slots, brick, inside)
        stored = inside & (slot < int(ROCK_BRICK))
        leaf_index = slot * (BRICK ** 3) + (((iz & 7) << 6) | ((iy & 7) << 3) | (ix & 7))
        word = dr.select(stored, dr.gather(mi.UInt32, self._words, leaf_index, stored),
                         dr.gather(mi.UInt32, self._brick_words, brick, inside & ~stored))
        word = dr.select(inside, word, 0)
        air, solid = word & 0xF, (word >> 4) & 0xF
        reach = [(word >> (8 * k)) & 0xFF for k in range(1, len(self.radii) + 1)]
        edge = dr.select(stored, self._leaf, self._brick)
        cx = dr.select(stored, mi.Float(ix), mi.Float(ix >> 3) * BRICK)
        cy = dr.select(stored, mi.Float(iy), mi.Float(iy >> 3) * BRICK)
        cz = dr.select(stored, mi.Float(iz), mi.Float(iz >> 3) * BRICK)
        lo = mi.Point3f(self._lo[0] + cx * self._leaf, self._lo[1] + cy * self._leaf, self._lo[2] + cz * self._leaf)
        return air, solid, reach, lo, lo + edge

    def nbytes(self) -> int:
        """Bytes of the structure's arrays (top grid slots and words, leaf words)."""
        return len(self.layout.slots_np) * 8 + self.layout.stored_cells * 4
