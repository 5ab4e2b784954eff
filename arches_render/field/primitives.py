"""Primitive solids: sphere, box, capsule (segment skeleton) and half-space.

Each primitive returns the *exact* signed distance with our sign (positive inside),
so its Lipschitz bound is 1 and its values are metres.

References
----------
Hart, J. C. (1996). Sphere tracing: a geometric method for the antialiased ray
tracing of implicit surfaces. The Visual Computer, 12(10), 527-545.
"""

from __future__ import annotations

import drjit as dr
import numpy as np

from .node import Node, opaque_float, opaque_point

_INF = np.inf


class Sphere(Node):
    """Ball of radius ``r`` around ``center``: ``f(p) = r - |p - c|``."""

    kind = "sphere"

    def __init__(self, center, radius):
        self.c_np = np.asarray(center, dtype=np.float64).reshape(3)
        self.r_np = float(radius)
        self.c = opaque_point(self.c_np)
        self.r = opaque_float(self.r_np)

    def eval(self, p):
        return self.r - dr.norm(p - self.c)

    def bounds(self):
        return self.c_np - self.r_np, self.c_np + self.r_np

    @property
    def lipschitz(self):
        return 1.0


class Box(Node):
    """Axis-aligned box with optional rounded edges.

    ``f(p) = -( |max(q, 0)| + min(max(q_x, q_y, q_z), 0) - rounding )`` with
    ``q = |p - c| - (h - rounding)``, ``h`` the half extents.
    """

    kind = "box"

    def __init__(self, center, half_extents, rounding=0.0):
        self.c_np = np.asarray(center, dtype=np.float64).reshape(3)
        self.h_np = np.asarray(half_extents, dtype=np.float64).reshape(3)
        self.round_np = float(rounding)
        self.c = opaque_point(self.c_np)
        self.h = opaque_point(self.h_np - self.round_np)
        self.rounding = opaque_float(self.round_np)

    def eval(self, p):
        q = dr.abs(p - self.c) - self.h
        outside = dr.norm(dr.maximum(q, 0.0))
        inside = dr.minimum(dr.maximum(dr.maximum(q.x, q.y), q.z), 0.0)
        return self.rounding - (outside + inside)

    def bounds(self):
        return self.c_np - self.h_np, self.c_np + self.h_np

    @property
    def lipschitz(self):
        return 1.0


class Capsule(Node):
    """Segment skeleton ``[a, b]`` with radius ``r``: ``f(p) = r - dist(p, [a, b])``."""

    kind = "capsule"

    def __init__(self, a, b, radius):
        self.a_np = np.asarray(a, dtype=np.float64).reshape(3)
        self.b_np = np.asarray(b, dtype=np.float64).reshape(3)
        self.r_np = float(radius)
        self.a = opaque_point(self.a_np)
        self.b = opaque_point(self.b_np)
        self.r = opaque_float(self.r_np)

    def eval(self, p):
        pa, ba = p - self.a, self.b - self.a
        t = dr.clip(dr.dot(pa, ba) / dr.maximum(dr.squared_norm(ba), 1e-20), 0.0, 1.0)
        return self.r - dr.norm(pa - ba * t)

    def bounds(self):
        lo = np.minimum(self.a_np, self.b_np) - self.r_np
        hi = np.maximum(self.a_np, self.b_np) + self.r_np
        return lo, hi

    @property
    def lipschitz(self):
        return 1.0


class Plane(Node):
    """Half-space below the plane through ``point`` with outward ``normal``.

    ``f(p) = n . (point - p)`` with ``|n| = 1``. Unbounded: combine it with a
    bounded node (intersection) before it becomes the root of a scene.
    """

    kind = "plane"

    def __init__(self, normal=(0.0, 0.0, 1.0), point=(0.0, 0.0, 0.0)):
        n = np.asarray(normal, dtype=np.float64).reshape(3)
        norm = np.linalg.norm(n)
        if not norm > 0:
            raise ValueError("plane normal must be non-zero")
        self.n_np = n / norm
        self.o_np = np.asarray(point, dtype=np.float64).reshape(3)
        self.n = opaque_point(self.n_np)
        self.o = opaque_point(self.o_np)

    def eval(self, p):
        return dr.dot(self.n, self.o - p)

    def bounds(self):
        lo = np.full(3, -_INF)
        hi = np.full(3, _INF)
        # An axis-aligned half-space is bounded on one side.
        for axis in range(3):
            if np.isclose(abs(self.n_np[axis]), 1.0):
                if self.n_np[axis] > 0:
                    hi[axis] = self.o_np[axis]
                else:
                    lo[axis] = self.o_np[axis]
        return lo, hi

    @property
    def lipschitz(self):
        return 1.0
