"""Affine transforms of a child field: translate, rotate, scale.

A transform ``A`` (``p' = M p + t``) moves the child's solid: ``g(p) = s f(A^{-1} p)``
with ``s = sigma_min(M)``, the smallest singular value. Scaling by ``s`` keeps
values in metres for rigid motions and uniform scales (where it is exact), and
keeps the Lipschitz bound of the child for any invertible ``M``:
``L_g = s ||M^{-1}|| L_f = L_f`` since ``||M^{-1}||_2 = 1 / sigma_min(M)``.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .node import Node, finite_box, opaque_float


def rotation_matrix(axis, angle_deg: float) -> np.ndarray:
    """Rotation about ``axis`` by ``angle_deg`` degrees (right-hand rule, Rodrigues)."""
    a = np.asarray(axis, dtype=np.float64).reshape(3)
    n = np.linalg.norm(a)
    if not n > 0:
        raise ValueError("rotation axis must be non-zero")
    x, y, z = a / n
    t = np.radians(angle_deg)
    c, s = np.cos(t), np.sin(t)
    C = 1 - c
    return np.array([[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                     [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                     [z * x * C - y * s, z * y * C + x * s, c + z * z * C]])


class Transform(Node):
    """Child field moved by ``p' = matrix @ p + offset`` (see module docstring)."""

    kind = "transform"

    def __init__(self, child: Node, matrix=None, offset=(0.0, 0.0, 0.0)):
        self.children = (child,)
        M = np.eye(3) if matrix is None else np.asarray(matrix, dtype=np.float64).reshape(3, 3)
        sv = np.linalg.svd(M, compute_uv=False)
        if not sv[-1] > 1e-12:
            raise ValueError("transform matrix must be invertible")
        self.M = M
        self.t = np.asarray(offset, dtype=np.float64).reshape(3)
        self.Minv = np.linalg.inv(M)
        self.s_np = float(sv[-1])
        self.sigma_max = float(sv[0])
        self._minv = [[opaque_float(self.Minv[i, j]) for j in range(3)] for i in range(3)]
        self._t = [opaque_float(v) for v in self.t]
        self._s = opaque_float(self.s_np)

    @classmethod
    def translate(cls, child, offset):
        return cls(child, None, offset)

    @classmethod
    def rotate(cls, child, axis, angle_deg, pivot=(0.0, 0.0, 0.0)):
        R = rotation_matrix(axis, angle_deg)
        c = np.asarray(pivot, dtype=np.float64)
        return cls(child, R, c - R @ c)

    @classmethod
    def scale(cls, child, factor, pivot=(0.0, 0.0, 0.0)):
        S = np.diag(np.broadcast_to(np.asarray(factor, dtype=np.float64), (3,)))
        c = np.asarray(pivot, dtype=np.float64)
        return cls(child, S, c - S @ c)

    def _local(self, p):
        q = [p.x - self._t[0], p.y - self._t[1], p.z - self._t[2]]
        m = self._minv
        return mi.Point3f(*(m[i][0] * q[0] + m[i][1] * q[1] + m[i][2] * q[2] for i in range(3)))

    def eval(self, p):
        return self._s * self.children[0].eval(self._local(p))

    def eval_bounds(self, p, levels, direction=None, footprint=None):
        # s f_c >= -c  <=>  f_c >= -c / s; a local distance d is a world distance
        # of at least sigma_min d = s d. A world cone of radius r covers local lengths
        # of at least r / sigma_max (the child keeps at least the detail it should);
        # as a function of the local point that radius keeps its rate.
        inv_s = 1.0 / self.s_np
        if footprint is not None:
            footprint = footprint.scaled(1.0 / self.sigma_max)
        f, ds = self.children[0].eval_bounds(self._local(p), tuple(c * inv_s for c in levels),
                                             footprint=footprint)
        return self._s * f, tuple(self._s * d for d in ds)

    def box_range(self, lo, hi):
        # The box in the child's coordinates: the bounding box of its eight mapped corners.
        corners = [self._local(mi.Point3f(x, y, z)) for x in (lo.x, hi.x) for y in (lo.y, hi.y)
                   for z in (lo.z, hi.z)]
        clo = mi.Point3f(*(dr.minimum(dr.minimum(dr.minimum(corners[0][i], corners[1][i]),
                                                 dr.minimum(corners[2][i], corners[3][i])),
                                      dr.minimum(dr.minimum(corners[4][i], corners[5][i]),
                                                 dr.minimum(corners[6][i], corners[7][i]))) for i in range(3)))
        chi = mi.Point3f(*(dr.maximum(dr.maximum(dr.maximum(corners[0][i], corners[1][i]),
                                                 dr.maximum(corners[2][i], corners[3][i])),
                                      dr.maximum(dr.maximum(corners[4][i], corners[5][i]),
                                                 dr.maximum(corners[6][i], corners[7][i]))) for i in range(3)))
        a, b = self.children[0].box_range(clo, chi)
        return self._s * a, self._s * b

    def lod_error(self, radius):
        # Values are scaled by s; the child sees the footprint shrunk by sigma_max.
        return self.s_np * self.children[0].lod_error(radius / self.sigma_max)

    def bounds(self):
        box = finite_box(self.children[0])
        if box is None:
            # Only axis-permuting maps keep infinite boxes meaningful; be safe.
            return np.full(3, -np.inf), np.full(3, np.inf)
        lo, hi = box
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])
        moved = corners @ self.M.T + self.t
        return moved.min(axis=0), moved.max(axis=0)

    @property
    def lipschitz(self):
        return self.children[0].lipschitz

    @property
    def unit_falloff(self):
        # Distances shrink by sigma_min / sigma_max: unit rate only for similarities.
        sv = np.linalg.svd(self.M, compute_uv=False)
        return bool(np.isclose(sv[0], sv[-1])) and self.children[0].unit_falloff

    def nbytes(self):
        return 64 + 13 * 4
