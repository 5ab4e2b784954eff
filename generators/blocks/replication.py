"""Selective replication of a block tile over a host field (Paris et al. 2020, section 5).

The amplified terrain is ``f~ = max(f, t)`` (union of the host ``f`` and the
replicated blocks ``t``, :class:`~.block_field.BlockField`) with

    t(p) = max_i b_i(p mod s) e_i(a_i + s floor(p / s)).

The presence ``e_i`` of block ``i`` in the virtual cell ``T`` is decided on its
anchors ``a_ik + s T`` (:func:`~.block_hulls.block_anchors`): the block is
replicated when more than half of them (``#A / 2``) satisfy every criterion:

* distance range: ``f(a) in [v_a, v_b]`` (``distance_range``; ``f`` is the host's
  field, ``> 0`` inside, so ``v_a < 0`` reaches into the air);
* slope: ``|g(a') . u_z| < epsilon`` with ``g`` the host's normalized gradient;
  the scene key is the angle ``min_slope`` (degrees), ``epsilon = cos(min_slope)``
  (only steep walls get blocks; 0 disables the test). ``a'`` is the anchor moved
  onto the host surface by three Newton steps ``a <- a - f g / |g|^2``: the paper
  takes ``g(a)``, but inside a solid the gradient points to the nearest face,
  which for an anchor low in a wall is the ground or the top, not the wall;
* geology: the host's resistance ``gamma(a)`` (any node of the language, or a
  constant) in ``resistance_range``: the block's material lies in that stratum.

Resting (an addition, for blocks fallen on the ground): with ``contact = c``, at
least :data:`CONTACTS` anchors must also lie within ``c`` of the host or inside it
(``f(a) >= -c``), as a block resting on three points does. The majority rule alone
keeps a block whose centroid and lower anchors are in the distance range while it
hovers over a hollow: fallen blocks 5.5 m across floated up to 1.7 m above the
ground at the foot of a mesa (``distance_range = [-0.8 b, 0.15 b]``).

Since ``e_i`` depends on ``p`` only through ``floor(p / s)``, it is evaluated once
per virtual cell of the region and stored as a table, which the field looks up.
The host gradient is a central difference of step ``h = 5 cm``.

Protrusion (an addition): tall blocks (columns) whose anchors sit on a wall also
stand above its top edge; ``protrusion = delta`` clips them to the host grown by
``delta``: ``f~ = max(f, min(t, f + delta))``, Lipschitz ``max(L_f, L_t)``.

References
----------
Paris et al. (2020), section 5 and Figure 11.
"""

from __future__ import annotations

import drjit as dr
import numpy as np

from arches_render.backend import variant
from arches_render.field import evaluate
from arches_render.field.node import Node, jit_points, opaque_float
from arches_render.field.operators import Intersection, Union

from .block_field import BlockField, PresentCopies

__all__ = ["presence_table", "replicate", "Offset", "CONTACTS"]

#: Anchors a resting block touches the host with (``contact``): a tripod.
CONTACTS = 3


def _values(node_or_value, pts):
    if node_or_value is None:
        return None
    if isinstance(node_or_value, (int, float)):
        return np.full(len(pts), float(node_or_value))
    return evaluate(node_or_value, pts).astype(np.float64)


def _gradient(host, pts, h):
    g = np.zeros((len(pts), 3))
    for a in range(3):
        e = np.zeros(3)
        e[a] = h
        g[:, a] = (_values(host, pts + e) - _values(host, pts - e)) / (2 * h)
    return g


#: Virtual cells a region may hold (the candidates are an int64 array of this many rows).
MAX_VIRTUAL_CELLS = 20_000_000
#: Block copies whose anchors are tested at once (the anchors of this many copies).
MAX_COPIES = 50_000_000
#: Candidate copies drawn at a time.
COPY_BATCH = 1 << 20


def _box_ranges(host, lo, hi, batch=1 << 18):
    """``(f_min, f_max)`` of the host over the boxes ``[lo, hi]`` (its ``box_range``:
    a rigorous enclosure from its local slope bounds), float64 numpy."""
    variant()
    f_min, f_max = np.empty(len(lo)), np.empty(len(lo))
    for k in range(0, len(lo), batch):
        a, b = host.box_range(jit_points(lo[k:k + batch]), jit_points(hi[k:k + batch]))
        dr.eval(a, b)
        m = len(lo[k:k + batch])
        f_min[k:k + m] = np.broadcast_to(np.asarray(a.numpy(), np.float64), (m,))
        f_max[k:k + m] = np.broadcast_to(np.asarray(b.numpy(), np.float64), (m,))
    return f_min, f_max


def _copy_uniform(T, b, seed):
    """A uniform draw in ``[0, 1)`` per copy ``(T, b)``: splitmix64's finalizer chained over
    the seed, the virtual cell's three indices and the block, vectorised, so that a
    copy's draw does not depend on which other copies a region holds.

    References
    ----------
    Steele, G., Lea, D., Flood, C. (2014). Fast splittable pseudorandom number
    generators. OOPSLA (the SplitMix64 finalizer).
    """
    x = np.full(len(b), np.uint64((int(seed) * 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF), dtype=np.uint64)
    with np.errstate(over="ignore"):
        for v in (T[:, 0], T[:, 1], T[:, 2], b):
            x = (x ^ np.asarray(v, np.int64).view(np.uint64)) * np.uint64(0xBF58476D1CE4E5B9)
            x ^= x >> np.uint64(31)
            x *= np.uint64(0x94D049BB133111EB)
            x ^= x >> np.uint64(29)
    return (x >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def _density_at(density, lo, hi, x, y):
    """Nearest-cell lookup of a ``(ny, nx)`` grid spanning the region's ``x, y`` (row 0 at
    ``y0``); 0 outside it."""
    ny, nx = density.shape
    i = np.floor((x - lo[0]) / (hi[0] - lo[0]) * nx).astype(np.int64)
    j = np.floor((y - lo[1]) / (hi[1] - lo[1]) * ny).astype(np.int64)
    inside = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
    out = np.zeros(len(x))
    out[inside] = density[j[inside], i[inside]]
    return out


def _density_columns(density, lo, hi, T, c_lo, c_hi, s):
    """Whether any copy of the virtual cells ``T`` can have its centroid on a positive
    density cell: the cells' centroid boxes ``T s + [c_lo, c_hi]`` against a summed-area
    table of ``density > 0`` (exact, conservative by one cell)."""
    ny, nx = density.shape
    sat = np.zeros((ny + 1, nx + 1), dtype=np.int64)
    sat[1:, 1:] = np.cumsum(np.cumsum(density > 0, axis=0), axis=1)
    gx, gy = (hi[0] - lo[0]) / nx, (hi[1] - lo[1]) / ny
    i0 = np.clip(np.floor((T[:, 0] * s + c_lo[0] - lo[0]) / gx).astype(np.int64) - 1, 0, nx)
    i1 = np.clip(np.floor((T[:, 0] * s + c_hi[0] - lo[0]) / gx).astype(np.int64) + 2, 0, nx)
    j0 = np.clip(np.floor((T[:, 1] * s + c_lo[1] - lo[1]) / gy).astype(np.int64) - 1, 0, ny)
    j1 = np.clip(np.floor((T[:, 1] * s + c_hi[1] - lo[1]) / gy).astype(np.int64) + 2, 0, ny)
    return (sat[j1, i1] - sat[j0, i1] - sat[j1, i0] + sat[j0, i0]) > 0


def presence_table(tile, host, region_lo, region_hi, distance_range=(-1.0, 1.0), min_slope=60.0,
                   resistance=None, resistance_range=(-np.inf, np.inf), h=0.05, max_slope=90.0,
                   density=None, seed=0, contact=None):
    """Presence ``e_i`` of every block in every virtual cell meeting a region.

    A copy is present when its centroid lies in the region, more than half of its
    anchors meet the distance, slope and resistance criteria, and (with a ``density``)
    a uniform draw of the copy falls below the density at its centroid.

    Which copies are tested is pruned without changing the answer: a group of blocks
    whose anchors' box has, in a virtual cell, a host range
    (:meth:`~arches_render.field.node.Node.box_range`) outside ``[v_a, v_b]`` has no
    anchor in the distance range there; with a density, cells whose
    centroids all fall on zero density, and then copies whose draw fails, are dropped
    before any anchor is evaluated. A region along the foot of every cliff of a
    terrain is so decided in seconds.

    Parameters
    ----------
    tile : BlockTile
        The blocks (with their anchors).
    host : Node
        Host field ``f`` (``> 0`` inside).
    region_lo, region_hi : array_like
        World box holding the centroids of the replicated copies.
    distance_range : (float, float)
        ``[v_a, v_b]`` for ``f(a)``.
    min_slope : float
        Degrees; anchors need ``|g . u_z| < cos(min_slope)`` (0: no test): steep walls.
    resistance : Node or float, optional
        Geology resistance ``gamma`` of the host.
    resistance_range : (float, float)
        Accepted ``gamma(a)``.
    h : float
        Finite-difference step of the gradient (m).
    max_slope : float
        Degrees; anchors need ``-g . u_z >= cos(max_slope)`` (90: no test): ground facing
        up, on which a fallen block can rest (an addition to the paper's criteria).
    density : numpy.ndarray, optional
        ``(ny, nx)`` probabilities in ``[0, 1]`` over the region's ``x, y`` (row 0 at
        ``y0``, nearest cell): the chance that a copy centred there is kept (an
        addition: scattered fallen blocks rather than a continuous layer).
    seed : int
        Seed of the copies' draws.
    contact : float, optional
        Metres: at least :data:`CONTACTS` anchors need ``f(a) >= -contact`` (the block
        rests on the host; an addition, module docstring); ``None``: no test.

    Returns
    -------
    PresentCopies
        The present copies, with the region's virtual cells.

    References
    ----------
    Paris et al. (2020), section 5.
    """
    lo, hi = np.asarray(region_lo, float), np.asarray(region_hi, float)
    if not np.all(hi > lo):
        raise ValueError("region must satisfy hi > lo on every axis")
    va, vb = (float(v) for v in distance_range)
    if not va <= vb:
        raise ValueError(f"distance_range must be [v_a, v_b] with v_a <= v_b (got {[va, vb]})")
    if contact is not None and not contact >= 0:
        raise ValueError(f"contact must be >= 0 (got {contact})")
    if not 0.0 <= min_slope <= max_slope <= 90.0:
        raise ValueError(f"slopes must satisfy 0 <= min_slope <= max_slope <= 90 (got {min_slope}, {max_slope})")
    if density is not None:
        density = np.asarray(density, dtype=np.float64)
        if density.ndim != 2 or density.size == 0 or not np.all((density >= 0) & (density <= 1)):
            raise ValueError("density must be a non-empty 2-D grid of probabilities in [0, 1]")
    s, B = tile.size, tile.n_blocks
    t_lo = np.floor(lo / s).astype(np.int64)
    t_hi = np.floor(hi / s).astype(np.int64)
    nt = t_hi - t_lo + 1
    if np.prod(nt) > MAX_VIRTUAL_CELLS:
        raise ValueError(f"region too large for this tile size (more than {MAX_VIRTUAL_CELLS:.0e} virtual cells)")
    # Columns first: a density leaves most of a terrain-wide region's columns empty.
    cols = np.stack(np.meshgrid(np.arange(t_lo[0], t_hi[0] + 1), np.arange(t_lo[1], t_hi[1] + 1), [0],
                                indexing="ij"), -1).reshape(-1, 3)
    if density is not None:
        cols = cols[_density_columns(density, lo, hi, cols, tile.centroid.min(0), tile.centroid.max(0), s)]
    T = np.repeat(cols, nt[2], axis=0)
    T[:, 2] = np.tile(np.arange(t_lo[2], t_hi[2] + 1), len(cols))
    # The tile's blocks in eight groups (by their centroid's octant of the tile), each
    # with the box of its anchors: a group whose box's host range misses [v_a, v_b]
    # in a cell has no anchor in range there (a box four times smaller than the whole
    # tile's keeps a third of the copies: the ground's band is thin).
    anchors = tile.anchors.astype(np.float64)
    group = ((tile.centroid >= s / 2).astype(np.int64) * [1, 2, 4]).sum(1)
    g_lo = np.array([anchors[group == g].reshape(-1, 3).min(0) if np.any(group == g) else np.zeros(3)
                     for g in range(8)])
    g_hi = np.array([anchors[group == g].reshape(-1, 3).max(0) if np.any(group == g) else -np.ones(3)
                     for g in range(8)])
    live = np.zeros((len(T), 8), dtype=bool)
    if len(T):
        corner = np.repeat(T * s, 8, axis=0)
        f_min, f_max = _box_ranges(host, corner + np.tile(g_lo, (len(T), 1)), corner + np.tile(g_hi, (len(T), 1)))
        slack = 1e-3 * (1.0 + np.maximum(np.abs(f_min), np.abs(f_max)))  # float32 rounding
        live = ((f_min - slack <= vb) & (f_max + slack >= va)).reshape(len(T), 8)
        live[:, ~np.isin(np.arange(8), group)] = False
        T, live = T[live.any(1)], live[live.any(1)]
    if len(T) * B > MAX_COPIES:
        raise ValueError(f"region too large for this tile size (more than {MAX_COPIES:.0e} block copies)")
    # The copies of a few thousand cells at a time (memory: a terrain's apron holds
    # millions of candidate copies, of which the draws keep a few per cent).
    cells, blocks = [], []
    step = max(1, COPY_BATCH // B)
    for k in range(0, len(T), step):
        Tk = T[k:k + step]
        cell = np.repeat(np.arange(k, k + len(Tk)), B)
        b = np.tile(np.arange(B), len(Tk))
        kept = live[cell, group[b]]
        cell, b = cell[kept], b[kept]
        c = tile.centroid[b].astype(np.float64) + s * T[cell]
        # The region selects copies by their centroid (anchor 0).
        keep = np.flatnonzero(np.all((c >= lo) & (c <= hi), axis=-1))
        if density is not None:
            p = _density_at(density, lo, hi, c[keep, 0], c[keep, 1])
            keep, p = keep[p > 0], p[p > 0]
            keep = keep[_copy_uniform(T[cell[keep]], b[keep], seed) < p]
        cells.append(cell[keep])
        blocks.append(b[keep])
    cell = np.concatenate(cells) if cells else np.zeros(0, np.int64)
    b = np.concatenate(blocks) if blocks else np.zeros(0, np.int64)
    K = tile.anchors.shape[1]
    A = tile.anchors[b].astype(np.float64) + s * T[cell][:, None, :]  # (n, K, 3)
    pts = A.reshape(-1, 3)
    f = _values(host, pts)
    ok = (f >= va) & (f <= vb)
    if contact is not None:
        # Before the slope test: its gradients are the costly part, and a copy that
        # does not rest on the host fails anyway.
        ok &= np.repeat((f >= -contact).reshape(len(b), K).sum(-1) >= CONTACTS, K)
    if min_slope > 0 or max_slope < 90:
        sel = np.nonzero(ok)[0]
        # The slope of the host *surface* near the anchor: the gradient deep inside
        # a solid points to whichever face is nearest (the top of a box, for an
        # anchor low in a wall), so the anchor is first projected on the surface.
        q = pts[sel].copy()
        fq = f[sel]
        for _ in range(3):
            g = _gradient(host, q, h)
            g2 = np.maximum((g * g).sum(1), 1e-12)
            q -= (fq / g2)[:, None] * g
            fq = _values(host, q)
        g = _gradient(host, q, h)
        norm = np.linalg.norm(g, axis=1)
        good = norm > 0
        if min_slope > 0:
            good &= np.abs(g[:, 2]) < np.cos(np.radians(min_slope)) * np.maximum(norm, 1e-12)
        if max_slope < 90:
            # Ground faces up (outward normal -g, f > 0 inside): an overhang's flat
            # underside holds no block.
            good &= -g[:, 2] >= np.cos(np.radians(max_slope)) * norm
        ok[sel] &= good
    if resistance is not None:
        rl, rh = (float(v) for v in resistance_range)
        gam = _values(resistance, pts)
        ok &= (gam >= rl) & (gam <= rh)
    present = ok.reshape(len(b), K).sum(-1) > K / 2
    return PresentCopies(cells=T[cell[present]], blocks=b[present], tiles_lo=t_lo, shape=(*nt, B))


class Offset(Node):
    """``f + delta``: the host grown by ``delta`` (a clip for protruding blocks)."""

    kind = "offset"
    unit_falloff = False

    def __init__(self, child, delta):
        self.children = (child,)
        self.delta_np = float(delta)
        self.delta = opaque_float(delta)

    def eval(self, p):
        return self.children[0].eval(p) + self.delta

    def box_range(self, lo, hi):
        a, b = self.children[0].box_range(lo, hi)
        return a + self.delta, b + self.delta

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        # {f + delta >= -c} = {f >= -c - delta}
        f, ds = self.children[0].eval_bounds(p, tuple(c + self.delta_np for c in levels), direction, footprint)
        return f + self.delta, ds

    def bounds(self):
        # Only used as a clip (an intersection operand): the other operand's box is tighter.
        return np.full(3, -np.inf), np.full(3, np.inf)

    @property
    def lipschitz(self):
        return self.children[0].lipschitz


def replicate(host, tile, region_lo, region_hi, distance_range=(-1.0, 1.0), min_slope=60.0,
              resistance=None, resistance_range=(-np.inf, np.inf), protrusion=None, max_slope=90.0,
              density=None, contact=None, **field_args):
    """The amplified field ``f~ = max(f, t)``: blocks replicated over a host.

    Parameters
    ----------
    host : Node
        Host field.
    tile : BlockTile
        Block tile.
    region_lo, region_hi, distance_range, min_slope, resistance, resistance_range, max_slope, density, contact
        Presence criteria, see :func:`presence_table` (the draws use ``field_args``'
        ``seed``).
    protrusion : float, optional
        Clip the blocks to ``{f >= -protrusion}`` (``max(f, min(t, f + delta))``): blocks
        stand out of the host by at most that much (none: the paper's ``max(f, t)``).
    **field_args
        ``smoothness``, ``warp``, ``warp_wavelength``, ``warp_octaves``, ``seed``,
        ``margin``, ``cell_size`` of :class:`~.block_field.BlockField`.

    Returns
    -------
    Node
        ``Union(host, blocks)``; the blocks node is its second child.

    References
    ----------
    Paris et al. (2020), section 5: ``f~ = max(f, t)``.
    """
    presence = presence_table(tile, host, region_lo, region_hi, distance_range, min_slope,
                              resistance, resistance_range, max_slope=max_slope, density=density,
                              seed=field_args.get("seed", 0), contact=contact)
    blocks = BlockField(tile, presence=presence, **field_args)
    if protrusion is not None:
        if not protrusion >= 0:
            raise ValueError(f"protrusion must be >= 0 (got {protrusion})")
        return Union(host, Intersection(blocks, Offset(host, protrusion)))
    return Union(host, blocks)
