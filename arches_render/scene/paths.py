"""File paths in scene files: relative to the scene, and kept inside its folder.

A scene file is data that may come from elsewhere (a render farm renders scenes
it did not write), so the files it names must not reach arbitrary files of the
machine that renders it. Every path a scene gives (meshes, DEMs, primitive and
stack arrays, tiles, textures, environment maps) goes through :func:`scene_file`:

* a relative path is relative to the folder of the scene file;
* the resolved path (symbolic links and ``..`` resolved, :func:`os.path.realpath`)
  must lie inside the scene's folder, or inside a folder the user allowed:
  ``--allow-path DIR`` on the command line (:func:`allow`, repeatable) or the
  ``ARCHES_RENDER_PATH`` environment variable (folders separated by
  :data:`os.pathsep`, like ``PATH``);
* otherwise the scene is refused with a one-line
  :class:`~arches_render.scene.errors.SceneError` naming the file, the key and
  the folders allowed.

Resolving links before the check means that a link inside the scene's folder that
points outside it is refused too. Nothing a scene names is ever executed or
unpickled (every ``np.load`` passes ``allow_pickle=False``; a test scans the code).
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterable, Iterator

__all__ = ["ENV", "allow", "allowed", "extra_folders", "allowed_folders", "check_inside", "scene_file"]

#: Environment variable listing extra folders that scenes may read from.
ENV = "ARCHES_RENDER_PATH"

# Folders allowed by --allow-path for the life of the process (the CLI sets them
# once); jobs that travel to other processes carry their own (RenderJob.allow_paths).
_ALLOWED: list[str] = []


def allow(folders: Iterable) -> None:
    """Allow scenes to read files under ``folders`` for the rest of the process (``--allow-path``).

    Parameters
    ----------
    folders : iterable of str or os.PathLike
        Folders; they need not exist yet.
    """
    for f in folders or ():
        real = os.path.realpath(os.fspath(f))
        if real not in _ALLOWED:
            _ALLOWED.append(real)


@contextlib.contextmanager
def allowed(folders: Iterable) -> Iterator[None]:
    """Allow ``folders`` inside a ``with`` block only (a render job's own list)."""
    before = list(_ALLOWED)
    allow(folders)
    try:
        yield
    finally:
        _ALLOWED[:] = before


def extra_folders() -> tuple[str, ...]:
    """The folders allowed besides a scene's own: ``--allow-path`` then ``$ARCHES_RENDER_PATH``.

    A render job records them when it is made (:class:`arches_render.render.jobs.RenderJob`),
    so that a worker process or machine applies the same rule as the command.
    """
    env = [os.path.realpath(p) for p in os.environ.get(ENV, "").split(os.pathsep) if p.strip()]
    return tuple(dict.fromkeys([*_ALLOWED, *env]))


def allowed_folders(scene_dir) -> list[str]:
    """The folders a scene in ``scene_dir`` may read from: its own, ``--allow-path``, ``$ARCHES_RENDER_PATH``.

    Parameters
    ----------
    scene_dir : str or os.PathLike
        The folder of the scene file.

    Returns
    -------
    list of str
        Real (link-free, absolute) paths, the scene's folder first.
    """
    return list(dict.fromkeys([os.path.realpath(os.fspath(scene_dir)), *extra_folders()]))


def _inside(path: str, folder: str) -> bool:
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def check_inside(path, scene_dir) -> str | None:
    """``None`` when ``path`` lies in an allowed folder of a scene in ``scene_dir``, else why not.

    Parameters
    ----------
    path : str or os.PathLike
        The file (absolute, or relative to the current folder).
    scene_dir : str or os.PathLike

    Returns
    -------
    str or None
        The reason, one clause: ``leaves the scene's folder ... (allowed: ...)``.
    """
    real = os.path.realpath(os.fspath(path))
    folders = allowed_folders(scene_dir)
    if any(_inside(real, f) for f in folders):
        return None
    return (f"{real} lies outside the scene's folder {folders[0]}; a scene may read only files "
            f"inside its own folder or a folder allowed with --allow-path DIR or ${ENV} "
            f"(allowed now: {os.pathsep.join(folders)})")


def scene_file(t, key: str, suffixes: tuple[str, ...] | None = None, base_dir=None,
               what: str = "file") -> Path:
    """The file named by string ``key`` of table ``t``: resolved, inside the allowed folders, existing.

    Parameters
    ----------
    t : arches_render.scene.validate.Table
        The table holding the key (its ``file`` is the scene file).
    key : str
        The key, e.g. ``'file'``, ``'mesh'``, ``'tile'``.
    suffixes : tuple of str, optional
        Allowed lower-case extensions, e.g. ``('.ply', '.obj')``.
    base_dir : str or os.PathLike, optional
        Folder relative paths start from; default the scene file's folder.
    what : str
        What the file is, for messages (``'mesh'``, ``'texture'``, ...).

    Returns
    -------
    pathlib.Path
        The real path of the file.

    Raises
    ------
    SceneError
        Not a string, wrong extension, outside the allowed folders, or no such file.
    """
    text = t.string(key)
    if not text.strip():
        raise t.error(key, f"must name a {what} (got an empty string)")
    if "\0" in text:
        raise t.error(key, f"must be a {what} path without NUL characters")
    base = Path(base_dir) if base_dir is not None else Path(t.file).parent
    path = Path(text) if Path(text).is_absolute() else base / text
    if suffixes and path.suffix.lower() not in suffixes:
        allowed_ = ", ".join(suffixes[:-1]) + (" or " if len(suffixes) > 1 else "") + suffixes[-1]
        raise t.error(key, f"must be a {allowed_} {what} (got {path.name!r})")
    reason = check_inside(path, base)
    if reason:
        raise t.error(key, f"refused: {reason}")
    real = Path(os.path.realpath(path))
    if not real.is_file():
        raise t.error(key, f"no such file: {path}" if not real.exists() else f"not a file: {path}")
    return real
