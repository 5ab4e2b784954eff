"""Atomic file output: a reader sees the old file or the complete new one, never a half-written one.

Every writer of arches-render (EXR, PNG, reports, golden metadata) goes through
:func:`atomic_write` or :func:`atomic_path`. Both write a temporary file in the
destination folder (so the final :func:`os.replace` stays on one file system and
is atomic on POSIX and Windows), flush it to disk, and only then rename it onto
the destination. On any exception the temporary file is removed and the
destination is left untouched.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import IO, Iterator

__all__ = ["atomic_write", "atomic_path"]

# os.umask can only be read by setting it; doing that once at import keeps the
# process-wide change out of concurrent writer threads.
_UMASK = os.umask(0o022)
os.umask(_UMASK)


def _temp_name(path: Path) -> tuple[int, str]:
    # The real suffix stays last because some writers (Mitsuba's Bitmap,
    # imageio, ...) choose the format from the extension of the name they get.
    # The leading dot hides the file from globbing and ``ls`` while it exists.
    return tempfile.mkstemp(prefix=f".{path.stem}.tmp-", suffix=path.suffix, dir=path.parent)


def _fsync_dir(folder: Path) -> None:
    # Makes the rename itself durable; not every platform lets one open a folder.
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _discard(tmp: str) -> None:
    with contextlib.suppress(FileNotFoundError):
        os.unlink(tmp)


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb", **open_kwargs) -> Iterator[IO]:
    """Open a temporary file that replaces ``path`` when the ``with`` block succeeds.

    Parameters
    ----------
    path : str or os.PathLike
        Destination file. Its folder must exist.
    mode : str, optional
        ``'wb'`` (default) or ``'w'`` (text); only write modes are accepted.
    **open_kwargs
        Passed to :func:`open` (e.g. ``encoding='utf-8'``, ``newline=''``).

    Yields
    ------
    file object
        The open temporary file; its ``name`` is the temporary path, which ends
        with the suffix of ``path``.

    Raises
    ------
    ValueError
        When ``mode`` is not a write mode.

    Notes
    -----
    The data is flushed and ``fsync``-ed before :func:`os.replace`, so a crash
    can not leave a renamed but empty file behind. The temporary file is created
    with ``mkstemp``'s private permissions; they are widened to the usual
    ``0o666 & ~umask`` so outputs look like files written with :func:`open`.

    Examples
    --------
    >>> with atomic_write("out/readme.txt", "w", encoding="utf-8") as f:  # doctest: +SKIP
    ...     f.write("complete or absent")
    """
    if mode not in ("w", "wb", "wt", "xb", "x"):
        raise ValueError(f"atomic_write needs a write mode ('w' or 'wb'), got {mode!r}")
    mode = mode.replace("x", "w")
    path = Path(path)
    fd, tmp = _temp_name(path)
    os.close(fd)
    try:
        # Re-opened by name (not os.fdopen) so that f.name is the path.
        with open(tmp, mode, **open_kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        _publish(tmp, path)
    except BaseException:
        _discard(tmp)
        raise


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Give a temporary path for a library that writes by file name, then publish it.

    Parameters
    ----------
    path : str or os.PathLike
        Destination file. Its folder must exist.

    Yields
    ------
    pathlib.Path
        An (empty, already created) temporary file next to ``path`` whose name
        ends with the suffix of ``path``; the ``with`` body lets the library
        overwrite it.

    Notes
    -----
    When the body returns, the temporary file is ``fsync``-ed and renamed onto
    ``path``; when it raises, or leaves no file, nothing is published and the
    temporary file is removed. Prefer :func:`atomic_write` when the library can
    write to a file object.
    """
    path = Path(path)
    fd, tmp = _temp_name(path)
    os.close(fd)
    try:
        yield Path(tmp)
        if not os.path.isfile(tmp):
            raise FileNotFoundError(f"the writer did not produce {tmp} (destination {path})")
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        _publish(tmp, path)
    except BaseException:
        _discard(tmp)
        raise


def _publish(tmp: str, path: Path) -> None:
    with contextlib.suppress(OSError):
        os.chmod(tmp, 0o666 & ~_UMASK)
    os.replace(tmp, path)
    _fsync_dir(path.parent)
