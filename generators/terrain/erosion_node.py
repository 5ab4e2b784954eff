"""The erosion node ``f~ = f - f_D (1 - rho)`` (Paris et al. 2019, Sec. 6).

A sub-tree ``f`` loses material where the erosion field ``f_D`` (the compactly
supported field of a :class:`~.skeletal_set.SkeletalSet` of non-negative energies,
or any node whose positive part is the erosion intensity) is strong and the
bedrock resistance ``rho`` (a :mod:`.geology` tree, clamped to ``[0, 1]``) is weak.
One node carries strata detail finer than its primitives: hard layers
(``rho ~ 1``) resist while soft ones (``rho ~ 0``) are cut back by ``f_D``.

We use ``D = max(f_D, 0)`` so the node only removes matter even if the control
field dips below zero. Then:

* ``f~ <= f``: the eroded solid lies inside the child's, so the child's box and
  distance bounds stay valid (the bound at level ``c`` is the child's, or Hart's
  bound of ``f~`` when larger), and a unit-rate falloff of the child is kept.
* Lipschitz: ``|grad(D (1 - rho))| <= L_D + sup D L_rho`` (``0 <= 1 - rho <= 1``), so
  ``L = L_f + L_D + M_D L_rho`` with ``M_D`` the erosion field's ``value_max``. The
  same holds in a ball with the erosion field's local bounds
  (:meth:`~.skeletal_set.SkeletalSet.local_lipschitz`), which ``eval_bounds`` uses.
* Slopes in small balls: in the ball ``B(p, rad)``, with ``S_f``, ``S_D`` the child's and
  the erosion field's slope bounds there (:func:`~arches_render.field.local_slopes.eval_local`),
  ``M_D(B)`` the erosion field's maximum there (its cell table within one cell edge) and
  ``r^ = clamp(rho, 0, 1)``, which is ``L_rho``-Lipschitz,

      |grad f~| <= |grad f| + |grad D| (1 - r^) + D |grad r^|
                <= S_f + S_D min(1, 1 - r^(p) + L_rho rad) + min(M_D(B), D(p) + S_D rad) L_rho,

  since ``1 - r^`` and ``D`` move by at most ``L_rho rad`` and ``S_D rad`` from ``p`` within
  the ball. So ``min(rad, (-f~ - c) / S)`` is a distance bound too. Hard beds
  (``r^ ~ 1``) thus take the child's slope, not the erosion field's steepest, and a
  point where the erosion is weak does not pay its maximum: on the erosion scenes
  ``S_D`` (about ``2 T G_SLOPE / R``) and ``M_D L_rho`` were each several times the
  child's slope next to the cliffs they carve. (``r^(p)`` is evaluated where ``D(p) > 0``
  only; elsewhere ``1 - r^`` is bounded by 1.) ``eval_bounds`` asks
  for two radii, the erosion field's ``local_radius`` and an eighth of it, as the
  sum does: a ray leaving a wall that the erosion cut into a terrain's steep side
  takes the step of the terrain's slope there, not of the steepest DEM cell anywhere
  (floating islands, shadow rays off the islands' rims: Hart's bound with ``L = 19``
  against true gradients of about 1).

References
----------
Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
38(5), Sec. 6 (Fig. 10).
"""

from __future__ import annotations

import drjit as dr

from arches_render.field.node import Node, hart_bounds

from .geology import ResistanceNode
from arches_render.field.local_slopes import eval_local, local_hart, local_lipschitz


class Erosion(Node):
    """``f - max(f_D, 0) (1 - clamp(rho, 0, 1))`` (see module docstring).

    Parameters
    ----------
    child : Node
        The eroded sub-tree ``f`` (a terrain).
    erosion_field : Node
        ``f_D``, with a known upper bound ``value_max`` (a ``SkeletalSet``).
    resistance : ResistanceNode
        The geology tree ``rho``.
    """

    kind = "erosion"

    def __init__(self, child: Node, erosion_field: Node, resistance: ResistanceNode):
        if not isinstance(resistance, ResistanceNode):
            raise ValueError(f"erosion resistance must be a geology node (got {type(resistance).__name__})")
        if isinstance(child, ResistanceNode) or isinstance(erosion_field, ResistanceNode):
            raise ValueError("erosion child and erosion_field must be field nodes, not resistance nodes")
        if getattr(erosion_field, "value_max", None) is None:
            raise ValueError(f"erosion_field ({type(erosion_field).__name__}) has no known upper bound "
                             "(value_max): use a skeletal_set")
        self.children = (child, erosion_field, resistance)

    def _erode(self, p, f, fd=None):
        """``(f~, 1 - clamp(rho, 0, 1))`` at ``p``, the second 1 where the erosion field
        is not positive (rho is not evaluated there)."""
        # The geology tree is evaluated only where the erosion field is positive
        # (a symbolic branch: packets with no such lane skip it).
        if fd is None:
            fd = self.children[1].eval(p)

        def eroded(p, f, fd):
            soft = 1.0 - dr.clip(self.children[2].eval(p), 0.0, 1.0)
            return f - fd * soft, soft

        def intact(p, f, fd):
            return f, dr.ones(type(f), dr.width(f))

        return dr.if_stmt((p, f, fd), fd > 0.0, eroded, intact, label="erosion")

    def eval(self, p):
        return self._erode(p, self.children[0].eval(p))[0]

    def box_range(self, lo, hi):
        # Erosion removes at most max(f_D, 0) (1 - rho) <= max(f_D, 0), never adds.
        a, b = self.children[0].box_range(lo, hi)
        _, d_hi = self.children[1].box_range(lo, hi)
        return a - dr.maximum(d_hi, 0.0), b

    def local_lipschitz(self, p):
        """``(L, M, r)``: slope bound ``L`` in the ball of radius ``r`` around ``p`` (the
        erosion field's local bounds, see the module docstring); ``M`` is the child's
        ``value_max`` (erosion only removes), or None. ``None`` when the erosion field
        has no local bounds."""
        own = getattr(self.children[1], "local_lipschitz", None)
        return None if own is None else self._local_from(p, own(p))

    def _local_from(self, p, field_local):
        """:meth:`local_lipschitz` from the erosion field's own ``(L_D, M_D, r_D)`` at ``p``."""
        Lf, rf = local_lipschitz(self.children[0], p)
        LD, MD, rD = field_local
        L = Lf + LD + MD * self.children[2].lipschitz
        return L, self.value_max, (rD if rf is None else dr.minimum(rf, rD))

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        child, field, rho = self.children
        radii = self.slope_radii if levels else ()
        f, ds, child_slopes = eval_local(child, p, levels, direction, footprint, radii)
        if radii:
            # The erosion field at full detail, as eval has it (the same value up to the
            # order of a sum over its primitives), with its slopes.
            fd, _, field_slopes = eval_local(field, p, (), None, None, radii)
            v, soft = self._erode(p, f, fd)
        else:
            v, _ = self._erode(p, f)
        # The erosion field's cell tables, read once: the local bound and the balls' M_D.
        own = getattr(field, "local_lipschitz", None)
        field_local = None if own is None else own(p)
        local = None if field_local is None else self._local_from(p, field_local)
        # The child's footprint field (arches_render.field.lod): slopes grow by 1 + kappa s.
        grow = 1.0 + self.lod_kappa * footprint.rate if footprint is not None and self.lod_kappa else 1.0
        if local is None:
            hart = hart_bounds(v, levels, self.lipschitz * grow)
        else:
            hart = local_hart(v, levels, local[0] * grow, local[2], self.lipschitz * grow)
        if radii:
            # Slopes in the balls of radii (module docstring); the child's already grown.
            _, M_cell, cell = field_local
            M_glob = max(float(field.value_max), 0.0)
            D, L_rho = dr.maximum(fd, 0.0), rho.lipschitz
            for S_f, S_D, rad in zip(child_slopes, field_slopes, radii):
                M = dr.minimum(dr.select(rad <= cell, dr.maximum(M_cell, 0.0), M_glob), D + S_D * rad)
                S = S_f + S_D * dr.minimum(soft + L_rho * rad, 1.0) + M * L_rho
                inv = dr.rcp(dr.maximum(S, 1e-12))
                hart = tuple(dr.maximum(h, dr.minimum(dr.maximum(-v - c, 0.0) * inv, rad))
                             for h, c in zip(hart, levels))
        return v, tuple(dr.maximum(d, h) for d, h in zip(ds, hart))

    @property
    def slope_radii(self):
        """Radii of the balls whose slopes bound the steps (module docstring): the
        erosion field's ``local_radius`` and an eighth of it; ``()`` when the field has
        no local slopes."""
        r = getattr(self.children[1], "local_radius", None)
        if not r or getattr(self.children[1], "local_lipschitz", None) is None:
            return ()
        return (float(r), float(r) / 8.0)

    def bounds(self):
        return self.children[0].bounds()

    @property
    def unit_falloff(self):
        return self.children[0].unit_falloff

    @property
    def lipschitz(self):
        f, d, rho = self.children
        return f.lipschitz + d.lipschitz + max(float(d.value_max), 0.0) * rho.lipschitz

    @property
    def value_max(self):
        return getattr(self.children[0], "value_max", None)
