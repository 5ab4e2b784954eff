"""Build rock tile sets once and reuse them, through the project's cache (:mod:`arches_render.cache`).

The key is a SHA-256 of the tile parameters (:meth:`TileParams.to_dict`, which
includes the seed) and of the digest of the tile format and of the source code of
the modules that generate tiles, so changing any of them builds new tiles instead
of reusing stale ones. Files are ``rocks-<key>.npz`` (:class:`RockStore`) in the
cache's ``rocks/`` folder. Loaded sets are also kept in memory for the life of
the process.
"""

from __future__ import annotations

from pathlib import Path

from arches_render import cache

from .rock_store import FORMAT, RockStore
from .tile_params import TileParams

__all__ = ["code_version", "cache_key", "build_tiles", "load_or_build", "clear_memory"]

_CODE_MODULES = ("seed_points", "corner_cubes", "anisotropic_voronoi", "contact_points",
                 "damped_erosion", "rock_meshes", "aperiodic_tiles", "periodic_tile", "tile_params",
                 "rock_store")
_MEMORY: dict[str, RockStore] = {}


def code_version() -> str:
    """Digest of the tile-generating source files and the tile format."""
    return cache.source_digest(Path(__file__).resolve().parent, _CODE_MODULES, FORMAT)


def cache_key(params: TileParams) -> str:
    """Cache key of a tile set: parameters (with the seed) and code version."""
    return cache.cache_key(params.to_dict(), code_version())


def build_tiles(params: TileParams, progress=None, workers: int | None = None) -> RockStore:
    """Build a tile set without the cache (aperiodic corner cubes or the periodic tile)."""
    # The builders are imported here, on a miss: they import numba and scikit-image
    # (0.25 s), which a scene whose tiles are in the cache never needs.
    if params.tiling == "periodic":
        from .periodic_tile import build_periodic_tile

        return build_periodic_tile(params, progress)
    from .aperiodic_tiles import build_aperiodic_tiles

    return build_aperiodic_tiles(params, progress, workers)


def _save(store: RockStore, path) -> None:
    with open(path, "wb") as f:
        store.save(f)


def load_or_build(params: TileParams, folder=None, progress=None, workers: int | None = None):
    """The tile set of ``params``: from memory, from the cache folder, or built and stored there.

    Parameters
    ----------
    params : TileParams
    folder : str or Path, optional
        Cache folder (created if missing); default the cache's ``rocks/`` folder.
    progress : callable, optional
        Passed to the builder on a miss.
    workers : int, optional
        Builder processes.

    Returns
    -------
    store : RockStore
    source : {'memory', 'disk', 'built'}
    """
    key = cache_key(params)
    if key in _MEMORY:
        return _MEMORY[key], "memory"
    folder = Path(folder) if folder is not None else cache.cache_dir("rocks")
    store, source = cache.load_or_build(folder / f"rocks-{key}.npz", RockStore.load,
                                        lambda: build_tiles(params, progress, workers), _save)
    _MEMORY[key] = store
    return store, source


def clear_memory() -> None:
    """Forget the tile sets loaded in this process (the disk cache stays)."""
    _MEMORY.clear()
