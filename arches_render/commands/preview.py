"""``arches-render preview SCENE``: a live, progressive render of a scene file in the browser.

Serves :mod:`arches_render.preview` on ``127.0.0.1`` (a free port unless ``--port``),
prints the page's URL and opens it in the browser when the machine has a display.
The picture starts small within a second on warm kernels, refines to the scene's
resolution and spp pass by pass, and renders again whenever the scene file, or a
file it names, is saved. Ctrl-C stops the server.
"""

from __future__ import annotations

import sys

from . import UsageError, bounded_int, scene_argument


def register(subparsers) -> None:
    p = subparsers.add_parser("preview", help="serve a live, progressive render of the scene on a local web page")
    scene_argument(p)
    p.add_argument("--port", type=bounded_int("--port", 0, 65535), default=0,
                   help="port on 127.0.0.1 (default 0: a free one)")
    p.add_argument("--camera", metavar="NAME", help="start with the scene's camera NAME")
    p.add_argument("--first-width", type=bounded_int("--first-width", 16, 4096), default=160,
                   help="width of the first image of every change (default 160)")
    p.add_argument("--no-browser", dest="browser", action="store_false", help="do not open a browser")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..preview.server import open_socket, serve
    from ..preview.session import PreviewSession
    try:
        sock = open_socket(args.port)
    except OSError as exc:
        raise UsageError(f"--port {args.port}: cannot listen on 127.0.0.1 ({exc.strerror})") from None
    session = PreviewSession(args.scene, camera=args.camera, first_width=args.first_width)
    print(f"preview: building {args.scene} ...", file=sys.stderr, flush=True)
    session.start()
    serve(session, sock, open_browser=args.browser,
          announce=lambda url: print(f"preview: {url}  (Ctrl-C stops)", flush=True))
    return 0


__all__ = ["register", "run"]
