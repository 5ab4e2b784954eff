"""Atomic file output: a reader sees the old file or the complete new one, never a half-written one.

Every writer of arches-render (EXR, PNG, reports, golden metadata) goes through
:func:`atomic_write` or :func:`atomic_path`. Both write a temporary file in the
destination folder (so the final :func:`os.replace` stays on one file system and
is atomic on POSIX and Windows), flush it to disk, and only then rename it onto
the destination. On any exception the temporary file is removed and the
destination is left untouched.

A process killed outright (SIGKILL, the OOM killer, a power cut) cannot remove its
temporary file. Temporary names therefore carry the host and process id
(``.NAME.tmp-HOST-PID-XXXX.ext``), and every atomic write into a folder first
removes the temporary files and folders (:func:`temp_dir`) there of processes of
this host that no longer run (:func:`sweep_stale`): after a kill, the rerun leaves
the folder as clean as an uninterrupted run.

Failures to write (a read-only folder, a full disk, a missing folder) raise
:class:`OutputError`, an ``OSError`` whose message is one line naming the file;
the CLI prints it and exits with status 1.

The fault tests kill a writer at two test-only points of :func:`_publish`
(:mod:`arches_render.faults`): its temporary file cut short, and complete but not
yet renamed.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import socket
import tempfile
from pathlib import Path
from typing import IO, Iterator

from . import faults

__all__ = ["OutputError", "atomic_write", "atomic_path", "temp_dir", "sweep_stale"]

# os.umask can only be read by setting it; doing that once at import keeps the
# process-wide change out of concurrent writer threads.
_UMASK = os.umask(0o022)
os.umask(_UMASK)

# Host names may hold characters that are awkward in file names.
_HOST = re.sub(r"[^A-Za-z0-9_]", "_", socket.gethostname())[:40] or "host"
_TEMP = re.compile(r"^\..*\.tmp-(?P<host>[A-Za-z0-9_]+)-(?P<pid>[0-9]+)-[^/]*$")
# Below this many free bytes, a writer's failure is taken for a full disk.
_FULL = 1 << 20


class OutputError(OSError):
    """An output that could not be written; ``str()`` is one line naming the file and the reason."""

    def __init__(self, path, reason: str, err: int | None = None):
        super().__init__(err or errno.EIO, f"cannot write {path}: {reason}")
        self.path = str(path)

    def __str__(self) -> str:
        return self.strerror


def _tag() -> str:
    return f"{_HOST}-{os.getpid()}-"


def _temp_name(path: Path) -> tuple[int, str]:
    # The real suffix stays last because some writers (Mitsuba's Bitmap,
    # imageio, ...) choose the format from the extension of the name they get.
    # The leading dot hides the file from globbing and ``ls`` while it exists.
    return tempfile.mkstemp(prefix=f".{path.stem}.tmp-{_tag()}", suffix=path.suffix, dir=path.parent)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # exists, owned by someone else
    return True


def sweep_stale(folder) -> list[str]:
    """Remove the temporary files and folders in ``folder`` of dead processes of this host.

    Parameters
    ----------
    folder : str or os.PathLike

    Returns
    -------
    list of str
        The names removed.
    """
    removed = []
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for name in names:
        m = _TEMP.match(name)
        if not m or m["host"] != _HOST or _alive(int(m["pid"])):
            continue
        full = os.path.join(folder, name)
        with contextlib.suppress(OSError):
            if os.path.isdir(full) and not os.path.islink(full):
                shutil.rmtree(full)
            else:
                os.unlink(full)
            removed.append(name)
    return removed


def _why(path: Path, exc: BaseException) -> OutputError | None:
    """The :class:`OutputError` for ``exc`` raised while writing ``path``, or ``None`` when it is no I/O failure."""
    if isinstance(exc, OutputError):
        return exc
    if isinstance(exc, OSError):
        reason = exc.strerror or str(exc)
        if not path.parent.is_dir():
            reason = f"folder {path.parent} does not exist"
        return OutputError(path, reason, exc.errno)
    if isinstance(exc, Exception):
        # Libraries that write by file name (OpenEXR, Pillow, trimesh) report a full
        # disk in their own exception types; the free space tells.
        with contextlib.suppress(OSError):
            if shutil.disk_usage(path.parent).free < _FULL:
                return OutputError(path, f"no space left on device ({type(exc).__name__}: "
                                         f"{str(exc).splitlines()[0] if str(exc) else ''})", errno.ENOSPC)
    return None


def _create(path: Path) -> str:
    sweep_stale(path.parent)
    try:
        fd, tmp = _temp_name(path)
    except OSError as exc:
        raise _why(path, exc) from None
    os.close(fd)
    return tmp


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
    tmp = _create(path)
    try:
        # Re-opened by name (not os.fdopen) so that f.name is the path.
        with open(tmp, mode, **open_kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        _publish(tmp, path)
    except BaseException as exc:
        _discard(tmp)
        err = _why(path, exc)
        if err is not None and err is not exc:
            raise err from exc
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
    tmp = _create(path)
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
    except BaseException as exc:
        _discard(tmp)
        err = _why(path, exc)
        if err is not None and err is not exc:
            raise err from exc
        raise


@contextlib.contextmanager
def temp_dir(folder, stem: str) -> Iterator[Path]:
    """A private work folder inside ``folder`` (for outputs published by renames), removed afterwards.

    Its name carries the host and process id like the temporary files, so a folder
    left by a killed process is removed by the next :func:`sweep_stale` of ``folder``.

    Parameters
    ----------
    folder : str or os.PathLike
        Where the outputs will be published (the renames stay on one file system).
    stem : str
        Name part, e.g. the output's stem.

    Yields
    ------
    pathlib.Path
    """
    folder = Path(folder)
    sweep_stale(folder)
    try:
        work = Path(tempfile.mkdtemp(prefix=f".{stem}.tmp-{_tag()}", suffix=".d", dir=folder))
    except OSError as exc:
        raise _why(folder / stem, exc) from None
    try:
        yield work
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _publish(tmp: str, path: Path) -> None:
    # Test-only kill points (arches_render.faults): a cut-short and a complete temporary file.
    faults.point("atomic.written", tmp)
    faults.point("atomic.before_replace", tmp)
    with contextlib.suppress(OSError):
        os.chmod(tmp, 0o666 & ~_UMASK)
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def check_writable(folder) -> None:
    """Raise :class:`OutputError` unless a file can be created in ``folder`` (tried, then removed).

    A real probe rather than :func:`os.access`: permissions, read-only mounts, a
    full inode table and the super-user's rights all show in what ``open`` does.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise OutputError(folder / "x", f"folder {folder} does not exist" if not folder.exists()
                          else f"{folder} is not a folder", errno.ENOENT)
    tmp = _create(folder / ".probe")
    _discard(tmp)
