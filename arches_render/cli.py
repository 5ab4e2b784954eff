"""``arches-render``: render, polygonize and inspect scene files.

The CLI is thin: this module is the parser and :func:`main`. Each subcommand is a
module with ``register(subparsers)``: the core ones in :mod:`arches_render.commands`,
a generator's in its package, listed by the registry (:mod:`arches_render.extensions`).
Bad input (scene files, arguments, requests that do not fit in memory) exits with
status 2 and one line naming the file, key and allowed range; an output that cannot
be written (read-only folder, full disk), or a Dask worker's render process that dies
(a native crash: the line names the scene, the frame or tile and the signal), exits
with status 1 and one line. No traceback reaches the user for an error of theirs or
of their machine.
"""

from __future__ import annotations

import argparse
import sys

from . import __version__, extensions
from .backend import BackendError, set_variant
from .atomic import OutputError
from .commands import UsageError, info, mesh, preview, render, turntable
from .render.isolated import RenderCrash
from .resources import ResourceError
from .scene import SceneError, paths

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2

#: The core subcommands (modules of :mod:`arches_render.commands`, each registering the
#: subcommand of its name), in the order of ``arches-render --help``.
CORE_COMMANDS = (render, turntable, mesh, preview, info)


def command_modules(argv=None) -> list:
    """The subcommand modules to register: only the named one where ``argv`` names a core
    subcommand, else every core and generator subcommand.

    A ``render`` must not import the generators' subcommands (``amplify``'s numba, trimesh
    and scipy: 0.4 s of every render process).
    """
    chosen = next((a for a in argv or () if not a.startswith("-")), None)
    named = [m for m in CORE_COMMANDS if m.__name__.rsplit(".", 1)[-1] == chosen]
    return named or [*CORE_COMMANDS, *extensions.commands()]


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The ``arches-render`` parser: the core subcommands, then every generator's (only the
    subcommand that ``argv`` names, where it is a core one: :func:`command_modules`)."""
    p = argparse.ArgumentParser(prog="arches-render", description=__doc__.splitlines()[0])
    p.add_argument("--version", action="version", version=f"arches-render {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="SUBCOMMAND")
    for module in command_modules(argv):
        module.register(sub)
    return p


def main(argv=None) -> int:
    """Entry point of the ``arches-render`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(argv).parse_args(argv)
    try:
        set_variant()
        with paths.allowed(getattr(args, "allow_path", None) or ()):
            return args.func(args)
    except (SceneError, UsageError, ResourceError) as exc:
        print(f"arches-render: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:
        # An output that cannot be written (OutputError names it), or any other I/O
        # failure of the machine (a full disk in a library's own writer): one line.
        msg = str(exc) if isinstance(exc, OutputError) or not exc.filename else f"{exc.filename}: {exc.strerror}"
        print(f"arches-render: error: {msg}", file=sys.stderr)
        return EXIT_FAILURE
    except (BackendError, RenderCrash) as exc:
        # RenderCrash: a render process of a Dask worker died (a native crash); the
        # message names the scene, the frame or tile, and the signal.
        print(f"arches-render: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print("arches-render: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
