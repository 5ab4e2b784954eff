"""Digest of source files, for cache keys that must change when the generating code does.

Generators cache what they build (rock tiles, block tiles) on disk, across runs and
across checkouts of the project. Keying by parameters alone would serve a tile made by
older code after the code changed; adding this digest makes such entries misses.
"""

from __future__ import annotations

import hashlib
from pathlib import Path


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
