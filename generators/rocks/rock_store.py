"""A set of rock meshes as flat arrays (the content of a ``TILES.npz``).

Rocks are stored once each, grouped by *slot*: the region of the aperiodic
corner cubes they belong to (:func:`.corner_cubes.regions`, so a rock shared
by many corner cubes is stored once, as in the paper's stone counts) or the
single slot of the periodic tile. Coordinates are in cells, relative to the
slot's base point ``n * base`` (aperiodic) or to the tile origin (periodic).

Arrays (``R`` rocks): ``vertices``/``normals`` ``(P, 3)`` float32 and
``faces`` ``(F, 3)`` int32 (rock-local indices) with CSR starts ``vstart``,
``fstart``; per rock ``seed`` ``(R, 3)`` (its ``p_k``), ``radius`` (bounding
sphere about the seed, the "Voronoi embedding sphere"), ``uid``, ``slot``;
``anchors`` ``(R * K, 3)`` (anchor voxel centres, section 6); ``slot_start``
``(S + 1,)`` since rocks are sorted by slot.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass

import numpy as np

from arches_render.npzfile import write_npz

__all__ = ["RockStore", "FORMAT"]

FORMAT = "arches-rock-tiles/1"
_ARRAYS = ("vertices", "normals", "faces", "vstart", "fstart", "seed", "radius", "uid", "slot",
           "anchors", "slot_start")
# Meta entries that measure a build rather than describe the tiles (not written to files).
_TIMINGS = ("build_seconds", "worker_cpu_seconds")


@dataclass
class RockStore:
    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    vstart: np.ndarray
    fstart: np.ndarray
    seed: np.ndarray
    radius: np.ndarray
    uid: np.ndarray
    slot: np.ndarray
    anchors: np.ndarray
    slot_start: np.ndarray
    meta: dict

    def __len__(self):
        return len(self.radius)

    @property
    def n_anchors(self) -> int:
        return len(self.anchors) // max(len(self), 1)

    def rock(self, i: int):
        """``(vertices, faces, normals)`` of rock ``i`` in slot-local cells."""
        v0, v1 = self.vstart[i], self.vstart[i + 1]
        f0, f1 = self.fstart[i], self.fstart[i + 1]
        return self.vertices[v0:v1], self.faces[f0:f1], self.normals[v0:v1]

    def slot_rocks(self, s: int) -> np.ndarray:
        return np.arange(self.slot_start[s], self.slot_start[s + 1])

    @classmethod
    def from_rocks(cls, rocks: list, n_slots: int, meta: dict) -> "RockStore":
        """Pack ``rocks``: dicts with vertices, faces, normals, seed, radius, uid, slot, anchors."""
        rocks = sorted(rocks, key=lambda r: (r["slot"], int(r["uid"])))
        nv = np.array([len(r["vertices"]) for r in rocks], dtype=np.int64)
        nf = np.array([len(r["faces"]) for r in rocks], dtype=np.int64)
        cat = (lambda key, shape, dt: np.concatenate([r[key] for r in rocks]).astype(dt, copy=False)
               if rocks else np.zeros(shape, dt))
        slot = np.array([r["slot"] for r in rocks], dtype=np.int64)
        return cls(vertices=cat("vertices", (0, 3), np.float32),
                   normals=cat("normals", (0, 3), np.float32),
                   faces=cat("faces", (0, 3), np.int32),
                   vstart=np.concatenate([[0], np.cumsum(nv)]).astype(np.int64),
                   fstart=np.concatenate([[0], np.cumsum(nf)]).astype(np.int64),
                   seed=np.array([r["seed"] for r in rocks], dtype=np.float64).reshape(-1, 3),
                   radius=np.array([r["radius"] for r in rocks], dtype=np.float64),
                   uid=np.array([r["uid"] for r in rocks], dtype=np.uint64),
                   slot=slot,
                   anchors=cat("anchors", (0, 3), np.float32),
                   slot_start=np.searchsorted(slot, np.arange(n_slots + 1)).astype(np.int64),
                   meta=dict(meta, format=FORMAT, rocks=len(rocks), triangles=int(nf.sum())))

    def save(self, path) -> None:
        """Write an uncompressed ``.npz`` (fast to load) to an open file or path.

        The same tiles give the same bytes (:func:`arches_render.npzfile.write_npz`);
        the build's timings stay in memory only, since they differ run to run.
        """
        meta = {k: v for k, v in self.meta.items() if k not in _TIMINGS}
        write_npz(path, {"meta": np.array(json.dumps(meta)), **{k: getattr(self, k) for k in _ARRAYS}})

    @classmethod
    def load(cls, path) -> "RockStore":
        """Read a ``.npz`` written by :meth:`save`.

        Raises
        ------
        ValueError
            Not a rock tile file of this format.
        """
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                arrays = {k: z[k] for k in _ARRAYS}
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise ValueError(f"{getattr(path, 'name', path)}: not a rock tile file ({exc})") from None
        if meta.get("format") != FORMAT:
            raise ValueError(f"{path}: tile format {meta.get('format')!r}, expected {FORMAT!r}")
        return cls(meta=meta, **arrays)
