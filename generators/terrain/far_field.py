"""The far field: terrain and sea from the edge of a DEM tile to the horizon (issue 14).

A heightfield tile ends at its border: seen from inside, the ground stops in a wall
(the cut sides of the terrain's bounding prism) and, past it, in the black lower
hemisphere of the sky. The far field continues the ground as a coarse, cheap
triangle mesh in the same material, and the sea as a flat ring at sea level:

Frame
    For an ``implicit_heightfield`` (Paris et al. 2019, Sec. 5.1) the DEM is
    embedded exactly only inside the domain shrunk by its falloff radius ``R``;
    in the outer band the surface rounds down into the prism's walls. The frame
    is the mesh of the DEM's own samples in that band (from one cell inside the
    seam to the border), lifted by a quarter of each cell's bilinear twist so that
    it covers the bilinear surface it replaces: the rounded edge and the walls lie
    under it. A plain ``heightfield`` is exact up to its border and gets no frame.
Rings
    From the border outwards, rings at distances ``s_0 = 0, s_1 = cell,
    s_{k+1} = (1 + 0.7 / DETAIL) s_k`` up to ``reach`` (default ``max(1e10 m, 1000 x
    the tile)``, :func:`default_reach`). Ring 0 is the border loop; ring ``k`` is the rectangle
    ``s_k`` outside the tile, each side sampled every ``sigma(s_k)`` (at least a cell,
    at most :data:`MAX_RING` points a ring past a quarter tile) and stitched to the previous ring's side
    (:func:`_stitch`), so the corner quadrants hold relief as the sides do. Its
    heights continue the DEM's own relief (issue 34): near the tile the DEM *mirrored*
    across its borders (reflected about the border samples, so the ground is
    continuous there and valleys and ridges run on past the edge), farther out a
    continuation with the tile's spectrum, heights and tile-scale trends but none of
    its landforms (:class:`.ContinuedRelief`: the mirror alone put every landform
    again every two tiles, to the horizon), low-pass filtered by a Gaussian of
    ``sigma(s)`` (:func:`blur_schedule`): ``s / (2 DETAIL)``
    near the tile, as a photograph's detail fades with distance, but never wider
    than the blur that keeps :data:`KEEP_RELIEF` of the DEM's height deviation, until
    the landforms subtend :data:`RELIEF_ANGLE`; only past that does the ground fade
    to the DEM's mean height. (Before, the blur grew with distance alone: past a
    tile or two the mountains of a 71 km Alpine tile became a flat plain, and a
    coast's hills a ruled horizon line. Before that, the rings held the border's own
    heights smoothed along the loop: from above, a square of relief on a flat plane.)
Sea
    With ``sea_level``, a flat ring at that level from the tile's border to
    ``reach`` (the water inside the tile is the scene's own, e.g. amplify's
    ``water.ply``): where the far ground lies below the sea, the sea reaches the
    horizon. It is cut into rectangular bands at the rings' distances
    (:func:`sea_ring_mesh`), so that no triangle near the tile is thousands of
    kilometres long.

Scene table (``[[far_field]]``, one per heightfield)::

    [[far_field]]
    node = "terrain"            # a heightfield or implicit_heightfield node, untransformed
    material = "landscape"      # the ground's material
    reach = 1e10                # optional, metres from the border
    sea_level = 0.0             # optional: a sea ring at this level ...
    water_material = "water"    # ... in this material (required with sea_level)
    context = { file = "data/t.context.npy", extent = [x0, y0, x1, y1] }
                                # optional: the DEM the tile was refined from
                                # (:mod:`.refined_crop`), in the tile's frame

Context
    A tile refined from a window of a coarser DEM (``amplify --refine``) lies inside
    that DEM: the rings then read the DEM around it (continued past its own border as
    above) instead of continuing the tile's relief, and the overview shows the real
    terrain around the crop. The crop meets the DEM's bilinear surface at its border,
    which is what the first rings read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mitsuba as mi
import numpy as np

from arches_render.field import Heightfield
from arches_render.mesh.polygonize import TriangleMesh
from arches_render.mesh.triangles import face_normals, merged_vertices, vertex_normals

from .continued_relief import ContinuedRelief

__all__ = ["FarField", "blur_schedule", "far_field_mesh", "surrounding_ground", "frame_band", "sea_ring_mesh", "ring_distances", "parse_far_field", "default_reach"]

_GROWTH = 1.35  # ring distance ratio (the sea's rings)

#: The share of the DEM's height deviation the far rings keep (:func:`blur_schedule`): at
#: 0.7 the Alps' ridges (a blur of 3.7 km on Aletsch) and the Santa Cruz range's hills
#: (1.9 km, Devil's Slide) run on to the horizon; the rings blurred into the mean height
#: showed a flat plain there, and its horizon as a ruled line across the frame.
KEEP_RELIEF = 0.7

#: Angle (radians) below which the far rings' landforms no longer show: twice the
#: DEM's height deviation seen from this far away subtends about three pixels of a
#: 1280-pixel, 55 degree frame.
RELIEF_ANGLE = 2e-3

#: Most points on one ring past a quarter tile from the border (past it the ring is
#: sampled, and blurred, more coarsely); nearer, the border loop's count if larger.
MAX_RING = 1024

#: Detail of the ground rings: their relief is blurred by ``sigma = s / (2 DETAIL)`` at
#: distance ``s`` from the border, sampled every ``s / (2 DETAIL)`` along the rings, with
#: rings ``1 + 0.7 / DETAIL`` apart. At 1 (``sigma = s / 2``) a 5 km canyon tile's
#: overview showed a smooth green skirt around the tile; at 4 its plateaus, river and
#: cliff bands run on past the edge (113k triangles on that tile against 40k).
DETAIL = 4.0


#: The far field's least reach (metres): a camera ``h`` above the ground sees a gap of
#: ``h / REACH`` radians below the horizon, where rays pass the far field's edge into the
#: sky's black lower hemisphere; 1e-5 rad at 100 km. (At 1e7 m an Alpine overview 7 km
#: up showed a row of dark specks along its horizon, partly covered pixels; 1e9 m still
#: darkened the row above it. The rings past the fade are flat and sparse: +350 faces
#: from 1e7 to 1e10 m. Float32 rounds those vertices by up to 512 m, and what lies there
#: is fully fogged.)
REACH = 1e10


def default_reach(extent) -> float:
    """Default distance of the far field's outer edge from the border (metres):
    :data:`REACH`, or a thousand tiles for larger ones."""
    x0, y0, x1, y1 = extent
    return max(REACH, 1000.0 * max(x1 - x0, y1 - y0))


def _loop(nx, ny):
    """Grid indices ``(j, i)`` of the border loop (counter-clockwise from ``(0, 0)``) and the
    corner positions in it."""
    bottom = [(0, i) for i in range(nx)]
    right = [(j, nx - 1) for j in range(1, ny)]
    top = [(ny - 1, i) for i in range(nx - 2, -1, -1)]
    left = [(j, 0) for j in range(ny - 2, 0, -1)]
    loop = np.array(bottom + right + top + left)
    corners = np.array([0, nx - 1, nx - 1 + ny - 1, 2 * (nx - 1) + ny - 1])
    return loop, corners


def blur_schedule(relief, cell):
    """The ground rings' blur as a function of the distance ``s`` from the border.

    ``s / (2 DETAIL)`` near the tile (detail fades with distance); at most ``keep``,
    the widest blur that keeps :data:`KEEP_RELIEF` of the DEM's height deviation
    (:meth:`.MirroredRelief.blur_keeping`), up to ``far`` = twice that deviation over
    :data:`RELIEF_ANGLE` (where the landforms shrink to a few pixels); beyond,
    ``keep (s / far)^2``, which fades to the mean height within a decade of distance
    (rings sampled as coarsely: their points fall as ``1 / s``). At least one DEM cell.

    Parameters
    ----------
    relief : ContinuedRelief or MirroredRelief
    cell : float
        The DEM's cell (metres).

    Returns
    -------
    callable
        ``sigma(s)`` in metres.
    """
    keep = max(relief.blur_keeping(KEEP_RELIEF), cell)
    near = 2.0 * DETAIL * keep
    far = max(2.0 * relief.relief / RELIEF_ANGLE, near)

    def sigma(s):
        return s / (2.0 * DETAIL) if s <= near else (keep if s <= far else keep * (s / far) ** 2)

    return sigma


def _square_ring(lo, hi, spacing):
    """A closed loop around the rectangle ``lo``-``hi`` (counter-clockwise from ``lo``), each
    side cut into segments of at most ``spacing``: ``(points (n, 2), sides)``, ``sides``
    four ``(indices, parameters)`` from corner to corner (the last index of a side is the
    next side's first; parameters from 0 to 1 along the side)."""
    corners = np.array([lo, (hi[0], lo[1]), hi, (lo[0], hi[1])], np.float64)
    pts, sides, start = [], [], 0
    for q in range(4):
        a, b = corners[q], corners[(q + 1) % 4]
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / spacing)))
        t = np.arange(n + 1) / n
        pts.append(a + t[:-1, None] * (b - a))
        sides.append((start + np.arange(n + 1), t))
        start += n
    pts = np.concatenate(pts)
    sides[-1][0][-1] = 0  # the loop closes at its first corner
    return pts, sides


def _loop_sides(corners, n):
    """The four sides of the border loop (``n`` points, ``corners`` their positions), as
    :func:`_square_ring` gives them."""
    ends = list(corners) + [n]
    sides = []
    for q in range(4):
        k = np.arange(ends[q], ends[q + 1] + 1)
        sides.append((k % n, (k - ends[q]) / (ends[q + 1] - ends[q])))
    return sides


def _stitch(inner, outer):
    """Triangles between two polylines from one end to the other, each ``(indices,
    parameters)`` with parameters rising from 0 to 1: the advancing front takes the
    nearer next point of the two, so no triangle spans more than a step of each."""
    (ia, pa), (ib, pb) = inner, outer
    events = np.concatenate([pa[1:], pb[1:]])
    is_a = np.concatenate([np.ones(len(pa) - 1, bool), np.zeros(len(pb) - 1, bool)])
    order = np.argsort(events, kind="stable")  # ties: the inner ring's point first
    is_a = is_a[order]
    na = np.cumsum(is_a) - is_a  # inner points passed before each event
    nb = np.cumsum(~is_a) - ~is_a
    a0, b0 = ia[na], ib[nb]
    third = np.where(is_a, ia[np.minimum(na + 1, len(ia) - 1)], ib[np.minimum(nb + 1, len(ib) - 1)])
    return np.column_stack([a0, third, b0])


def frame_band(node) -> tuple[int, int]:
    """Width of the frame (module docstring) in DEM cells along x and y: one cell past the
    falloff radius ``R`` of an ``implicit_heightfield``, ``(0, 0)`` for a plain one."""
    R = getattr(node, "R_np", None)
    if R is None:
        return 0, 0
    ny, nx = node.heights_np.shape
    x0, y0, x1, y1 = node.extent
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    return (min(int(math.ceil(R / dx - 1e-9)) + 1, (nx - 1) // 2),
            min(int(math.ceil(R / dy - 1e-9)) + 1, (ny - 1) // 2))


def far_field_mesh(node, reach=None, sea_level=None, context=None):
    """Ground mesh of the far field of a heightfield node (see the module docstring).

    Parameters
    ----------
    node : arches_render.field.Heightfield
        A ``heightfield`` or ``implicit_heightfield`` node (world coordinates).
    reach : float, optional
        Distance of the outer ring from the border, metres (default :func:`default_reach`).
    sea_level : float, optional
        The sea's level: the ground past a sea border stays under it and past a land
        border above it (:class:`.ContinuedRelief`, "Coasts").
    context : (numpy.ndarray, tuple), optional
        ``(heights, extent)`` of a DEM holding the tile (module docstring, "Context"):
        the rings read it instead of the tile's continuation.

    Returns
    -------
    TriangleMesh
        Upward-facing triangles with vertex normals.
    """
    H = np.asarray(node.heights_np, np.float64)
    ny, nx = H.shape
    x0, y0, x1, y1 = node.extent
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    reach = float(reach) if reach is not None else default_reach(node.extent)
    V, F = [], []

    # Frame (implicit heightfields): the DEM's samples in the outer band, one cell past the seam.
    lift = np.zeros_like(H)
    bi, bj = frame_band(node)
    if bi or bj:
        twist = np.abs(H[:-1, :-1] - H[:-1, 1:] - H[1:, :-1] + H[1:, 1:]) / 4.0
        for sj in (slice(0, -1), slice(1, None)):
            for si in (slice(0, -1), slice(1, None)):
                lift[sj, si] = np.maximum(lift[sj, si], twist)
        J, I = np.mgrid[0:ny, 0:nx]
        lift[(I >= bi) & (I <= nx - 1 - bi) & (J >= bj) & (J <= ny - 1 - bj)] = 0.0  # the inner edge: exact
        cj, ci = np.nonzero((I[:-1, :-1] < bi) | (I[:-1, :-1] >= nx - 1 - bi)
                            | (J[:-1, :-1] < bj) | (J[:-1, :-1] >= ny - 1 - bj))
        used = np.zeros(H.shape, bool)
        for a, b in ((0, 0), (0, 1), (1, 0), (1, 1)):
            used[cj + a, ci + b] = True
        vj, vi = np.nonzero(used)
        vid = np.full(H.shape, -1, np.int64)
        vid[vj, vi] = np.arange(len(vj))
        V.append(np.column_stack([x0 + vi * dx, y0 + vj * dy, H[vj, vi] + lift[vj, vi]]))
        a, b, c, d = vid[cj, ci], vid[cj, ci + 1], vid[cj + 1, ci], vid[cj + 1, ci + 1]
        F += [np.column_stack([a, b, d]), np.column_stack([a, d, c])]

    # Rings from the border outwards: rectangles around the tile (their corners too hold
    # relief), sides sampled at the ring's blur and stitched to the previous ring's.
    loop, corners = _loop(nx, ny)
    border = (H + lift)[loop[:, 0], loop[:, 1]]  # the frame's border vertices, shared exactly
    V.append(np.column_stack([x0 + loop[:, 1] * dx, y0 + loop[:, 0] * dy, border]))
    off = sum(len(v) for v in V[:-1])
    prev = [(off + k, t) for k, t in _loop_sides(corners, len(loop))]
    off += len(loop)
    if context is None:
        relief = ContinuedRelief(H, node.extent, sea_level)
        sigma = blur_schedule(relief, max(dx, dy))
    else:
        C, (cx0, cy0, cx1, cy1) = np.asarray(context[0], np.float64), context[1]
        relief = ContinuedRelief(C, (cx0, cy0, cx1, cy1), sea_level)
        sigma = blur_schedule(relief, max((cx1 - cx0) / (C.shape[1] - 1), (cy1 - cy0) / (C.shape[0] - 1)))
    for sk in ring_distances(max(dx, dy), reach, 1.0 + 0.7 / DETAIL)[1:]:
        lo, hi = (x0 - sk, y0 - sk), (x1 + sk, y1 + sk)
        # Along a ring: at least a cell, at most MAX_RING points (then blurred as sampled),
        # or as many as the border loop within a quarter tile of it (a cell apart next to
        # the tile, as the frame's samples are, on DEMs of any size).
        most = max(MAX_RING, len(loop)) if sk < 0.25 * min(x1 - x0, y1 - y0) else MAX_RING
        spacing = max(sigma(sk), 2.0 * ((hi[0] - lo[0]) + (hi[1] - lo[1])) / most, min(dx, dy))
        p, sides = _square_ring(lo, hi, spacing)
        V.append(np.column_stack([p, relief.heights(p[:, 0], p[:, 1], spacing)]))
        ring = [(off + k, t) for k, t in sides]
        F += [_stitch(a, b) for a, b in zip(prev, ring)]
        prev, off = ring, off + len(p)
    # Merged vertices (frame and first ring share theirs) and upward faces, so that
    # vertex normals are smooth across the seams.
    vertices, faces = merged_vertices(np.concatenate(V), np.concatenate(F))
    down = face_normals(vertices, faces)[:, 2] < 0
    faces[down] = faces[down][:, ::-1]
    return TriangleMesh(vertices, faces, vertex_normals(vertices, faces))


def surrounding_ground(node, widths, sea_level=None, context=None):
    """The far field's ground around a heightfield tile, out to ``widths`` tile widths,
    without its faces over the tile: what a view from inside the tile sees beyond it
    (amplify's close shots take it as an occluder, :func:`.shots.close_shots`).

    Parameters
    ----------
    node : arches_render.field.Heightfield
        The tile's ``heightfield`` or ``implicit_heightfield``.
    widths : float
        The reach, in widths of the tile's longer side.
    sea_level, context
        As :func:`far_field_mesh`.

    Returns
    -------
    trimesh.Trimesh
    """
    import trimesh
    x0, y0, x1, y1 = node.extent
    mesh = far_field_mesh(node, reach=widths * max(x1 - x0, y1 - y0), sea_level=sea_level, context=context)
    V, F = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    c = V[F].mean(axis=1)
    outside = (c[:, 0] < x0) | (c[:, 0] > x1) | (c[:, 1] < y0) | (c[:, 1] > y1)
    return trimesh.Trimesh(V, F[outside], process=False)


def ring_distances(first: float, reach: float, growth: float = _GROWTH) -> list:
    """Distances of the rings from the border: ``0, first``, then ``x growth`` each, and ``reach``.

    Parameters
    ----------
    first : float
        The first ring's distance (metres, > 0).
    reach : float
        The last ring's distance (metres).
    growth : float
        Ratio of successive distances (> 1; the sea's rings 1.35, the ground's ``1 + 0.7 / DETAIL``).

    Returns
    -------
    list of float
    """
    s = [0.0, float(first)]
    while s[-1] * growth < reach:
        s.append(s[-1] * growth)
    s.append(float(reach))
    return s


def sea_ring_mesh(extent, level, reach, first=None):
    """A flat ring at ``level`` from the rectangle ``extent`` to ``reach`` beyond it (upward faces).

    The ring is a band of rectangles at :func:`ring_distances` from the border
    (``first``: default a 64th of the longer side), not one band of four quads: a
    triangle reaching from the shore to ``reach`` (10,000 km) put Mitsuba's hit
    points near the shore kilometres off (float32 barycentrics of such a triangle;
    the ``position`` AOV 9 km away at 40 m from the camera, and shadow rays leaving
    from there), while a triangle about as long as its distance from the tile keeps
    them within float32 precision of the ray's own ``o + t d``.

    Parameters
    ----------
    extent : sequence of 4 floats
        The tile ``(x0, y0, x1, y1)``.
    level : float
        The sea level (z).
    reach : float
        Distance of the outer edge from the tile (metres).
    first : float, optional
        Distance of the first ring.

    Returns
    -------
    TriangleMesh
    """
    x0, y0, x1, y1 = extent
    first = max(x1 - x0, y1 - y0) / 64.0 if first is None else float(first)
    V = []
    for sk in ring_distances(first, reach):
        V += [(x0 - sk, y0 - sk, level), (x1 + sk, y0 - sk, level), (x1 + sk, y1 + sk, level),
              (x0 - sk, y1 + sk, level)]
    F = []
    for k in range(len(V) // 4 - 1):
        i, o = 4 * k, 4 * (k + 1)  # the inner and outer rectangles
        for q in range(4):
            o0, o1, i0, i1 = o + q, o + (q + 1) % 4, i + q, i + (q + 1) % 4
            F += [(o0, o1, i1), (o0, i1, i0)]
    vertices, faces = np.array(V, np.float64), np.array(F, np.int64)
    return TriangleMesh(vertices, faces, vertex_normals(vertices, faces))


def _mitsuba_mesh(name, mesh, bsdf):
    props = mi.Properties()
    props["bsdf"] = bsdf
    m = mi.Mesh(name, len(mesh.vertices), len(mesh.faces), props, has_vertex_normals=True)
    params = mi.traverse(m)
    params["vertex_positions"] = mi.Float(np.asarray(mesh.vertices, np.float32).ravel())
    params["faces"] = mi.UInt32(np.asarray(mesh.faces, np.uint32).ravel())
    params["vertex_normals"] = mi.Float(np.asarray(mesh.normals, np.float32).ravel())
    params.update()
    return m


@dataclass
class FarField:
    """A validated ``[[far_field]]`` entry (an item of a scene table, :mod:`arches_render.extensions`)."""

    index: int
    node: Heightfield
    material: str
    reach: float
    sea_level: float | None = None
    water_material: str | None = None
    context: tuple | None = None
    _meshes: list | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def name(self) -> str:
        """``far_field<index>``: prefix of its shape ids."""
        return f"far_field{self.index}"

    def meshes(self) -> list:
        """``[(material, TriangleMesh)]``: the ground, then the sea ring if any (built once)."""
        if self._meshes is None:
            out = [(self.material, far_field_mesh(self.node, self.reach, self.sea_level, self.context))]
            if self.sea_level is not None:
                out.append((self.water_material, sea_ring_mesh(self.node.extent, self.sea_level, self.reach)))
            self._meshes = out
        return self._meshes

    def ray_region(self) -> tuple:
        """``(hole, z0, z1)``: the far field lies between heights ``z0`` and ``z1`` outside the
        open column over ``hole``, the tile less its frame band
        (:mod:`arches_render.render.mesh_region`: rays that cannot meet it skip it)."""
        bi, bj = frame_band(self.node)
        ny, nx = self.node.heights_np.shape
        x0, y0, x1, y1 = self.node.extent
        dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
        z = np.concatenate([m.vertices[:, 2] for _, m in self.meshes()])
        return (x0 + bi * dx, y0 + bj * dy, x1 - bi * dx, y1 - bj * dy), float(z.min()), float(z.max())

    def shapes(self, bsdfs: dict, progress=None) -> list:
        """Mitsuba meshes of the far field with their BSDFs from ``bsdfs``."""
        return [_mitsuba_mesh(f"{self.name}_{k}", m, bsdfs[mat]) for k, (mat, m) in enumerate(self.meshes())]

    def point_instancer(self):
        """No instances: the far field is plain meshes."""
        return None


def parse_far_field(t, builder, field_node, materials: dict, scene_file, index: int) -> FarField:
    """Validate one ``[[far_field]]`` table (keys in the module docstring)."""
    node = builder.named(t.string("node"), t, "node")
    if not isinstance(node, Heightfield):
        raise t.error("node", f"must name a heightfield or implicit_heightfield node (got a {node.kind})")
    mat = t.string("material")
    if mat not in materials:
        raise t.error("material", f"unknown material '{mat}' (defined: {', '.join(sorted(materials))})")
    reach = t.number("reach", default_reach(node.extent), lo=0, lo_open=True)
    sea = t.number("sea_level", None)
    water = None
    if sea is not None:
        water = t.string("water_material")
        if water not in materials:
            raise t.error("water_material", f"unknown material '{water}' (defined: {', '.join(sorted(materials))})")
    context = _context(t, node, scene_file)
    t.finish()
    return FarField(index, node, mat, float(reach), sea, water, context)


def _context(t, node, scene_file):
    """``(heights, extent)`` of the table's optional ``context`` (module docstring), which
    must hold the node's tile."""
    ct = t.table("context", None)
    if ct is None:
        return None
    from pathlib import Path

    from arches_render.scene.nodes import load_heights
    x0, y0, x1, y1 = ct.vector("extent", 4)
    tx0, ty0, tx1, ty1 = node.extent
    if not (x0 <= tx0 and y0 <= ty0 and x1 >= tx1 and y1 >= ty1):
        raise ct.error("extent", f"must hold the tile {[tx0, ty0, tx1, ty1]} (got {[x0, y0, x1, y1]})")
    H = load_heights(ct, Path(scene_file).parent)
    ct.finish()
    return np.asarray(H, np.float64), (float(x0), float(y0), float(x1), float(y1))
