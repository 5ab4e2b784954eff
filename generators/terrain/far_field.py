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
    s_{k+1} = (1 + 0.7 / DETAIL) s_k`` up to ``reach`` (default ``max(1e7 m, 1000 x
    the tile)``, so that a camera 1 km above the ground sees no gap below the horizon
    wider than 1e-4 rad). Ring ``k`` is the border loop moved outwards by ``s_k``
    (sides along their normals, corners diagonally). Its heights continue the DEM's
    own relief (issue 34): the DEM *mirrored* across its borders (reflected about
    the border samples, so the ground is continuous there and valleys and ridges
    run on past the edge), low-pass filtered by a Gaussian of ``sigma = s_k / (2
    DETAIL)`` (:class:`MirroredRelief`): detail fades with distance as a photograph's
    does, and far away, where ``sigma`` exceeds the tile, the ground is the DEM's mean
    height. (Before, the rings held the border's own heights smoothed along the loop:
    from above, a square of relief on a flat plane.) Ring ``k`` keeps every ``2^j``-th
    loop point with ``2^j spacing <= sigma`` (the corners always): the mesh holds
    about ``DETAIL^2`` times the border's length in triangles beyond the frame,
    whatever the DEM's area.
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
    reach = 1e7                 # optional, metres from the border
    sea_level = 0.0             # optional: a sea ring at this level ...
    water_material = "water"    # ... in this material (required with sea_level)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mitsuba as mi
import numpy as np

from arches_render.field import Heightfield
from arches_render.mesh.polygonize import TriangleMesh
from arches_render.mesh.triangles import face_normals, merged_vertices, vertex_normals

__all__ = ["FarField", "MirroredRelief", "far_field_mesh", "sea_ring_mesh", "ring_distances", "parse_far_field", "default_reach"]

_GROWTH = 1.35  # ring distance ratio (the sea's rings)

#: Detail of the ground rings: their relief is blurred by ``sigma = s / (2 DETAIL)`` at
#: distance ``s`` from the border, sampled every ``s / (2 DETAIL)`` along the rings, with
#: rings ``1 + 0.7 / DETAIL`` apart. At 1 (``sigma = s / 2``) a 5 km canyon tile's
#: overview showed a smooth green skirt around the tile; at 4 its plateaus, river and
#: cliff bands run on past the edge (113k triangles on that tile against 40k).
DETAIL = 4.0


def default_reach(extent) -> float:
    """Default distance of the far field's outer edge from the border (metres)."""
    x0, y0, x1, y1 = extent
    return max(1e7, 1000.0 * max(x1 - x0, y1 - y0))


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


def _outward(loop, nx, ny):
    """Offset direction of each loop point: side normals, diagonals at the corners."""
    j, i = loop[:, 0], loop[:, 1]
    out = np.zeros((len(loop), 2))
    out[j == 0, 1] = -1.0
    out[j == ny - 1, 1] = 1.0
    out[i == 0, 0] = -1.0
    out[i == nx - 1, 0] = 1.0
    return out


class MirroredRelief:
    """Heights of a DEM mirrored across its borders and blurred by a Gaussian of any width.

    The DEM is extended by reflection about its border samples (period ``2 (n - 1)``
    samples per axis: the extension is continuous and repeats the tile's character,
    not a flat plane). A pyramid of the extension, each level blurred by a Gaussian of
    one of its samples and halved (:func:`gaussian_blur`, mirrored: the same
    reflection), holds blurs of about ``2^j`` samples; a query between two levels
    interpolates linearly in ``sigma`` (:func:`bilinear`), and beyond the coarsest
    level the heights fade to the DEM's mean over one octave.

    Parameters
    ----------
    H : numpy.ndarray
        ``(ny, nx)`` heights.
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` of the samples' corners (the tile).
    """

    def __init__(self, H, extent):
        H = np.asarray(H, np.float64)
        self.shape = H.shape
        x0, y0, x1, y1 = (float(v) for v in extent)
        ny, nx = H.shape
        self.origin = (x0, y0)
        self.spacing = ((x1 - x0) / max(nx - 1, 1), (y1 - y0) / max(ny - 1, 1))
        # Blur of each level in level-0 samples (a blur of one sample of level j is 2^j of
        # level 0); the levels themselves are built when first asked for (an unblurred
        # query, as the overview camera's, needs none).
        self.levels, self.sigmas = [H], [0.0]
        size = min(H.shape)
        while size > 2:
            size = (size + 1) // 2
            self.sigmas.append(math.sqrt(self.sigmas[-1] ** 2 + 4.0 ** (len(self.sigmas) - 1)))
        self.mean = float(H.mean())

    def _level(self, j):
        """Level ``j`` of the pyramid (built up to it on first use)."""
        while len(self.levels) <= j:
            self.levels.append(gaussian_blur(self.levels[-1])[::2, ::2])
        return self.levels[j]

    def _mirror(self, x, y):
        """Level-0 sample coordinates ``(u, v)`` of world points, reflected into the tile."""
        out = []
        for c, o, d, n in ((x, self.origin[0], self.spacing[0], self.shape[1]),
                           (y, self.origin[1], self.spacing[1], self.shape[0])):
            period = 2.0 * max(n - 1, 1)
            u = np.mod((np.asarray(c, np.float64) - o) / d, period)
            out.append(np.where(u > n - 1, period - u, u))
        return out

    def heights(self, x, y, sigma):
        """Heights at world points ``(x, y)`` (arrays) blurred by ``sigma`` metres (a float).

        Returns
        -------
        numpy.ndarray
        """
        u, v = self._mirror(x, y)
        s = max(float(sigma), 0.0) / min(self.spacing)  # in level-0 samples

        def level(j):
            scale = 0.5 ** j
            return bilinear(self._level(j), v * scale, u * scale)

        top = len(self.sigmas) - 1
        if s >= self.sigmas[top]:
            # Past the coarsest level: to the mean over one octave of sigma.
            w = min(math.log2(s / self.sigmas[top]) if self.sigmas[top] > 0 else 1.0, 1.0)
            return (1.0 - w) * level(top) + w * self.mean
        j = int(np.searchsorted(self.sigmas, s, side="right")) - 1
        w = (s - self.sigmas[j]) / (self.sigmas[j + 1] - self.sigmas[j])
        return level(j) if w <= 0.0 else (1.0 - w) * level(j) + w * level(j + 1)


def gaussian_blur(H: np.ndarray, radius: int = 4) -> np.ndarray:
    """``H`` blurred by a Gaussian of one sample, truncated at ``radius`` samples, each axis
    mirrored about its end samples (``d c b | a b c d | c b a``).

    What ``scipy.ndimage.gaussian_filter(H, 1.0, mode="mirror")`` returns, bit for bit
    (the same normalized taps, summed in the same order: the centre, then the pairs
    from the outermost in), in numpy: importing ``scipy.ndimage`` took 0.17 s of every
    render process with a far field.
    """
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    taps = np.exp(-0.5 * x ** 2)
    taps = (taps / taps.sum())[radius:]  # taps[k]: weight at distance k
    out = np.asarray(H, np.float64)
    for axis in range(out.ndim):
        pad = [(0, 0)] * out.ndim
        pad[axis] = (radius, radius)
        padded = np.pad(out, pad, mode="reflect")  # numpy's "reflect" is scipy's "mirror"
        n = out.shape[axis]

        def shifted(k):
            index = [slice(None)] * out.ndim
            index[axis] = slice(radius + k, radius + k + n)
            return padded[tuple(index)]

        acc = shifted(0) * taps[0]
        for k in range(radius, 0, -1):
            acc = acc + (shifted(-k) + shifted(k)) * taps[k]
        out = acc
    return out


def bilinear(A: np.ndarray, v, u) -> np.ndarray:
    """``A`` interpolated bilinearly at fractional rows ``v`` and columns ``u``, samples
    beyond the edges repeating the edge's: ``scipy.ndimage.map_coordinates(A, [v, u],
    order=1, mode="nearest")`` bit for bit (the weights of the unclamped coordinates, the
    four corners summed in its order), in numpy (see :func:`gaussian_blur` for why)."""
    v, u = np.asarray(v, np.float64), np.asarray(u, np.float64)
    ny, nx = A.shape
    j0, i0 = np.floor(v).astype(np.int64), np.floor(u).astype(np.int64)
    fy, fx = v - j0, u - i0
    rows = (np.clip(j0, 0, ny - 1), np.clip(j0 + 1, 0, ny - 1))
    cols = (np.clip(i0, 0, nx - 1), np.clip(i0 + 1, 0, nx - 1))
    wy, wx = (1.0 - fy, fy), (1.0 - fx, fx)
    out = 0.0
    for a in range(2):
        for b in range(2):
            out = out + A[rows[a], cols[b]] * wy[a] * wx[b]
    return np.asarray(out, np.float64)


def _zip(a, b, off_a, off_b):
    """Triangles between two closed rings of loop indices: ``a`` and its subset ``b`` (both sorted).

    Each segment ``b_j -> b_j+1`` of the coarse ring faces the run of fine points
    from ``b_j`` to ``b_j+1``: a fan to ``b_j`` over the first half of the run, to
    ``b_j+1`` over the second, and one triangle joining the two apexes.
    """
    tris = []
    pos = {int(v): k for k, v in enumerate(a)}
    na, nb = len(a), len(b)
    for jb in range(nb):
        k0 = pos[int(b[jb])]
        k1 = pos[int(b[jb + 1])] if jb + 1 < nb else na
        mid = (k0 + k1 + 1) // 2
        for k in range(k0, k1):
            apex = jb if k < mid else (jb + 1) % nb
            tris.append((off_a + k % na, off_a + (k + 1) % na, off_b + apex))
        tris.append((off_a + mid % na, off_b + (jb + 1) % nb, off_b + jb))
    return tris


def far_field_mesh(node, reach=None):
    """Ground mesh of the far field of a heightfield node (see the module docstring).

    Parameters
    ----------
    node : arches_render.field.Heightfield
        A ``heightfield`` or ``implicit_heightfield`` node (world coordinates).
    reach : float, optional
        Distance of the outer ring from the border, metres (default :func:`default_reach`).

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
    R = getattr(node, "R_np", None)
    lift = np.zeros_like(H)
    if R is not None:
        bi = min(int(math.ceil(R / dx - 1e-9)) + 1, (nx - 1) // 2)
        bj = min(int(math.ceil(R / dy - 1e-9)) + 1, (ny - 1) // 2)
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

    # Rings from the border outwards.
    loop, corners = _loop(nx, ny)
    out = _outward(loop, nx, ny)
    border = (H + lift)[loop[:, 0], loop[:, 1]]  # the frame's border vertices, shared exactly
    xy = np.column_stack([x0 + loop[:, 1] * dx, y0 + loop[:, 0] * dy])
    spacing = min(dx, dy)
    relief = MirroredRelief(H, node.extent)
    s = ring_distances(max(dx, dy), reach, 1.0 + 0.7 / DETAIL)
    off = sum(len(v) for v in V)
    prev = None
    for sk in s:
        step = 1 << max(0, int(math.floor(math.log2(max(1.0, sk / (2.0 * DETAIL * spacing))))))
        keep = np.union1d(np.arange(0, len(loop), step), corners)
        p = xy[keep] + sk * out[keep]
        h = border[keep] if sk == 0.0 else relief.heights(p[:, 0], p[:, 1], 0.5 * sk / DETAIL)
        V.append(np.column_stack([p, h]))
        if prev is not None:
            pkeep, poff = prev
            # The coarser ring is a subset of the finer one (steps are powers of two).
            F.append(np.array(_zip(pkeep, keep, poff, off), np.int64))
        prev = (keep, off)
        off += len(keep)
    # Merged vertices (frame and first ring share theirs) and upward faces, so that
    # vertex normals are smooth across the seams.
    vertices, faces = merged_vertices(np.concatenate(V), np.concatenate(F))
    down = face_normals(vertices, faces)[:, 2] < 0
    faces[down] = faces[down][:, ::-1]
    return TriangleMesh(vertices, faces, vertex_normals(vertices, faces))


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

    @property
    def name(self) -> str:
        """``far_field<index>``: prefix of its shape ids."""
        return f"far_field{self.index}"

    def meshes(self) -> list:
        """``[(material, TriangleMesh)]``: the ground, then the sea ring if any."""
        out = [(self.material, far_field_mesh(self.node, self.reach))]
        if self.sea_level is not None:
            out.append((self.water_material, sea_ring_mesh(self.node.extent, self.sea_level, self.reach)))
        return out

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
    t.finish()
    return FarField(index, node, mat, float(reach), sea, water)
