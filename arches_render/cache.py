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
    (:mod:`arches_render.atomic`). Every entry ends in a 64-byte seal: a magic
    and format version, the SHA-256 of the payload and of the entry's name (its
    key), and the payload's length. An entry whose seal is missing (written by
    another version, or cut short), whose checksum fails (truncated, garbage, a
    flipped bit) or whose payload the loader refuses is reported in one line on
    stderr and rebuilt over; a cache folder that cannot be written only costs the
    time of the next build.
Concurrency
    A builder holds an exclusive ``flock`` on ``.NAME.lock`` beside the entry while
    it builds and writes. A second process (another render, a Dask worker) asking
    for the same entry waits, then reads the entry the first one wrote: both get
    the same bits, the tile is built once, and the folder holds one entry. The
    kernel drops the lock of a killed process, so a kill never blocks the next run;
    the killed builder's temporary file is removed by the next write
    (:func:`arches_render.atomic.sweep_stale`). One process never waits: a
    multiprocessing worker still importing its parent's main script (a script
    without ``if __name__ == "__main__":``, re-run there by multiprocessing's rule)
    whose entry is locked, most likely by that parent waiting for it; it raises, the
    parent's pool breaks, and the parent builds the entry itself (the rock tiles'
    fallback) instead of both hanging.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import struct
import sys
from pathlib import Path

import platformdirs

from . import faults
from .atomic import atomic_path

try:  # POSIX; elsewhere concurrent builders both build (still one entry, by the atomic rename)
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

__all__ = ["ENV", "SEAL_MAGIC", "cache_root", "cache_dir", "source_digest", "cache_key", "load_or_build", "report"]

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


#: Seal of an entry: magic + format version, SHA-256 of payload and name, payload length.
SEAL_MAGIC = b"ARCACHE1"
_SEAL = struct.Struct("<8s32sQ16s")


def _digest(payload: bytes, name: str) -> bytes:
    return hashlib.sha256(payload + b"\0" + name.encode()).digest()


def _seal_file(tmp: Path, name: str) -> None:
    payload = tmp.read_bytes()
    with open(tmp, "ab") as f:
        f.write(_SEAL.pack(SEAL_MAGIC, _digest(payload, name), len(payload),
                           hashlib.sha256(name.encode()).digest()[:16]))


def _unseal(path: Path) -> tuple[bytes | None, str | None]:
    """The payload of entry ``path``, or ``None`` and why it cannot be used."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        return None, f"cannot be read ({exc.strerror})"
    if len(data) < _SEAL.size:
        return None, f"is truncated ({len(data)} bytes)"
    magic, digest, length, _ = _SEAL.unpack(data[-_SEAL.size:])
    if magic != SEAL_MAGIC:
        return None, "has no seal of this version (written by another version, or truncated)"
    payload = data[:-_SEAL.size]
    if length != len(payload):
        return None, f"is truncated or padded ({len(payload)} payload bytes, sealed {length})"
    if digest != _digest(payload, path.name):
        return None, "fails its checksum (damaged, or renamed from another entry)"
    return payload, None


def report(message: str) -> None:
    """Print one line about the cache on stderr (``arches-render: cache: MESSAGE``)."""
    print(f"arches-render: cache: {message}", file=sys.stderr, flush=True)


def _importing_parents_main() -> bool:
    """Whether this process is a multiprocessing worker still importing its parent's
    main script (a script without ``if __name__ == "__main__":`` runs again there).

    The standard library's own test (``multiprocessing.spawn._check_not_importing_main``
    reads the same flag); there is no public one.
    """
    import multiprocessing.process
    return bool(getattr(multiprocessing.process.current_process(), "_inheriting", False))


@contextlib.contextmanager
def _locked(path: Path):
    """Hold an exclusive lock for building entry ``path`` (no lock where the folder cannot be written)."""
    if fcntl is None:
        yield
        return
    try:
        _make_folder(path.parent)
        fd = os.open(path.parent / f".{path.name}.lock", os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        yield  # a read-only cache: no entry will be written, nothing to guard
        return
    try:
        if _importing_parents_main():
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                # Its parent, which started this worker, may hold the lock while it
                # waits for the worker: waiting here would hang both for ever.
                raise RuntimeError(f"{path}: a worker process re-running its parent's unguarded main "
                                   "script would wait for the parent's cache lock") from None
        else:
            fcntl.flock(fd, fcntl.LOCK_EX)
        faults.point("cache.locked")  # test-only kill point (arches_render.faults)
        yield
    finally:
        os.close(fd)  # closing drops the lock


def _load(path: Path, load):
    payload, why = _unseal(path)
    if payload is None:
        return None, why
    f = io.BytesIO(payload)
    f.name = str(path)
    try:
        return load(f), None
    except Exception as exc:  # the loader's refusal of a sealed payload: an older format
        text = str(exc).strip().splitlines()
        return None, f"cannot be loaded ({type(exc).__name__}: {text[0] if text else ''})"


def load_or_build(path, load, build, save):
    """The entry at ``path``: read with ``load``, or made with ``build`` and stored with ``save``.

    Parameters
    ----------
    path : str or Path
        The entry's file (usually ``cache_dir(kind) / f"...-{key}.npz"``).
    load : callable
        ``load(file) -> value``, ``file`` a binary file object holding the payload
        (its ``name`` is the entry's path); raises for a payload it cannot use,
        which is then rebuilt.
    build : callable
        ``build() -> value``.
    save : callable
        ``save(value, path)``, writing the payload to ``path`` (a temporary file
        that is then sealed and renamed into place).

    Returns
    -------
    (value, str)
        The value and where it came from: ``'disk'`` or ``'built'``.

    Notes
    -----
    A damaged entry is reported in one line on stderr (:func:`report`) and rebuilt.
    """
    path = Path(path)
    if path.is_file():
        value, why = _load(path, load)
        if why is None:
            return value, "disk"
    with _locked(path):
        # Another process may have built the entry while this one waited for the lock.
        if path.is_file():
            value, why = _load(path, load)
            if why is None:
                return value, "disk"
            report(f"{path} {why}: rebuilding it")
        value = build()
        try:
            _make_folder(path.parent)
            with atomic_path(path) as tmp:
                save(value, tmp)
                _seal_file(Path(tmp), path.name)
        except OSError:
            pass  # a read-only cache only costs time
    return value, "built"
