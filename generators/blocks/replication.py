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

import numpy as np

from arches_render.field import evaluate
from arches_render.field.node import Node, opaque_float
from arches_render.field.operators import Intersection, Union

from .block_field import BlockField

__all__ = ["presence_table", "replicate", "Offset"]


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


def presence_table(tile, host, region_lo, region_hi, distance_range=(-1.0, 1.0), min_slope=60.0,
                   resistance=None, resistance_range=(-np.inf, np.inf), h=0.05):
    """Presence ``e_i`` of every block in every virtual cell meeting a region.

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
        Degrees; anchors need ``|g . u_z| < cos(min_slope)`` (0: no test).
    resistance : Node or float, optional
        Geology resistance ``gamma`` of the host.
    resistance_range : (float, float)
        Accepted ``gamma(a)``.
    h : float
        Finite-difference step of the gradient (m).

    Returns
    -------
    presence : numpy.ndarray
        ``(nx, ny, nz, B)`` booleans.
    tiles_lo : numpy.ndarray
        Integer index of the first virtual cell.

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
    s = tile.size
    t_lo = np.floor(lo / s).astype(int)
    t_hi = np.floor(hi / s).astype(int)
    nt = t_hi - t_lo + 1
    if np.prod(nt) * tile.n_blocks > 50_000_000:
        raise ValueError("region too large for this tile size (more than 5e7 block copies)")
    T = np.stack(np.meshgrid(*[np.arange(t_lo[a], t_hi[a] + 1) for a in range(3)], indexing="ij"),
                 -1).reshape(-1, 3)
    K = tile.anchors.shape[1]
    A = tile.anchors[None].astype(np.float64) + s * T[:, None, None, :]  # (nT, B, K, 3)
    pts = A.reshape(-1, 3)
    f = _values(host, pts)
    ok = (f >= va) & (f <= vb)
    if min_slope > 0:
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
        steep = np.abs(g[:, 2]) < np.cos(np.radians(min_slope)) * np.maximum(norm, 1e-12)
        ok[sel] &= steep & (norm > 0)
    if resistance is not None:
        rl, rh = (float(v) for v in resistance_range)
        gam = _values(resistance, pts)
        ok &= (gam >= rl) & (gam <= rh)
    present = ok.reshape(len(T), tile.n_blocks, K).sum(-1) > K / 2
    # The region selects copies by their centroid (anchor 0).
    c = A[:, :, 0]
    present &= np.all((c >= lo) & (c <= hi), axis=-1)
    return present.reshape(*nt, tile.n_blocks), t_lo


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
              resistance=None, resistance_range=(-np.inf, np.inf), protrusion=None, **field_args):
    """The amplified field ``f~ = max(f, t)``: blocks replicated over a host.

    Parameters
    ----------
    host : Node
        Host field.
    tile : BlockTile
        Block tile.
    region_lo, region_hi, distance_range, min_slope, resistance, resistance_range
        Presence criteria, see :func:`presence_table`.
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
    presence, t_lo = presence_table(tile, host, region_lo, region_hi, distance_range, min_slope,
                                    resistance, resistance_range)
    blocks = BlockField(tile, presence=presence, tiles_lo=t_lo, **field_args)
    if protrusion is not None:
        if not protrusion >= 0:
            raise ValueError(f"protrusion must be >= 0 (got {protrusion})")
        return Union(host, Intersection(blocks, Offset(host, protrusion)))
    return Union(host, blocks)
