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
import sys

from tqdm import tqdm


class UsageError(ValueError):
    """A bad command-line value (message is the one line shown)."""


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
