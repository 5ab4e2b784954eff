"""Rock piles from tiles: virtual tiling of space and selection by a support object (section 6).

Tiling. Corner cubes sit with their corners on the integer lattice (edge ``n``
cells); every lattice point gets a random colour (:func:`.corner_cubes.lattice_colours`)
and every region of the lattice (vertex, edge, face, centre) its rocks from the
tile set. The periodic tile simply repeats with its period.

Selection. A support object ``O`` gives a point membership function ``s(p)``:
an implicit field node of the scene (``f > 0`` inside, evaluated with
:func:`arches_render.field.evaluate`), a procedural shape, or a closed triangle
mesh (inside tests by ray queries through trimesh and Embree). Every rock has
anchor points ``A = {a_i}``, centres of its voxels plus its seed ``p_k``; a rock
is instantiated when the fraction of its anchors inside ``O`` reaches a
threshold (rocks that would float with only a small part in ``O`` are dropped),
and rocks deeper in ``O`` than twice the largest Voronoi embedding sphere
radius are eliminated (section 6; Arches, section 5).

Depth. For field nodes ``f / L`` (``L`` the node's Lipschitz bound) is a lower
bound of the distance to the surface, and for the procedural shapes the
exact signed distance is used; a mesh has no cheap distance, so a rock is too
deep when the 26 points at ``2 R_max`` around its seed (axes, face and cube
diagonals) are all inside.

We store a subsample of each rock's voxel centres (``anchors`` of the tile
parameters, 32 by default) instead of all of them: the inside fraction is then
estimated to a few per cent, and selection of thousands of rocks stays cheap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arches_render.field import evaluate

from . import corner_cubes as cc
from .rock_store import RockStore
from .seed_points import hash_uniform

__all__ = ["FieldSupport", "ShapeSupport", "MeshSupport", "SHAPES", "candidate_rocks", "select_rocks",
           "RockInstances", "instance_buffers", "MAX_CANDIDATES"]

#: Upper bound on rocks considered in one pile's extent (guards against a tiny rock_size).
MAX_CANDIDATES = 4_000_000
SHAPES = ("sphere", "box", "cylinder", "torus")


class FieldSupport:
    """An implicit field node as support: ``s(p) = f(p) > 0``, depth ``>= f(p) / L``."""

    kind = "field"

    def __init__(self, node):
        self.node = node

    def bounds(self):
        lo, hi = self.node.bounds()
        return np.asarray(lo, float), np.asarray(hi, float)

    def value(self, points):
        return evaluate(self.node, points).astype(np.float64)

    def inside(self, points):
        return self.value(points) > 0

    def depth(self, points):
        return self.value(points) / float(self.node.lipschitz)


class ShapeSupport:
    """A procedural shape: exact signed distance (positive inside).

    ``sphere``: center, radius. ``box``: center, size. ``cylinder`` (axis +Z):
    center, radius, height. ``torus`` (axis +Z): center, radius (major),
    thickness (minor radius).
    """

    kind = "shape"

    def __init__(self, shape: str, center, radius=1.0, size=(1, 1, 1), height=1.0, thickness=0.25):
        if shape not in SHAPES:
            raise ValueError(f"shape must be one of {', '.join(SHAPES)} (got {shape!r})")
        self.shape, self.center = shape, np.asarray(center, float)
        self.radius, self.size = float(radius), np.asarray(size, float)
        self.height, self.thickness = float(height), float(thickness)

    def bounds(self):
        e = {"sphere": np.full(3, self.radius), "box": self.size / 2,
             "cylinder": np.array([self.radius, self.radius, self.height / 2]),
             "torus": np.array([self.radius + self.thickness] * 2 + [self.thickness])}[self.shape]
        return self.center - e, self.center + e

    def depth(self, points):
        q = np.asarray(points, float) - self.center
        if self.shape == "sphere":
            return self.radius - np.linalg.norm(q, axis=1)
        if self.shape == "box":
            d = np.abs(q) - self.size / 2
            outside = np.linalg.norm(np.maximum(d, 0), axis=1) + np.minimum(d.max(axis=1), 0)
            return -outside
        if self.shape == "cylinder":
            d = np.stack([np.hypot(q[:, 0], q[:, 1]) - self.radius, np.abs(q[:, 2]) - self.height / 2], 1)
            return -(np.linalg.norm(np.maximum(d, 0), axis=1) + np.minimum(d.max(axis=1), 0))
        ring = np.hypot(q[:, 0], q[:, 1]) - self.radius
        return self.thickness - np.hypot(ring, q[:, 2])

    def inside(self, points):
        return self.depth(points) > 0


class MeshSupport:
    """A closed triangle mesh: inside tests by ray queries (trimesh, through Embree when installed)."""

    kind = "mesh"

    def __init__(self, mesh):
        if not mesh.is_watertight:
            raise ValueError("the support mesh must be closed (watertight) for inside tests")
        self.mesh = mesh

    def bounds(self):
        return np.asarray(self.mesh.bounds[0], float), np.asarray(self.mesh.bounds[1], float)

    def inside(self, points):
        return np.asarray(self.mesh.contains(np.asarray(points, float)), dtype=bool)

    def depth(self, points):
        return None


def _ranges(starts, counts):
    """Concatenation of ``arange(s, s + c)`` for every pair (vectorised)."""
    counts = np.asarray(counts, np.int64)
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, np.int64)
    shift = np.repeat(np.asarray(starts, np.int64) - (np.cumsum(counts) - counts), counts)
    return np.arange(total, dtype=np.int64) + shift


def candidate_rocks(store: RockStore, lo_cells, hi_cells, colour_seed: int):
    """Rocks of the virtual tiling whose seed lies in the box ``[lo, hi)`` (cell units).

    Parameters
    ----------
    store : RockStore
    lo_cells, hi_cells : (3,) float
        The extent in cells (world origin at cell 0).
    colour_seed : int
        Seed of the lattice colouring (aperiodic tiles).

    Returns
    -------
    ids : (K,) int64
        Rock indices into ``store``.
    offsets : (K, 3) float64
        Cell offset of each rock's slot (add to its slot-local coordinates).
    """
    lo, hi = np.asarray(lo_cells, float), np.asarray(hi_cells, float)
    P = float(store.meta["cells_per_period"])
    L0 = np.floor(lo / P).astype(np.int64) - 1
    L1 = np.floor(hi / P).astype(np.int64) + 1
    if store.meta["tiling"] == "periodic":
        per_cell = len(store) / P ** 3
    else:
        per_cell = float(np.mean(store.meta["params"]["seeds"]["seeds_per_cell"]))
    count_est = float(np.prod(np.maximum(hi - lo, 0))) * per_cell
    if count_est > MAX_CANDIDATES:
        raise ValueError(f"the extent holds about {count_est:.3g} rock positions (limit "
                         f"{MAX_CANDIDATES:,}); use a larger rock_size or a smaller extent")
    grid = np.stack(np.meshgrid(*(np.arange(a, b + 1) for a, b in zip(L0, L1)), indexing="ij"),
                    -1).reshape(-1, 3)
    ids, offs = [], []
    if store.meta["tiling"] == "periodic":
        slots = [(np.zeros(len(grid), np.int64), grid)]
    else:
        slots = []
        for mask in cc.REGION_MASKS:
            code = cc.owner_colour_codes(np.full(len(grid), mask), grid,
                                         lambda p: cc.lattice_colours(p, colour_seed))
            slots.append((cc.region_index(mask, code), grid))
    for slot, base in slots:
        counts = store.slot_start[slot + 1] - store.slot_start[slot]
        r = _ranges(store.slot_start[slot], counts)
        off = np.repeat(base * P, counts, axis=0).astype(np.float64)
        p = store.seed[r] + off
        keep = np.all((p >= lo) & (p < hi), axis=1)
        ids.append(r[keep])
        offs.append(off[keep])
    return np.concatenate(ids), np.concatenate(offs)


_DIRS = np.array([d for d in np.ndindex(3, 3, 3) if d != (1, 1, 1)], float) - 1.0
_DIRS /= np.linalg.norm(_DIRS, axis=1, keepdims=True)


def select_rocks(store: RockStore, ids, offsets, support, cell: float, origin, min_inside: float = 0.5):
    """Rocks to instantiate: enough anchors inside the support, not too deep (section 6).

    Parameters
    ----------
    store : RockStore
    ids, offsets : arrays
        Candidates from :func:`candidate_rocks`.
    support : FieldSupport, ShapeSupport or MeshSupport
    cell : float
        Metres per cell (the scene's ``rock_size``).
    origin : (3,) float
        World position of cell 0.
    min_inside : float
        Threshold on the fraction of anchors (and seed) inside the support.

    Returns
    -------
    keep : (K,) bool
    stats : dict
        Counts of candidates, near-surface rocks, rocks dropped as floating
        and as too deep.
    """
    origin = np.asarray(origin, float)
    r_max = float(store.radius.max()) * cell if len(store) else 0.0
    seeds_w = origin + (store.seed[ids] + offsets) * cell
    radius_w = store.radius[ids] * cell
    keep = np.zeros(len(ids), dtype=bool)
    near = np.ones(len(ids), dtype=bool)
    depth = support.depth(seeds_w) if len(ids) else np.zeros(0)
    if depth is not None:
        # Wholly outside (no anchor can be inside) or wholly too deep: decided by the seed alone.
        near = (depth > -radius_w) & (depth <= 2.0 * r_max)
    sel = np.nonzero(near)[0]
    K = store.n_anchors
    if len(sel):
        a_idx = (ids[sel, None] * K + np.arange(K)).ravel()
        anchors = origin + (store.anchors[a_idx].astype(np.float64) + np.repeat(offsets[sel], K, 0)) * cell
        inside = support.inside(np.concatenate([anchors, seeds_w[sel]])).astype(np.float64)
        frac = (inside[:len(anchors)].reshape(-1, K).sum(axis=1) + inside[len(anchors):]) / (K + 1)
        ok = frac >= min_inside
        if depth is None and ok.any():
            s = sel[ok]
            probe = (seeds_w[s, None, :] + 2.0 * r_max * _DIRS[None]).reshape(-1, 3)
            deep = support.inside(probe).reshape(len(s), -1).all(axis=1)
            ok[np.nonzero(ok)[0][deep]] = False
        keep[sel[ok]] = True
    floating = int(len(sel) - keep.sum())
    stats = dict(candidates=int(len(ids)), near_surface=int(len(sel)), floating_or_deep=floating,
                 instanced=int(keep.sum()), r_max=r_max)
    return keep, stats


@dataclass
class RockInstances:
    """Selected rocks of one pile: store indices, slot offsets (cells), metres per cell, origin."""

    store: RockStore
    ids: np.ndarray
    offsets: np.ndarray
    cell: float
    origin: np.ndarray

    def __len__(self):
        return len(self.ids)

    def tiles(self) -> np.ndarray:
        """Index of the corner cube (or periodic tile) holding each rock's seed."""
        P = float(self.store.meta["cells_per_period"])
        return np.floor((self.store.seed[self.ids] + self.offsets) / P).astype(np.int64)


def instance_buffers(inst: RockInstances, max_triangles: int = 250_000, texture_offset: float = 97.0):
    """Flat world-space vertex buffers of the rocks, merged per tile.

    Rocks are grouped by the tile holding their seed; neighbouring tiles are
    packed together until a buffer holds ``max_triangles`` (a tile is never
    split). Transforms are baked into the vertices: no instancing.

    Parameters
    ----------
    inst : RockInstances
    max_triangles : int
    texture_offset : float
        Each rock's object-space texture coordinates are its vertices relative
        to its seed plus a random offset in ``[0, texture_offset)^3`` metres, so
        rocks show different parts of a triplanar texture and keep them.

    Returns
    -------
    list of dict
        ``positions`` (P, 3) float32 world, ``normals`` (P, 3) float32,
        ``faces`` (F, 3) uint32, ``objp`` (P, 3) float32, ``rocks`` (count).
    """
    st = inst.store
    if len(inst) == 0:
        return []
    tiles = inst.tiles()
    order = np.lexsort(tiles.T[::-1])
    ids, offs, tiles = inst.ids[order], inst.offsets[order], tiles[order]
    nf = st.fstart[ids + 1] - st.fstart[ids]
    new_tile = np.r_[True, np.any(tiles[1:] != tiles[:-1], axis=1)]
    tile_no = np.cumsum(new_tile) - 1
    tile_tris = np.bincount(tile_no, weights=nf)
    tile_chunk = np.zeros(len(tile_tris), np.int64)
    acc, chunk = 0, 0
    for t, c in enumerate(tile_tris):
        if acc and acc + c > max_triangles:
            chunk, acc = chunk + 1, 0
        tile_chunk[t] = chunk
        acc += c
    rock_chunk = tile_chunk[tile_no]
    jitter = np.stack([hash_uniform(st.uid[ids], 20 + a) for a in range(3)], 1) * texture_offset
    out = []
    for c in range(chunk + 1):
        sel = np.nonzero(rock_chunk == c)[0]
        r = ids[sel]
        nv = st.vstart[r + 1] - st.vstart[r]
        fc = st.fstart[r + 1] - st.fstart[r]
        vi = _ranges(st.vstart[r], nv)
        fi = _ranges(st.fstart[r], fc)
        local = st.vertices[vi].astype(np.float64)
        rep_off = np.repeat(offs[sel], nv, axis=0)
        pos = inst.origin + (local + rep_off) * inst.cell
        objp = (local - np.repeat(st.seed[r], nv, axis=0)) * inst.cell + np.repeat(jitter[sel], nv, axis=0)
        base = np.repeat(np.cumsum(nv) - nv, fc)
        faces = st.faces[fi].astype(np.int64) + base[:, None]
        out.append(dict(positions=pos.astype(np.float32), normals=st.normals[vi],
                        faces=faces.astype(np.uint32), objp=objp.astype(np.float32), rocks=len(r)))
    return out
