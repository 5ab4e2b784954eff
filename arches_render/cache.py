"""One on-disk cache for what the generators build (rock tiles, block tiles, ...).

Folder
    ``$ARCHES_RENDER_CACHE`` when set, else the user's cache directory
    (``platformdirs.user_cache_dir("arches-render")``: ``~/.cache/arches-render`` on
    Linux, or under ``$XDG_CACHE_HOME``); one sub-folder per kind of entry
    (``rocks/``, ``blocks/``). A cache folder this module creates gets a
    ``.gitignore``, so a cache pointed into a checkout never reaches version control.
Keys
    :func:`cache_key`: a SHA-256 of the parameters (seed included) and of
    :func:`source_digest`, a digest of the source code of the modules that generate
    the entry and of its file format. Keying by parameters alone would serve an entry
    made by older code after the code changed (stale tiles once broke two goldens);
    with the digest such entries are misses.
Entries
    :func:`load_or_build` reads an entry, or builds it and writes it atomically
    (:mod:`arches_render.atomic`). An entry that cannot be read (damaged, foreign,
    older format) is rebuilt over; a cache folder that cannot be written only costs
    the time of the next build.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import platformdirs

from .atomic import atomic_path

__all__ = ["ENV", "cache_root", "cache_dir", "source_digest", "cache_key", "load_or_build"]

#: The environment variable naming the cache folder.
ENV = "ARCHES_RENDER_CACHE"


def cache_root() -> Path:
    """``$ARCHES_RENDER_CACHE``, else the user's cache directory for arches-render."""
    env = os.environ.get(ENV)
    return Path(env) if env else Path(platformdirs.user_cache_dir("arches-render", appauthor=False))


def cache_dir(kind: str) -> Path:
    """The folder of one kind of entry, e.g. ``cache_dir("rocks")`` (not created here)."""
    return cache_root() / kind


def source_digest(folder, modules, salt: str = "") -> str:
    """SHA-256 (16 hex digits) of ``salt`` and the files ``folder/NAME.py`` for NAME in ``modules``.

    Parameters
    ----------
    folder : str or os.PathLike
        Folder of the modules (usually ``Path(__file__).parent``).
    modules : iterable of str
        Module names, in a fixed order.
    salt : str
        Extra text, e.g. a file-format version.

    Returns
    -------
    str
    """
    h = hashlib.sha256(salt.encode())
    for name in modules:
        h.update((Path(folder) / f"{name}.py").read_bytes())
    return h.hexdigest()[:16]


def cache_key(params: dict, code: str) -> str:
    """Key of an entry: SHA-256 (24 hex digits) of its parameters and its code digest.

    Parameters
    ----------
    params : dict
        JSON-serializable parameters (tuples become lists), seed included.
    code : str
        :func:`source_digest` of the generating modules.

    Returns
    -------
    str
    """
    blob = json.dumps({"params": params, "code": code}, sort_keys=True, default=list)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def _make_folder(folder: Path) -> None:
    """Create ``folder``; the topmost folder created (the cache root, or ``folder``) gets a ``.gitignore``."""
    if folder.is_dir():
        return
    root = cache_root()
    top = root if root in folder.parents and not root.exists() else folder
    folder.mkdir(parents=True, exist_ok=True)
    (top / ".gitignore").write_text("# arches-render cache\n*\n")


def load_or_build(path, load, build, save):
    """The entry at ``path``: read with ``load``, or made with ``build`` and stored with ``save``.

    Parameters
    ----------
    path : str or Path
        The entry's file (usually ``cache_dir(kind) / f"...-{key}.npz"``).
    load : callable
        ``load(path) -> value``; raises ``ValueError`` (or ``OSError``) for a file it
        cannot use, which is then rebuilt.
    build : callable
        ``build() -> value``.
    save : callable
        ``save(value, path)``, writing to a temporary path renamed into place.

    Returns
    -------
    (value, str)
        The value and where it came from: ``'disk'`` or ``'built'``.
    """
    path = Path(path)
    if path.is_file():
        try:
            return load(path), "disk"
        except (OSError, ValueError):
            pass  # damaged, foreign or stale: rebuild over it
    value = build()
    try:
        _make_folder(path.parent)
        with atomic_path(path) as tmp:
            save(value, tmp)
    except OSError:
        pass  # a read-only cache only costs time
    return value, "built"
