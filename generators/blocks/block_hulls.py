"""Convex blocks from clusters: hull planes, joint dilation, anchors and boxes.

Paris et al. (2020, section 4.2): "we first compute the convex hull of each cluster
and extract a corresponding polygonal mesh ``M_i``. We compute the planes
``H_k = (o_k, u_k)`` associated to every polygon of ``M_i`` such that their normal
``u_k`` should be oriented towards the exterior"; the half-space functions are
``h_k(p) = (p - o_k) . u_k`` (negative inside).

Here a plane is stored as ``(u_k, w_k)`` with ``w_k = o_k . u_k``, so that the
*inside-positive* half-space of the field language is ``w_k - u_k . p``.

Simplification. The hull of ~100 jittered samples has ~150 triangles, most of them
slivers of the few fracture faces that bound the block. Triangles whose normals
lie within ``merge_angle`` of each other (greedy, largest area first) become one
plane with the area-weighted normal, placed at the supporting position
``w = max_v u . v`` over the hull vertices: the block stays convex and contains
every sample of its cluster. This leaves ~14 planes per block (merge angle 20
deg); at most ``max_planes`` of the largest faces are kept (the dropped ones are
small corner facets; the block's box planes keep it bounded). The plane count is
what the field's cost is proportional to (the paper notes that "blocks could be
optimized with a limited number of primitives", section 6.4).

Joints. Poisson samples come arbitrarily close to a fracture plane, so the hull
faces of two clusters on either side of a fracture both lie on it; the planes are
pulled in by ``joint_width / 2`` (``dilation < 0``) so that open joints of width
``joint_width`` separate the blocks.

Anchors (section 5): each block gets its centroid and up to ``n_anchors - 1`` hull
vertices (farthest-point order) pulled 30 % towards the centroid; presence is
decided by a majority of them.

Boxes. ``b(p) <= min_k (w_k - u_k . p) + e`` for a warp of amplitude ``e``, so
``b < -m`` outside the polytope ``{u_k . p <= w_k + m + e}``; the box of that
offset polytope (vertices by ``scipy.spatial.HalfspaceIntersection``) is where the
block can matter, and is what the lookup grid registers.

References
----------
Paris et al. (2020), section 4.2, 5 and 6.4.
Barber, C. B., Dobkin, D. P., Huhdanpaa, H. (1996). The quickhull algorithm for
convex hulls. ACM TOMS 22(4) (Qhull, used through scipy.spatial).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, HalfspaceIntersection, QhullError

__all__ = ["hull_planes", "offset_box", "block_anchors"]


def hull_planes(points: np.ndarray, merge_angle: float = 20.0, dilation: float = 0.0,
                max_planes: int | None = None):
    """Simplified outward planes of the convex hull of ``points``.

    Parameters
    ----------
    points : numpy.ndarray
        ``(n, 3)`` samples of one cluster (unwrapped), ``n >= 4``.
    merge_angle : float
        Facets whose normals differ by less than this (degrees) share a plane.
    dilation : float
        Outward offset added to every plane (metres).
    max_planes : int, optional
        Keep only the largest faces (the caller must bound the block otherwise,
        e.g. with its box planes).

    Returns
    -------
    normals : numpy.ndarray
        ``(K, 3)`` unit outward normals ``u_k``, largest face first.
    offsets : numpy.ndarray
        ``(K,)`` offsets ``w_k``: the block is ``{p : u_k . p <= w_k}``.
    vertices : numpy.ndarray
        Hull vertices (before dilation).

    Raises
    ------
    ValueError
        If the points are degenerate (coplanar or fewer than four).

    References
    ----------
    Paris et al. (2020), section 4.2.
    """
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError) as exc:
        raise ValueError(f"degenerate cluster: {exc}") from None
    eq = hull.equations  # n . x + d <= 0 inside, unit n outward
    tri = points[hull.simplices]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    normals_f = eq[:, :3]
    verts = points[hull.vertices]
    cos_t = np.cos(np.radians(merge_angle))
    free = np.ones(len(eq), dtype=bool)
    planes = []
    for f in np.argsort(-area):
        if not free[f]:
            continue
        group = free & (normals_f @ normals_f[f] > cos_t)
        free &= ~group
        n = (normals_f[group] * area[group, None]).sum(0)
        norm = np.linalg.norm(n)
        n = n / norm if norm > 1e-12 else normals_f[f]
        planes.append((area[group].sum(), n))
    planes.sort(key=lambda t: -t[0])
    if max_planes:
        planes = planes[:int(max_planes)]
    normals = np.array([n for _, n in planes])
    offsets = (verts @ normals.T).max(axis=0) + float(dilation)
    return normals, offsets, verts


def offset_box(normals, offsets, interior, margin: float):
    """Box of the polytope ``{u_k . p <= w_k + margin}`` (``interior`` strictly inside)."""
    halfspaces = np.hstack([normals, -(offsets + margin)[:, None]])
    try:
        hs = HalfspaceIntersection(halfspaces, np.asarray(interior, float))
    except (QhullError, ValueError) as exc:
        raise ValueError(f"degenerate block: {exc}") from None
    v = hs.intersections
    if not np.all(np.isfinite(v)) or np.any(np.abs(v - interior).max() > 1e6):
        raise ValueError("unbounded block")
    return v.min(0), v.max(0)


def block_anchors(points: np.ndarray, vertices: np.ndarray, n_anchors: int = 9) -> np.ndarray:
    """Anchor points ``a_k`` of a block: centroid and pulled-in hull vertices.

    Parameters
    ----------
    points : numpy.ndarray
        Samples of the cluster.
    vertices : numpy.ndarray
        Its hull vertices.
    n_anchors : int
        Number of anchors (centroid included).

    Returns
    -------
    numpy.ndarray
        ``(n_anchors, 3)``; the centroid is repeated when the hull has fewer vertices.

    References
    ----------
    Paris et al. (2020), section 5 (a set of anchor points per block).
    """
    c = points.mean(0)
    chosen = [int(np.argmax(np.linalg.norm(vertices - c, axis=1)))]
    dist = np.linalg.norm(vertices - vertices[chosen[0]], axis=1)
    while len(chosen) < min(n_anchors - 1, len(vertices)):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(vertices - vertices[k], axis=1))
    a = c + 0.7 * (vertices[chosen] - c)
    out = np.vstack([c[None], a])
    if len(out) < n_anchors:
        out = np.vstack([out, np.repeat(c[None], n_anchors - len(out), 0)])
    return out
