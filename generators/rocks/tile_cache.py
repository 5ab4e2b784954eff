"""Build rock tile sets once and reuse them: an on-disk cache keyed by parameters, seed and code.

The key is a SHA-256 of the tile parameters (:meth:`TileParams.to_dict`, which
includes the seed), of the tile format and of the source code of the modules
that generate tiles, so changing any of them builds new tiles instead of
reusing stale ones. Files are ``rocks-<key>.npz`` (:class:`RockStore`) in the
cache folder: ``$ARCHES_CACHE_DIR`` when set, else ``.cache/`` beside the
scene file. A ``.gitignore`` is put in a cache folder this module creates, so
caches never end up in version control. Writes are atomic; a damaged file is
rebuilt. Loaded sets are also kept in memory for the life of the process.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from .rock_store import FORMAT, RockStore
from .tile_params import TileParams

__all__ = ["code_version", "cache_key", "cache_dir", "build_tiles", "load_or_build", "clear_memory"]

_CODE_MODULES = ("seed_points", "corner_cubes", "anisotropic_voronoi", "contact_points",
                 "damped_erosion", "rock_meshes", "aperiodic_tiles", "periodic_tile", "tile_params",
                 "rock_store")
_MEMORY: dict[str, RockStore] = {}


def code_version() -> str:
    """Hash of the tile-generating source files and the tile format."""
    from arches_render.source_digest import source_digest
    return source_digest(Path(__file__).resolve().parent, _CODE_MODULES, FORMAT)


def cache_key(params: TileParams) -> str:
    """Cache key of a tile set: parameters (with the seed) and code version."""
    blob = json.dumps({"params": params.to_dict(), "code": code_version()}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def cache_dir(scene_file=None) -> Path:
    """``$ARCHES_CACHE_DIR``, else ``.cache/`` beside ``scene_file`` (or the working folder)."""
    env = os.environ.get("ARCHES_CACHE_DIR")
    if env:
        return Path(env)
    base = Path(scene_file).resolve().parent if scene_file is not None else Path.cwd()
    return base / ".cache"


def build_tiles(params: TileParams, progress=None, workers: int | None = None) -> RockStore:
    """Build a tile set without the cache (aperiodic corner cubes or the periodic tile)."""
    if params.tiling == "periodic":
        from .periodic_tile import build_periodic_tile
        return build_periodic_tile(params, progress)
    from .aperiodic_tiles import build_aperiodic_tiles
    return build_aperiodic_tiles(params, progress, workers)


def load_or_build(params: TileParams, folder, progress=None, workers: int | None = None):
    """The tile set of ``params``: from memory, from ``folder``, or built and stored there.

    Parameters
    ----------
    params : TileParams
    folder : str or Path
        Cache folder (created if missing).
    progress : callable, optional
        Passed to the builder on a miss.
    workers : int, optional
        Builder processes.

    Returns
    -------
    store : RockStore
    source : {'memory', 'disk', 'built'}
    """
    from arches_render.atomic import atomic_path
    key = cache_key(params)
    if key in _MEMORY:
        return _MEMORY[key], "memory"
    folder = Path(folder)
    path = folder / f"rocks-{key}.npz"
    if path.is_file():
        try:
            store = RockStore.load(path)
            _MEMORY[key] = store
            return store, "disk"
        except ValueError:
            pass                      # damaged or foreign: rebuild over it
    store = build_tiles(params, progress, workers)
    if not folder.is_dir():
        folder.mkdir(parents=True, exist_ok=True)
        (folder / ".gitignore").write_text("# arches-render tile cache\n*\n")
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            store.save(f)
    _MEMORY[key] = store
    return store, "built"


def clear_memory() -> None:
    """Forget the tile sets loaded in this process (the disk cache stays)."""
    _MEMORY.clear()
