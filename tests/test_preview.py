"""``arches-render preview``: the progressive session, the server's refusals, the page in Chromium.

The scene is the default one (a copy, at 192x108 and 8 spp to keep the test short),
so the kernels are those the rest of the suite compiles for it at other sizes.
"""

from __future__ import annotations

import asyncio
import json
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from arches_render import tomlfile
from arches_render.preview.session import MAX_ELEVATION, PreviewSession, dolly, orbit

REPO = Path(__file__).resolve().parents[1]
CHROMIUM = "/usr/bin/chromium"


def _scene(folder: Path, resolution=(192, 108), spp=8) -> Path:
    """The default scene and the DEM it names, copied into ``folder``, smaller and cheaper."""
    (folder / "data").mkdir(parents=True)
    shutil.copy(REPO / "scenes" / "data" / "default_gorge.heights.npy", folder / "data")
    text = (REPO / "scenes" / "default.toml").read_text()
    text = text.replace("resolution = [640, 360]", f"resolution = [{resolution[0]}, {resolution[1]}]")
    text = text.replace("spp = 16", f"spp = {spp}")
    assert f"spp = {spp}" in text and f"resolution = [{resolution[0]}" in text
    path = folder / "default.toml"
    path.write_text(text)
    return path


def test_orbit_keeps_distance_and_target_and_stops_short_of_the_pole():
    o, t, up = [10.0, -20.0, 5.0], [1.0, 2.0, 3.0], [0.0, 0.0, 1.0]
    r = np.linalg.norm(np.subtract(o, t))
    for turn in ((30.0, 0.0), (-90.0, 20.0), (0.0, 200.0), (0.0, -200.0)):
        moved = orbit(o, t, up, *turn)
        # (float64 rounding of the rotation's sines and cosines only: ~1e-15 relative)
        assert np.linalg.norm(np.subtract(moved, t)) == pytest.approx(r, rel=1e-9)
        elevation = np.degrees(np.arcsin((moved[2] - t[2]) / r))
        assert abs(elevation) <= MAX_ELEVATION + 1e-9
    # A pure azimuth turn keeps the height and turns the horizontal offset by that angle.
    moved = orbit(o, t, up, 90.0, 0.0)
    a = np.subtract(o, t)[:2]
    b = np.subtract(moved, t)[:2]
    assert moved[2] == pytest.approx(o[2])
    assert np.degrees(np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b)) == pytest.approx(90.0)
    assert np.linalg.norm(np.subtract(dolly(o, t, 0.5), t)) == pytest.approx(0.5 * r)


def _next(session, after: int, stage: str, timeout=300.0):
    return session.wait_for(lambda s: s.picture > after and s.stage == stage, timeout)


def test_session_refines_reloads_moves_and_keeps_the_last_picture_on_a_bad_edit(tmp_path):
    path = _scene(tmp_path)
    session = PreviewSession(path, first_width=64).start()
    try:
        first = session.wait_for(lambda s: s.stage == "first", 300)
        assert first.size == (64, 36)
        done = session.wait_for(lambda s: s.stage == "done", 300)
        assert done.size == (192, 108) and done.samples == done.spp == 8
        # The refinement went pass by pass (8 spp in passes of 4: one running mean shown).
        assert done.picture - first.picture >= 2

        # A camera move is a parameter edit: nothing compiles.
        session.post("orbit", (2.0, 1.0))  # (farther turns put the camera in the gorge's wall)
        moved = _next(session, done.picture, "done")
        assert moved.compiled == 0
        assert moved.error is None
        # A turn that would put the camera in the gorge's wall is refused: the view stays.
        origin = session._full.desc.camera.origin
        session.post("orbit", (15.0, 0.0))
        refused = session.wait_for(lambda s: s.error is not None, 60)
        assert "inside the terrain" in refused.error
        assert session._full.desc.camera.origin == origin and session.state().picture == moved.picture

        # A saved edit of a material value re-renders, without compiling either.
        _, before = session.picture()
        text = path.read_text()
        assert "elevation = 33.0" in text
        path.write_text(text.replace("elevation = 33.0", "elevation = 12.0"))
        session.post("reload")
        first = _next(session, moved.picture, "first", 60)
        lower = _next(session, first.picture, "done")
        assert lower.compiled == 0 and lower.error is None
        assert session.picture()[1] != before
        # The moved camera survived the reload (an override on the file's tables).
        assert session._full.desc.camera.origin != tomlfile.loads(path.read_text())["camera"]["origin"]
        # A material value saved in the file: a new picture, no kernel compiled.
        assert '"grass.height_min" = 13.1' in path.read_text()
        path.write_text(path.read_text().replace('"grass.height_min" = 13.1', '"grass.height_min" = 30.0'))
        session.post("reload")
        first = _next(session, lower.picture, "first", 60)
        assert first.compiled == 0
        lower = _next(session, first.picture, "done")
        assert lower.compiled == 0 and lower.error is None

        # A bad edit: its one line is shown, the picture stays.
        version, png = session.picture()
        path.write_text(path.read_text().replace("fov = 58.0", "fov = -58.0"))
        session.post("reload")
        bad = session.wait_for(lambda s: s.error is not None, 60)
        assert "camera.fov" in bad.error and "\n" not in bad.error
        time.sleep(1.0)
        assert session.picture() == (version, png)
        assert session.state().picture == lower.picture

        # Fixed: the message goes, a new picture comes.
        path.write_text(path.read_text().replace("fov = -58.0", "fov = 58.0"))
        session.post("reload")
        fixed = _next(session, lower.picture, "done")
        assert fixed.error is None

        # The file gone for a moment (an editor saving by rename): one line, the thread lives on.
        text = path.read_text()
        path.unlink()
        session.post("reload")
        gone = session.wait_for(lambda s: s.error is not None, 60)
        assert "default.toml" in gone.error and "\n" not in gone.error
        path.write_text(text.replace("elevation = 12.0", "elevation = 14.0"))
        session.post("reload")
        fixed = _next(session, fixed.picture, "done")
        assert fixed.error is None

        # The current view saved as a named camera: the file reads back with it.
        session.post("save_camera", "preview_view")
        saved = session.wait_for(lambda s: "preview_view" in s.cameras, 60)
        assert saved.camera == "preview_view"
        cam = tomlfile.loads(path.read_text())["cameras"]["preview_view"]
        assert cam["origin"] == pytest.approx(session._full.desc.camera.origin)
        session.post("save_camera", "preview_view")  # taken: refused, the file unchanged
        taken = session.wait_for(lambda s: s.error is not None, 60)
        assert "taken" in taken.error
        assert path.read_text().count("[cameras.preview_view]") == 1

        # An AOV layer: rendered with AOVs from then on, shown as a normal map.
        session.post("layer", "normal")
        normal = session.wait_for(lambda s: s.layer == "normal" and "normal" in s.layers and s.stage == "done"
                                  and s.picture > taken.picture, 300)
        # A normal map of ground facing up: blue over green over red, on average.
        from PIL import Image
        import io
        rgb = np.asarray(Image.open(io.BytesIO(session.picture()[1])), float).reshape(-1, 3).mean(axis=0)
        assert normal.layer == "normal" and rgb[2] > rgb[0] and rgb[2] > 127
    finally:
        session.stop()


def _asgi_get(app, path, client="127.0.0.1", host="127.0.0.1:8000"):
    """Status of one GET through the ASGI app (no network: the client address is ours to set)."""
    sent, asked = [], []

    async def receive():
        if asked:  # the request was read: the client stays connected until the response ends
            await asyncio.Event().wait()
        asked.append(True)
        return {"type": "http.request", "body": b"", "more_body": False}

    async def send(message):
        sent.append(message)

    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "GET",
             "scheme": "http", "path": path, "raw_path": path.encode(), "query_string": b"",
             "headers": [(b"host", host.encode())], "client": (client, 50000), "server": ("127.0.0.1", 8000),
             "root_path": ""}
    asyncio.run(app(scope, receive, send))
    return next(m["status"] for m in sent if m["type"] == "http.response.start")


def test_server_refuses_other_hosts_and_paths_outside_the_scene_folder(tmp_path):
    from arches_render.preview.server import create_app
    path = _scene(tmp_path / "scene")
    (tmp_path / "secret.txt").write_text("not the scene's")
    app = create_app(SimpleNamespace(path=path.resolve()))
    assert _asgi_get(app, "/files/default.toml") == 200
    assert _asgi_get(app, "/files/data/default_gorge.heights.npy") == 200
    assert _asgi_get(app, "/files/../secret.txt") == 403
    assert _asgi_get(app, "/files/../../etc/passwd") == 403
    assert _asgi_get(app, "/files/default.toml", client="192.168.1.7") == 403
    assert _asgi_get(app, "/files/default.toml", host="evil.example:8000") == 403
    assert _asgi_get(app, "/nothing") == 404


def test_cli_preview_rejects_a_bad_scene_in_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[render]\nspp = -1\n")
    out = subprocess.run([sys.executable, "-m", "arches_render.cli", "preview", str(bad), "--no-browser"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.toml" in lines[0] and "Traceback" not in out.stderr


def _wait_until_done_picture_shown(page):
    """Wait for the status line to say done and for the done picture itself to be on screen.

    The page sets its status from the event at once but swaps the picture only when the
    next one has loaded, so "done" alone can be read while the previous picture still shows
    (CI once saw the done picture arrive after the next step had read the old one).
    """
    page.wait_for_function("document.getElementById('status').textContent.startsWith('done')", timeout=300_000)
    done = json.loads(page.evaluate("fetch('/state').then(r => r.text())"))["picture"]
    page.wait_for_function(f"Number(document.getElementById('picture').dataset.picture) >= {done}",
                           timeout=60_000)


def test_preview_page_in_chromium_shows_updates_and_errors(tmp_path):
    playwright = pytest.importorskip("playwright.sync_api", reason="the test extra installs playwright")
    assert Path(CHROMIUM).exists(), "bash setup.sh test installs Debian's chromium"
    from arches_render.preview.server import open_socket, serve
    path = _scene(tmp_path)
    session = PreviewSession(path, first_width=64).start()
    sock = open_socket(0)
    url = f"http://127.0.0.1:{sock.getsockname()[1]}/"
    server = threading.Thread(target=serve, args=(session, sock, False, lambda u: None), daemon=True)
    server.start()
    args = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync"]
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=args)
        try:
            page = browser.new_page()
            page.goto(url)
            page.wait_for_function("document.getElementById('picture').naturalWidth > 0", timeout=120_000)
            _wait_until_done_picture_shown(page)
            shown = int(page.get_attribute("#picture", "data-picture"))
            src = page.get_attribute("#picture", "src")
            # Saved edit: the watcher sees it, the page shows a newer picture.
            path.write_text(path.read_text().replace("elevation = 33.0", "elevation = 15.0"))
            page.wait_for_function(f"Number(document.getElementById('picture').dataset.picture) > {shown}",
                                   timeout=120_000)
            _wait_until_done_picture_shown(page)
            assert page.get_attribute("#picture", "src") != src
            # Broken edit: the error line, and the last picture stays on screen.
            last = page.get_attribute("#picture", "src")
            path.write_text(path.read_text().replace("fov = 58.0", "fov = 0.0"))
            page.wait_for_selector("#error", state="visible", timeout=60_000)
            assert "camera.fov" in page.inner_text("#error")
            time.sleep(1.0)
            assert page.get_attribute("#picture", "src") == last
            assert page.evaluate("document.getElementById('picture').naturalWidth") == 192
            assert json.loads(page.evaluate("fetch('/state').then(r => r.text())"))["error"]
        finally:
            browser.close()
            session.stop()
