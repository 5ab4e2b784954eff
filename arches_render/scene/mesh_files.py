"""Mesh files (PLY, OBJ, STL) that scenes name: read once and checked before use.

``[[meshes]] file`` (rendered by Mitsuba's own PLY/OBJ readers) and a rock pile's
``support = { mesh = ... }`` (inside tests through trimesh) come from files that
another program wrote. :func:`read_mesh` reads one with trimesh (a maintained
reader of all three formats) and refuses, in one line naming the file and the
element, what would otherwise end in a traceback, a Mitsuba error or a silently
empty image:

* an empty, truncated or garbage file, or one whose content is not its extension's
  format (trimesh's error, first line);
* no triangle at all, or only triangles of zero area;
* a face index outside the vertex list;
* NaN or infinite vertex coordinates (the first one's index);
* an open (not watertight) mesh where closure is needed (``closed=True``: inside
  tests of a rock-pile support).

A mesh with some degenerate triangles among valid ones is accepted (renderers and
inside tests skip them); :func:`read_mesh` counts them in its result.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["MeshInfo", "read_mesh"]


@dataclass
class MeshInfo:
    """A checked mesh: the trimesh object, and its count of zero-area triangles."""

    mesh: object
    degenerate: int


def _first_line(exc) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def read_mesh(path, t, key: str, closed: bool = False, process: bool = False) -> MeshInfo:
    """Read and check the mesh file ``path`` named by key ``key`` of table ``t``.

    Parameters
    ----------
    path : str or Path
        The file (already resolved by :func:`arches_render.scene.paths.scene_file`).
    t : arches_render.scene.validate.Table
        For the error messages (scene file and key path).
    key : str
    closed : bool
        Require a closed (watertight) surface.
    process : bool
        Let trimesh merge duplicate vertices and drop degenerate faces (what an
        inside test wants); the checks run on the file's own arrays first.

    Returns
    -------
    MeshInfo

    Raises
    ------
    SceneError
        See the module docstring.
    """
    import trimesh  # on use: slow to import, only scenes with mesh files need it

    path = Path(path)
    name = path.name
    if path.stat().st_size == 0:
        raise t.error(key, f"{name}: the mesh file is empty")
    try:
        mesh = trimesh.load_mesh(path, process=False, force="mesh")
    except Exception as exc:  # every reader failure is a bad file, not our bug
        raise t.error(key, f"{name}: cannot read the mesh ({_first_line(exc)}); "
                           f"it must be a valid {path.suffix.lower()[1:].upper()} triangle mesh") from None
    v = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
    f = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if len(f) == 0 or len(v) == 0:
        raise t.error(key, f"{name}: the mesh has no triangles ({len(v)} vertices, {len(f)} faces)")
    if f.min() < 0 or f.max() >= len(v):
        raise t.error(key, f"{name}: a face refers to vertex {int(f.max() if f.max() >= len(v) else f.min())}; "
                           f"indices must be in [0, {len(v) - 1}]")
    bad = ~np.all(np.isfinite(v), axis=1)
    if bad.any():
        raise t.error(key, f"{name}: {int(bad.sum())} vertices have NaN or infinite coordinates "
                           f"(first: vertex {int(np.argmax(bad))}); all must be finite")
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    scale = float(np.max(np.ptp(v, axis=0))) or 1.0
    degenerate = int(np.count_nonzero(area <= 1e-12 * scale * scale))
    if degenerate == len(f):
        raise t.error(key, f"{name}: all {len(f)} triangles have zero area; the mesh must have a surface")
    if process:
        mesh = trimesh.Trimesh(v, f, process=True)
    if closed and not mesh.is_watertight:
        raise t.error(key, f"{name}: the mesh must be closed (watertight) for inside tests "
                           f"({len(mesh.faces)} faces, some edges have one face only)")
    return MeshInfo(mesh, degenerate)
