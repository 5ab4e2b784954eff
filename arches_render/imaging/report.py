"""Failure reports of golden-image checks: the images and one HTML page to look at them.

A report is a folder ``<report_dir>/<name>/`` holding

* ``index.html``: verdict, failed checks, numbers against their limits, images;
* ``test.exr``: the failing render (its mean, variance, coverage and depth);
* ``reference.png`` / ``test.png``: sRGB previews;
* ``pixels.png``: heat map of the per-pixel Welch ``|z|`` of luminance;
* ``windows.png``: heat map of the 8 x 8 window ``|z|``, scaled so that the
  limit is the middle of the colour ramp (anything in the upper half failed),
  with the worst window outlined;
* ``geometry.png``: the per-pixel ``|z|`` of coverage and depth, same scaling;
* ``result.json``: the numbers, for scripts.

The HTML page uses no scripts, fonts or style sheets from elsewhere: it opens
from a CI artefact or a file browser as is. Small renders are shown enlarged
with nearest-neighbour sampling so single pixels stay visible.
"""

from __future__ import annotations

import html
import json
import os
from pathlib import Path

import numpy as np

from ..atomic import atomic_write
from .exr import write_exr
from .preview import write_png
from .welch import WIDE_WINDOW, WINDOW, PixelMoments, WelchResult

__all__ = ["write_failure_report", "clear_report", "heatmap", "REPORT_FILES", "check_name"]

REPORT_FILES = ("index.html", "result.json", "test.exr", "reference.png", "test.png", "pixels.png",
                "windows.png", "geometry.png")
"""Names of the files :func:`write_failure_report` writes (and :func:`clear_report` removes)."""

# Black -> dark red -> red -> yellow -> white: monotonic in lightness, so the
# ramp reads correctly in grey too, and it needs no plotting library.
_RAMP = np.array([[0, 0, 0], [110, 0, 0], [230, 30, 0], [255, 200, 0], [255, 255, 255]], np.float64)

# Shown images are at least this wide (CSS pixels).
_MIN_DISPLAY_WIDTH = 384


def check_name(name: str) -> str:
    """Return ``name`` if it can serve as one file or folder name, else raise ``ValueError``.

    Parameters
    ----------
    name : str
        A golden or report name such as ``'arch_sunset'``.

    Returns
    -------
    str
        ``name`` unchanged.
    """
    if (not isinstance(name, str) or not name or name in (".", "..") or "/" in name or "\\" in name
            or name.startswith(".") or any(ord(c) < 32 for c in name)):
        raise ValueError(f"{name!r} is not usable as a file name (no '/', '\\\\', leading '.' or control "
                         "characters)")
    return name


def heatmap(values, vmax: float) -> np.ndarray:
    """Map non-negative values to an 8-bit black-red-yellow-white colour ramp.

    Parameters
    ----------
    values : array_like
        ``(H, W)`` values; NaNs are shown as the top of the ramp.
    vmax : float
        Value mapped to white; larger values are clipped.

    Returns
    -------
    numpy.ndarray
        uint8 ``(H, W, 3)`` sRGB image.
    """
    v = np.asarray(values, dtype=np.float64) / max(float(vmax), 1e-30)
    v = np.clip(np.nan_to_num(v, nan=1.0, posinf=1.0), 0.0, 1.0) * (len(_RAMP) - 1)
    i = np.minimum(v.astype(int), len(_RAMP) - 2)
    f = (v - i)[..., None]
    return np.round(_RAMP[i] * (1 - f) + _RAMP[i + 1] * f).astype(np.uint8)


def _outline(img: np.ndarray, y: int, x: int, size: int, colour=(0, 200, 255)) -> np.ndarray:
    # The frame is drawn one pixel outside the window (clipped at the image
    # border) so it hides none of the pixels it points at.
    out = img.copy()
    h, w = out.shape[:2]
    y0, x0, y1, x1 = y - 1, x - 1, y + size, x + size
    ys, xs = slice(max(y0, 0), min(y1, h - 1) + 1), slice(max(x0, 0), min(x1, w - 1) + 1)
    for row in (y0, y1):
        if 0 <= row < h:
            out[row, xs] = colour
    for col in (x0, x1):
        if 0 <= col < w:
            out[ys, col] = colour
    return out


def _window_canvas(tile_map: np.ndarray, shape: tuple[int, int], size: int) -> np.ndarray:
    # Entry [y, x] of the map is the window with top-left pixel (y, x); drawing
    # it at the window centre lines the heat map up with the image.
    canvas = np.zeros(shape)
    o = size // 2
    h, w = tile_map.shape
    canvas[o:o + h, o:o + w] = tile_map[: shape[0] - o, : shape[1] - o]
    return canvas


def _row(label: str, value: str, limit: str, failed: bool) -> str:
    cls = ' class="bad"' if failed else ""
    return (f"<tr{cls}><td>{html.escape(label)}</td><td>{html.escape(value)}</td>"
            f"<td>{html.escape(limit)}</td></tr>")


def _page(name: str, shape: tuple[int, int], spp: tuple[int, int], result: WelchResult) -> str:
    lim = result.limits
    h, w = shape
    scale = max(1, -(-_MIN_DISPLAY_WIDTH // w))
    failures = "".join(f"<li>{html.escape(f)}</li>" for f in result.failures) or "<li>none</li>"
    rows = [
        _row("pixel-channels passing (Mitsuba's rule)", f"{result.pixel_pass:.4%}",
             f"≥ {lim['pixel_pass']:.2%} at |z| ≤ {lim['pixel_z']:.2f}", result.pixel_pass < lim["pixel_pass"]),
        _row(f"worst {WINDOW}×{WINDOW} window |z| (luminance)", f"{result.window_z:.2f} at (y, x) = "
             f"{result.window_where}", f"{lim['window_z']:.2f}", result.window_z > lim["window_z"]),
        _row(f"worst {WIDE_WINDOW}×{WIDE_WINDOW} window |z| (luminance)", f"{result.wide_window_z:.2f} at (y, x) = "
             f"{result.wide_window_where}", f"{lim['window_z']:.2f}", result.wide_window_z > lim["window_z"]),
        _row("image mean z (R, G, B, Y)", ", ".join(f"{z:+.2f}" for z in result.mean_z), f"±{lim['mean_z']:.2f}",
             max(abs(z) for z in result.mean_z) > lim["mean_z"]),
        _row("image mean shift (R, G, B, Y)", ", ".join(f"{v:+.3%}" for v in result.mean_shift), "", False),
        _row("worst coverage |z|", f"{result.coverage_z:.2f}", f"{lim['geometry_z']:.2f}",
             result.coverage_z > lim["geometry_z"]),
        _row("worst depth |z| (covered pixels)", f"{result.depth_z:.2f}", f"{lim['geometry_z']:.2f}",
             result.depth_z > lim["geometry_z"]),
    ]
    figures = [
        ("reference.png", f"reference, {spp[0]} spp (sRGB preview)"),
        ("test.png", f"test render, {spp[1]} spp (sRGB preview)"),
        ("pixels.png", f"per-pixel |z| of luminance; mid-ramp = {lim['pixel_z']:.2f}"),
        ("windows.png", f"{WINDOW}×{WINDOW} window |z|; mid-ramp = limit {lim['window_z']:.2f}; outlined: worst"),
        ("geometry.png", f"coverage and depth |z|; mid-ramp = limit {lim['geometry_z']:.2f}"),
    ]
    figs = "".join(
        f'<figure><img src="{f}" width="{w * scale}" height="{h * scale}" alt="{f}">'
        f"<figcaption>{cap}</figcaption></figure>" for f, cap in figures)
    verdict = "PASS" if result.passed else "FAIL"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>{verdict}: golden {html.escape(name)}</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 1.5em; color: #222; }}
h1 .v {{ color: {'#070' if result.passed else '#b00'}; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
td, th {{ border: 1px solid #ccc; padding: 0.3em 0.7em; text-align: left; }}
tr.bad td {{ background: #fdd; }}
figure {{ display: inline-block; margin: 0 1em 1em 0; vertical-align: top; }}
figure img {{ image-rendering: pixelated; border: 1px solid #999; }}
figcaption {{ font-size: 0.85em; max-width: {max(w * scale, 200)}px; }}
</style></head><body>
<h1><span class="v">{verdict}</span> golden <code>{html.escape(name)}</code></h1>
<p>{w}×{h} pixels. Welch's two-sample statistic z = (test − reference) / √(var<sub>test</sub>/n<sub>test</sub>
+ var<sub>ref</sub>/n<sub>ref</sub>); limits are Šidák-corrected (family-wise α = {lim['alpha']:g}).
Test render: <a href="test.exr">test.exr</a> (mean and variance); numbers: <a href="result.json">result.json</a>.</p>
<h2>Failed checks</h2><ul>{failures}</ul>
<h2>Numbers</h2>
<table><tr><th>check</th><th>measured</th><th>limit</th></tr>{''.join(rows)}</table>
<h2>Images</h2>{figs}
</body></html>
"""


def write_failure_report(folder: str | os.PathLike, name: str, ref: PixelMoments, test: PixelMoments,
                         result: WelchResult) -> Path:
    """Write the report of a golden check into ``folder/name/``.

    Parameters
    ----------
    folder : str or os.PathLike
        The report root (created if missing), e.g. ``test-reports/``.
    name : str
        Name of the golden; becomes the sub-folder name.
    ref, test : PixelMoments
        The reference and the test render.
    result : WelchResult
        Outcome of :func:`arches_render.imaging.welch.welch_compare` for them.

    Returns
    -------
    pathlib.Path
        Path of ``index.html``.

    Notes
    -----
    Every file is written atomically; files of an older report of the same
    name are overwritten, none is left over (all names are fixed, see
    :data:`REPORT_FILES`).
    """
    out = Path(folder) / check_name(name)
    out.mkdir(parents=True, exist_ok=True)
    lim = result.limits
    s = min(WINDOW, *ref.shape)
    write_exr(out / "test.exr", np.asarray(test.mean, np.float32),
              header={"golden": name, "role": "failed test render", "spp": test.n},
              layers={"variance": (test.sample_variance(), ("R", "G", "B", "Y")),
                      "coverage": (test.coverage, ("hit",)), "depth": (test.depth, ("Z",))},
              full_precision=("rgb", "depth"))
    write_png(out / "reference.png", np.asarray(ref.mean, np.float32))
    write_png(out / "test.png", np.nan_to_num(np.asarray(test.mean, np.float32), nan=0.0, posinf=0.0, neginf=0.0))
    wy, wx = result.window_where
    write_png(out / "pixels.png", heatmap(result.z_map, 2.0 * lim["pixel_z"]))
    windows = _window_canvas(result.window_map, ref.shape, s)
    write_png(out / "windows.png", _outline(heatmap(windows, 2.0 * lim["window_z"]), wy, wx, s))
    write_png(out / "geometry.png", heatmap(result.geometry_map, 2.0 * lim["geometry_z"]))

    with atomic_write(out / "result.json", "w", encoding="utf-8") as f:
        json.dump({"name": name, "spp": {"reference": ref.n, "test": test.n}, **result.numbers()}, f, indent=2,
                  default=float)
    page = out / "index.html"
    with atomic_write(page, "w", encoding="utf-8") as f:
        f.write(_page(name, ref.shape, (ref.n, test.n), result))
    return page


def clear_report(folder: str | os.PathLike, name: str) -> None:
    """Remove the report ``folder/name/`` written by :func:`write_failure_report`, if any.

    Parameters
    ----------
    folder : str or os.PathLike
        The report root.
    name : str
        Name of the golden.

    Notes
    -----
    Only the files in :data:`REPORT_FILES` are removed; the folder goes only if
    that leaves it empty, so nothing a person put there is lost. A stale report
    of a check that passes now would otherwise send people hunting a fixed bug.
    """
    out = Path(folder) / check_name(name)
    if not out.is_dir():
        return
    for f in REPORT_FILES:
        try:
            (out / f).unlink()
        except FileNotFoundError:
            pass
    try:
        out.rmdir()
    except OSError:
        pass
