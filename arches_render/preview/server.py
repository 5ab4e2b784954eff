"""The preview's web server: one page, its picture, its events, its controls; loopback only.

Routes (Starlette, served by uvicorn on ``127.0.0.1``):

==================  =================================================================
``GET /``           the page (:file:`page.html`)
``GET /image.png``  the current picture (:meth:`PreviewSession.picture`), never cached
``GET /state``      the :class:`~.session.PreviewState` as JSON
``GET /events``     server-sent events: the state as JSON each time a picture or an
                    error is published (the page then fetches ``/image.png?v=N``)
``POST /control``   ``{"kind": ..., "value": ...}``: a change for the session
                    (:meth:`PreviewSession.post`); unknown kinds are refused (400)
``GET /files/...``  a file of the scene's folder (the scene, the DEMs and meshes it
                    names), read-only; any path that resolves outside it is refused (403)
==================  =================================================================

Every request must come from the loopback interface and name a loopback host in
its ``Host`` header (a page of another site cannot reach the server through a DNS
name that resolves to 127.0.0.1); others get 403. The file watcher
(:func:`watch_scene`) posts ``reload`` when a file of the scene's folder, or of a
folder of a file it names, changes.

References
----------
Starlette: https://www.starlette.io/ ; uvicorn: https://www.uvicorn.org/ ;
watchfiles: https://watchfiles.helpmanual.io/ ; WHATWG HTML, "Server-sent events".
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import threading
import webbrowser
from dataclasses import asdict
from importlib import resources

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, HTMLResponse, JSONResponse, PlainTextResponse, Response, StreamingResponse
from starlette.routing import Route

from ..render.jobs import scene_files

__all__ = ["create_app", "open_socket", "serve", "watch_scene", "CONTROLS"]

#: The changes the page may post, and how their values are read.
CONTROLS = {
    "reload": lambda v: None,
    "camera": str,
    "orbit": lambda v: (float(v[0]), float(v[1])),
    "dolly": float,
    "save_camera": str,
    "layer": str,
    "exposure": float,
    "view": str,
}

LOOPBACK_CLIENTS = ("127.0.0.1", "::1")
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "[::1]")

#: Seconds between the event stream's looks at the session's state.
EVENT_POLL = 0.05


class LoopbackOnly:
    """ASGI middleware: 403 for a client off the loopback interface or a ``Host`` that
    names another host (module docstring)."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] in ("http", "websocket"):
            client = (scope.get("client") or ("",))[0]
            host = dict(scope.get("headers") or ()).get(b"host", b"").decode("latin-1")
            name = host.rsplit(":", 1)[0] if not host.endswith("]") else host
            if client not in LOOPBACK_CLIENTS or name not in LOOPBACK_HOSTS:
                await PlainTextResponse("forbidden: the preview serves its own machine only", 403)(scope, receive, send)
                return
        await self.app(scope, receive, send)


def create_app(session) -> Starlette:
    """The ASGI application of a :class:`~.session.PreviewSession` (module docstring)."""
    page = resources.files(__package__).joinpath("page.html").read_text(encoding="utf-8")
    folder = session.path.parent

    async def index(request: Request):
        return HTMLResponse(page, headers={"Cache-Control": "no-store"})

    async def image(request: Request):
        number, png = session.picture()
        if not png:
            return Response(status_code=204)
        return Response(png, media_type="image/png", headers={"Cache-Control": "no-store", "X-Picture": str(number)})

    async def state(request: Request):
        return JSONResponse(asdict(session.state()))

    async def events(request: Request):
        async def stream():
            last = None
            while not await request.is_disconnected():
                s = session.state()
                if s.version != last:
                    last = s.version
                    yield f"data: {json.dumps(asdict(s))}\n\n"
                await asyncio.sleep(EVENT_POLL)
        return StreamingResponse(stream(), media_type="text/event-stream", headers={"Cache-Control": "no-store"})

    async def control(request: Request):
        try:
            body = await request.json()
            kind = body["kind"]
            value = CONTROLS[kind](body.get("value"))
        except (ValueError, KeyError, TypeError, IndexError):
            return JSONResponse({"error": f"unknown control; allowed: {', '.join(CONTROLS)}"}, status_code=400)
        session.post(kind, value)
        return JSONResponse({"ok": True})

    async def files(request: Request):
        wanted = (folder / request.path_params["path"]).resolve()
        if not wanted.is_relative_to(folder):
            return PlainTextResponse("forbidden: outside the scene's folder", 403)
        if not wanted.is_file():
            return PlainTextResponse("not found", 404)
        return FileResponse(wanted, headers={"Cache-Control": "no-store"})

    app = Starlette(routes=[Route("/", index), Route("/image.png", image), Route("/state", state),
                            Route("/events", events), Route("/control", control, methods=["POST"]),
                            Route("/files/{path:path}", files)])
    app.add_middleware(LoopbackOnly)
    return app


def open_socket(port: int = 0) -> socket.socket:
    """A listening TCP socket on ``127.0.0.1:port`` (0: a free port)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", int(port)))
    sock.listen(64)
    return sock


def watch_scene(session, stop: threading.Event) -> threading.Thread:
    """Start a thread that posts ``reload`` to ``session`` whenever a file of the scene's
    folder or of a named file's folder changes (the session compares the scene's
    inputs, so other files cost one digest)."""
    import watchfiles

    folders = {session.path.parent} | {f.parent for f in scene_files(session.path)}

    def run():
        for _ in watchfiles.watch(*sorted(folders), stop_event=stop, debounce=50, step=20,
                                  raise_interrupt=False):
            session.post("reload")

    thread = threading.Thread(target=run, name="preview-watch", daemon=True)
    thread.start()
    return thread


def serve(session, sock: socket.socket, open_browser: bool = True, announce=print) -> None:
    """Serve ``session`` on ``sock`` until interrupted (Ctrl-C); watch its files meanwhile.

    Parameters
    ----------
    session : PreviewSession
        Started.
    sock : socket.socket
        From :func:`open_socket`.
    open_browser : bool
        Open the page in the default browser when the machine has a display.
    announce : callable
        Receives the page's URL.
    """
    import uvicorn

    url = f"http://127.0.0.1:{sock.getsockname()[1]}/"
    announce(url)
    stop = threading.Event()
    watch_scene(session, stop)
    if open_browser and (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        webbrowser.open(url)
    server = uvicorn.Server(uvicorn.Config(create_app(session), log_level="warning", lifespan="off"))
    try:
        server.run(sockets=[sock])
    finally:
        stop.set()
        session.stop()
