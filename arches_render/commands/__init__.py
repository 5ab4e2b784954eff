"""Subcommands of ``arches-render``, one module each, and what every command module shares.

A command module defines ``register(subparsers)``: it adds its parser with
``subparsers.add_parser(NAME, help=...)`` and sets ``func`` to a handler
``handler(args) -> int``. The core commands live here (``render``, ``turntable``,
``mesh``, ``info``); a generator's commands live in its package and are listed by
the registry (``COMMANDS``, :mod:`arches_render.extensions`).
:func:`arches_render.cli.build_parser` registers both.

Handlers raise :class:`UsageError` (bad argument) or
:class:`~arches_render.scene.SceneError` (bad file) for the user's mistakes: the CLI
prints the one-line message and exits with status 2, with no traceback. The
argument parsers below give argparse the same one-line messages. This package is
the command-plugin API a generator's command module may import (with the scene
API, :mod:`arches_render.scene`); it imports no command module itself.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..atomic import check_writable
from ..mesh.polygonize import PolygonizeError
from ..resources import BASE_BYTES, check_memory, polygonize_bytes, render_bytes
from ..scene import SceneError
from ..scene.validate import Table


class UsageError(ValueError):
    """A bad command-line value (message is the one line shown)."""


@contextlib.contextmanager
def voxel_errors(args, desc):
    """Turn a field that cannot be polygonized at the chosen voxel into a :class:`UsageError`.

    ``args.voxel`` (``--voxel``) or the scene's ``[render] voxel`` chose the voxel;
    the message names the scene file and that setting.
    """
    try:
        yield
    except PolygonizeError as exc:
        where = "--voxel" if args.voxel else ("render.voxel" if desc.render.voxel else "the default voxel")
        raise UsageError(f"{args.scene}: {where}: {exc}") from None


def resolution(text: str):
    """``'WxH'`` as ``(width, height)``, each in [1, 16384] (an argparse ``type``)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--resolution must be WxH, e.g. 640x360 (got {text!r})") from None
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"--resolution width and height must be in [1, 16384] (got {text!r})")
    return w, h


def bounded_int(name, lo, hi):
    """An argparse ``type`` for option ``name``: an integer in ``[lo, hi]``."""
    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer in [{lo}, {hi}] (got {text!r})") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{name} must be an integer in [{lo}, {hi}] (got {v})")
        return v
    return parse


def positive_float(name):
    """An argparse ``type`` for option ``name``: a number > 0."""
    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number > 0 (got {text!r})") from None
        if not v > 0:
            raise argparse.ArgumentTypeError(f"{name} must be a number > 0 (got {text!r})")
        return v
    return parse


def scene_argument(parser, help: str = "scene file (.toml)") -> None:
    """Add the ``scene`` positional and ``--allow-path DIR`` (repeatable) to a command that reads scenes.

    A scene may read files only inside its own folder and the folders allowed here
    or in ``$ARCHES_RENDER_PATH`` (:mod:`arches_render.scene.paths`); the CLI applies
    ``--allow-path`` before the command runs.
    """
    parser.add_argument("scene", help=help)
    parser.add_argument("--allow-path", action="append", default=[], metavar="DIR",
                        help="let the scene read files under DIR too (repeatable; also $ARCHES_RENDER_PATH, "
                             "folders separated by ':'); by default a scene reads only inside its own folder")


class Progress:
    """A ``progress(done, total)`` callback drawing a tqdm bar on stderr."""

    def __init__(self, desc, unit, quiet):
        self.bar = tqdm(total=None, desc=desc, unit=unit, disable=quiet, file=sys.stderr,
                        leave=True, dynamic_ncols=True)

    def __call__(self, done, total):
        if self.bar.total != total:
            self.bar.total = total
        self.bar.update(done - self.bar.n)

    def close(self):
        self.bar.close()


def output_file(text: str, suffix: str) -> Path:
    """The ``-o/--output`` path, which must end in ``suffix`` (e.g. ``'.npz'``).

    Raises
    ------
    UsageError
        ``-o/--output must end in SUFFIX (got ...)``.
    """
    out = Path(text)
    if out.suffix.lower() != suffix:
        raise UsageError(f"-o/--output must end in {suffix} (got {out})")
    return out


def writable_output(out: Path, folder: bool = False, create: bool = False) -> Path:
    """Check, before any work, that output ``out`` can be written; return it.

    Parameters
    ----------
    out : Path
        The output file, or with ``folder`` the output folder (turntable frames).
    folder : bool
        ``out`` is a folder: it is created if missing (its parent must exist).
    create : bool
        Create the missing parent folders too (the default ``out/`` of ``render``).

    Raises
    ------
    UsageError
        ``-o/--output OUT: folder F does not exist`` or ``... is not writable (reason)``.
    """
    where = out if folder else out.parent
    try:
        if create:
            where.mkdir(parents=True, exist_ok=True)
        elif folder and not where.exists() and where.parent.is_dir():
            where.mkdir()
    except OSError as exc:
        raise UsageError(f"-o/--output {out}: folder {where.parent} is not writable "
                         f"(cannot create {where.name}: {exc.strerror})") from None
    if not where.is_dir():
        raise UsageError(f"-o/--output {out}: folder {where} does not exist" if not where.exists()
                         else f"-o/--output {out}: {where} is not a folder")
    try:
        check_writable(where)
    except OSError as exc:
        raise UsageError(f"-o/--output {out}: folder {where} is not writable "
                         f"({os.strerror(exc.errno) if exc.errno else exc})") from None
    return out


def check_render_memory(desc, width: int, height: int, aovs: bool, geometry: str, voxel=None) -> None:
    """Refuse, before any work, a render whose memory estimate exceeds the machine's.

    The image (:func:`arches_render.resources.render_bytes`: beauty, weight and, with
    ``aovs``, the AOV channels) and in mesh mode the marching-cubes
    grid of the field (:func:`arches_render.resources.polygonize_bytes`). The sample
    count costs time, not memory (the kernels draw samples inside their loop).

    Raises
    ------
    arches_render.resources.ResourceError
    """
    channels = 4  # beauty and the film's weight
    if aovs:  # the base layers, one per layer of the field's material, the atmosphere's
        mat = desc.materials.get(desc.field_material or "", {}) if desc.field is not None else {}
        channels += 12 + int(mat.get("layer_count", 0)) + (6 if desc.atmosphere is not None else 0)
    need = render_bytes(width, height, channels)
    what = [f"rendering {width}x{height} with {channels} film channels"] if width * height else []
    if geometry == "mesh" and desc.field is not None:
        lo, hi = (np.asarray(b, np.float64) for b in desc.field.bounds())
        v = float(voxel or desc.render.voxel or np.max(hi - lo) / 256)
        voxels = float(np.prod(np.ceil((hi - lo + 2 * v) / v) + 1))
        need += polygonize_bytes(voxels) - BASE_BYTES
        what.append(f"polygonizing {voxels:.3g} voxels of {v:g} m")
    check_memory(need, " and ".join(what))


def find_node(data: dict, file, kind: str, name: str | None = None) -> tuple[str, Table]:
    """The ``[nodes.NAME]`` table of type ``kind`` that a command works on (``--node``).

    One lookup for every command that reads a node of a scene file, so that the
    same mistake gives the same message.

    Parameters
    ----------
    data : dict
        The scene's TOML data (:func:`arches_render.scene.read_toml`).
    file : str or Path
        The scene file, for messages.
    kind : str
        Node type, e.g. ``'blocks'``.
    name : str, optional
        The node's name (``--node``); default the only node of that type.

    Returns
    -------
    (str, Table)
        The name and the node's table (its ``type`` already read).

    Raises
    ------
    SceneError
        When ``[nodes]`` is not a table or holds no node of type ``kind``.
    UsageError
        When ``name`` is none of them, or it is omitted and there are several.
    """
    nodes = data.get("nodes", {})
    if not isinstance(nodes, dict):
        raise SceneError(file, "nodes", "must be a table of named node tables")
    names = sorted(n for n, t in nodes.items() if isinstance(t, dict) and t.get("type") == kind)
    if not names:
        raise SceneError(file, "nodes", f"has no node of type {kind}")
    if name is None:
        if len(names) > 1:
            raise UsageError(f"{file} has several {kind} nodes ({', '.join(names)}): choose one with --node")
        name = names[0]
    elif name not in names:
        raise UsageError(f"--node must name a {kind} node of {file} ({', '.join(names)}; got {name!r})")
    table = Table(nodes[name], file, f"nodes.{name}")
    table.string("type")
    return name, table
