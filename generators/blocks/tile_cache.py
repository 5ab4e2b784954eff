"""A block tile: generation (section 4 of the paper), storage and a cache on disk.

:func:`build_tile` runs the whole pre-processing step of Paris et al. (2020,
Figure 3 left, Figure 4): periodic Poisson samples of the cube ``C = [0, s)^3``
(:mod:`.poisson_disc`), fracture discs of a structure type (:mod:`.fracture_discs`),
the cut neighbour graph and its clusters (:mod:`.fracture_graph`), and the
simplified hull planes of each cluster (:mod:`.block_hulls`). The result,
:class:`BlockTile`, holds only arrays (planes, per-block ranges, anchors): this is
what the paper measures as the memory of a tile (Table 2, < 0.6 MB).

Clusters of fewer than ``min_points`` samples (slivers clipped off by propagated
fractures) are not made into blocks; the paper turns degenerate clusters into
"thick polygon, line segment or point primitives", which at this size would be
invisible specks.

:func:`cached_tile` keys a tile by its parameters and the digest of the code that
builds it, and keeps it as a ``.npz`` in the ``blocks/`` folder of the project's
cache (:mod:`arches_render.cache`).

References
----------
Paris et al. (2020), sections 4 and 6 (Tables 1 and 2).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from arches_render import cache
from arches_render.atomic import atomic_path
from arches_render.npzfile import write_npz
from arches_render.scene.array_files import Spec, read_arrays

from .block_hulls import block_anchors, hull_planes
from .fracture_discs import STRUCTURES, fracture_discs
from .fracture_graph import fracture_clusters
from .poisson_disc import poisson_disc_periodic

__all__ = ["BlockTile", "TileParams", "build_tile", "save_tile", "load_tile", "cached_tile"]

FORMAT_VERSION = 4
# The modules whose code decides a tile's blocks (see TileParams.key).
_CODE_MODULES = ("poisson_disc", "fracture_discs", "fracture_graph", "block_hulls", "tile_cache")


@dataclass(frozen=True)
class TileParams:
    """Parameters of a block tile (names of the paper where it has them).

    ``size`` is the tile edge ``s`` (m); ``point_radius`` the Poisson radius ``r`` of
    the samples (m, default ``s / 28.5``: about 14,000 samples as in Table 1);
    ``spacing`` the fracture spacing of a set, ``disc_radius`` the radius scale
    ``r_i`` (defaults per structure, see :mod:`.fracture_discs`); ``axis`` the
    structure axis; ``obliquity`` (rhombohedral, degrees); ``column_sets``
    (columnar); ``joint_width`` the open width of the joints between blocks (m);
    ``merge_angle`` the hull simplification angle (degrees) and ``max_planes`` the
    most faces kept per block (besides its six box planes); ``min_points`` the
    smallest cluster made into a block; ``seed``.
    """

    structure: str = "equidimensional"
    size: float = 20.0
    point_radius: float | None = None
    spacing: float | None = None
    disc_radius: float | None = None
    axis: tuple = (0.0, 0.0, 1.0)
    obliquity: float = 25.0
    column_sets: int = 3
    joint_width: float = 0.1
    merge_angle: float = 20.0
    max_planes: int = 12
    min_points: int = 6
    seed: int = 0

    def validate(self):
        if self.structure not in STRUCTURES:
            raise ValueError(f"structure must be one of {', '.join(STRUCTURES)} (got {self.structure!r})")
        if not 1.0 <= self.size <= 1000.0:
            raise ValueError(f"tile size must be in [1, 1000] m (got {self.size:g})")
        r = self.radius()
        if not self.size / 60.0 <= r <= self.size / 4.0:
            raise ValueError(f"point_radius must be in [size/60, size/4] = [{self.size / 60:g}, "
                             f"{self.size / 4:g}] (got {r:g})")
        if not np.linalg.norm(self.axis) > 0:
            raise ValueError("axis must be a non-zero vector")
        if self.joint_width < 0:
            raise ValueError(f"joint_width must be >= 0 (got {self.joint_width:g})")

    def radius(self) -> float:
        return float(self.point_radius) if self.point_radius else self.size / 28.5

    def key(self) -> str:
        """Cache key: the parameters (seed included) and a digest of the generating code,
        so that a tile cached by older code is never served."""
        code = cache.source_digest(Path(__file__).resolve().parent, _CODE_MODULES, str(FORMAT_VERSION))
        return cache.cache_key(dict(self.__dict__), code)


@dataclass
class BlockTile:
    """Blocks of a periodic tile as plane arrays.

    ``normals`` ``(P, 3)`` and ``offsets`` ``(P,)``: all planes, block after block
    (block ``i`` owns ``start[i] : start[i] + count[i]``, largest face first);
    ``anchors`` ``(B, K, 3)``; ``centroid`` ``(B, 3)``; ``size`` the tile edge.
    Block positions are unwrapped: a block straddling a tile face extends beyond
    ``[0, s)`` and its centroid lies inside.
    """

    size: float
    normals: np.ndarray
    offsets: np.ndarray
    start: np.ndarray
    count: np.ndarray
    anchors: np.ndarray
    centroid: np.ndarray
    params: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)

    @property
    def n_blocks(self) -> int:
        return len(self.start)

    def planes(self, i):
        """``(normals, offsets)`` of block ``i``."""
        s, c = int(self.start[i]), int(self.count[i])
        return self.normals[s:s + c], self.offsets[s:s + c]

    def nbytes(self) -> int:
        """Bytes of the arrays that define the blocks' field functions (float32/uint32)."""
        return 4 * (self.normals.size + self.offsets.size + self.start.size + self.count.size
                    + self.anchors.size + self.centroid.size)

    def vertices(self, i) -> np.ndarray:
        """Corners of block ``i`` (the intersection of its half-spaces)."""
        from scipy.spatial import HalfspaceIntersection
        n, w = self.planes(i)
        return HalfspaceIntersection(np.hstack([n, -w[:, None]]), self.centroid[i]).intersections


def build_tile(params: TileParams, progress=None) -> BlockTile:
    """Generate a block tile (Paris et al. 2020, section 4).

    Parameters
    ----------
    params : TileParams
        Structure type and parameters.
    progress : callable, optional
        ``progress(done, total)`` over the pipeline's four stages.

    Returns
    -------
    BlockTile

    References
    ----------
    Paris et al. (2020), section 4, Figure 4, Table 1.
    """
    params.validate()
    step = progress or (lambda d, t: None)
    s, r = float(params.size), params.radius()
    pts = poisson_disc_periodic(s, r, seed=params.seed)
    step(1, 4)
    discs = fracture_discs(params.structure, s, seed=params.seed, spacing=params.spacing,
                           disc_radius=params.disc_radius, axis=params.axis,
                           obliquity=params.obliquity, column_sets=params.column_sets)
    step(2, 4)
    labels, u, gstats = fracture_clusters(pts, s, discs, threshold=2.0 * r)
    step(3, 4)
    # Samples reach the fracture planes (Poisson samples come arbitrarily close to
    # a plane), so hull faces lie on the fractures: half a joint in from each side.
    dilation = -0.5 * params.joint_width
    order = np.argsort(labels, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(np.bincount(labels))])
    normals, offsets, start, count, anchors, centroid, sizes = [], [], [], [], [], [], []
    n_planes = 0
    for c in range(len(bounds) - 1):
        idx = order[bounds[c]:bounds[c + 1]]
        if len(idx) < params.min_points:
            continue
        q = u[idx]
        try:
            n, w, verts = hull_planes(q, params.merge_angle, dilation, params.max_planes)
        except ValueError:
            continue  # coplanar samples: no volume
        if np.min(w - n @ q.mean(0)) < 0.02:
            continue  # a sliver thinner than its joints: nothing left once they open
        # The six supporting planes of the cluster's box come first: they leave
        # the polytope unchanged (up to the rounding R at extreme corners), keep
        # every offset polytope of a sharp wedge within the grown box, and let the
        # field's early exit reject a block from a point outside its box in at
        # most six planes.
        eye = np.vstack([np.eye(3), -np.eye(3)])
        n = np.vstack([eye, n])
        w = np.concatenate([np.concatenate([q.max(0), -q.min(0)]) + dilation, w])
        normals.append(n)
        offsets.append(w)
        start.append(n_planes)
        count.append(len(w))
        n_planes += len(w)
        anchors.append(block_anchors(q, verts))
        centroid.append(q.mean(0))
        sizes.append(len(idx))
    step(4, 4)
    if not start:
        raise ValueError("the fracturing left no block: increase spacing or decrease point_radius")
    stats = dict(points=len(pts), discs=len(discs), blocks=len(start),
                 mean_points_per_block=float(np.mean(sizes)),
                 samples_in_blocks=float(np.sum(sizes) / len(pts)),
                 mean_planes_per_block=float(n_planes / len(start)), dilation=dilation,
                 **gstats)
    return BlockTile(size=s, normals=np.concatenate(normals).astype(np.float32),
                     offsets=np.concatenate(offsets).astype(np.float32),
                     start=np.asarray(start, np.uint32), count=np.asarray(count, np.uint32),
                     anchors=np.asarray(anchors, np.float32), centroid=np.asarray(centroid, np.float32),
                     params=dict(params.__dict__), stats=stats)


def save_tile(tile: BlockTile, path) -> None:
    """Write a tile as ``.npz`` atomically."""
    meta = json.dumps({"version": FORMAT_VERSION, "size": tile.size, "params": tile.params,
                       "stats": tile.stats}, default=list)
    with atomic_path(Path(path)) as tmp:
        with open(tmp, "wb") as fh:
            write_npz(fh, dict(normals=tile.normals, offsets=tile.offsets, start=tile.start,
                               count=tile.count, anchors=tile.anchors, centroid=tile.centroid,
                               meta=np.array(meta)), compress=True)


#: The arrays of a tile file (:func:`arches_render.scene.array_files.read_arrays` schema).
TILE_SPECS = {"normals": Spec(("p", 3)), "offsets": Spec(("p",)), "start": Spec(("b",), "integer", lo=0),
              "count": Spec(("b",), "integer", lo=1), "anchors": Spec(("b", None, 3)),
              "centroid": Spec(("b", 3)), "meta": Spec((), "string")}


def load_tile(path) -> BlockTile:
    """Read a tile written by :func:`save_tile` (``ValueError`` if it is not one).

    The arrays are checked before use (shapes, finite values, plane ranges inside
    the plane arrays): the field gathers planes by ``start``/``count``, and an index
    outside the arrays would read out of bounds.
    """
    try:
        z = read_arrays(path, TILE_SPECS, "block tile")
        meta = json.loads(str(z.pop("meta")))
        if not isinstance(meta, dict) or meta.get("version") != FORMAT_VERSION:
            raise ValueError(f"tile format {meta.get('version') if isinstance(meta, dict) else meta!r} "
                             f"(expected {FORMAT_VERSION})")
        size = float(meta["size"])
        if not (np.isfinite(size) and size > 0):
            raise ValueError(f"tile size must be > 0 (got {size})")
        if len(z["start"]) == 0 or int((z["start"] + z["count"]).max()) > len(z["normals"]):
            raise ValueError(f"block plane ranges start + count must lie in [0, {len(z['normals'])}]")
        params, stats = dict(meta.get("params", {})), dict(meta.get("stats", {}))
    except (KeyError, TypeError, ValueError, json.JSONDecodeError) as exc:
        raise ValueError(f"{Path(getattr(path, 'name', None) or str(path)).name}: not a block tile ({exc})") from None
    return BlockTile(size=size, params=params, stats=stats,
                     **{k: v.astype(np.uint32 if k in ("start", "count") else np.float32) for k, v in z.items()})


def cached_tile(params: TileParams, folder=None, progress=None) -> BlockTile:
    """The tile of ``params`` from the cache, built and stored on a miss.

    Parameters
    ----------
    params : TileParams
    folder : str or Path, optional
        Cache folder; default the cache's ``blocks/`` folder.
    progress : callable, optional
        Passed to :func:`build_tile` on a miss.

    Returns
    -------
    BlockTile
    """
    params.validate()
    folder = Path(folder) if folder else cache.cache_dir("blocks")
    tile, _ = cache.load_or_build(folder / f"{params.structure}-{params.key()}.npz", load_tile,
                                  lambda: build_tile(params, progress), save_tile)
    return tile
