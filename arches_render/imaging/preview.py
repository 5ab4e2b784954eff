"""Display previews of linear renders: sRGB encoding and PNG output.

The encoding is colour-science's sRGB transfer function (IEC 61966-2-1) applied
after exposure and clipping to [0, 1]; no tone mapping, so a preview shows the
numbers the golden tests compare, with highlights above 1 clipped.

PNGs are 8-bit, tagged sRGB, and written by Pillow into the file object of
:func:`arches_render.atomic.atomic_write` (no half-written preview), without
Mitsuba (``mi.util.write_bitmap`` writes asynchronously by default, and an image
helper should not load the renderer).

References
----------
.. [1] IEC 61966-2-1:1999, Multimedia systems and equipment - Colour
   measurement and management - Part 2-1: Default RGB colour space - sRGB.
.. [2] W3C, "Portable Network Graphics (PNG) Specification (Third Edition)",
   https://www.w3.org/TR/png-3/
"""

from __future__ import annotations

import io
import os
import warnings
from pathlib import Path

import numpy as np
from PIL import Image
from PIL.PngImagePlugin import PngInfo

from ..atomic import atomic_write

__all__ = ["encode_srgb", "png_bytes", "to_srgb8", "write_png"]

#: PNG chunks that tag the pixels as sRGB (W3C PNG 11.3.2: rendering intent 0,
#: and the matching gAMA of 1/2.2 for viewers that ignore sRGB).
_SRGB_CHUNKS = ((b"sRGB", b"\x00"), (b"gAMA", (45455).to_bytes(4, "big")))


def _colour():
    # colour-science warns at import that matplotlib is absent; we use no
    # plotting, so that warning is noise in every test run.
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*Matplotlib.*")
        import colour
    return colour


def encode_srgb(rgb_linear, exposure: float = 0.0) -> np.ndarray:
    """Encode linear Rec.709 values with the sRGB transfer function, as floats.

    Parameters
    ----------
    rgb_linear : array_like
        Linear values, any shape (usually ``(H, W, 3)``).
    exposure : float, optional
        Exposure in stops: values are multiplied by ``2 ** exposure`` first.

    Returns
    -------
    numpy.ndarray
        float64 values in [0, 1]; NaNs become 0.

    References
    ----------
    IEC 61966-2-1:1999, via :func:`colour.cctf_encoding` with ``function='sRGB'``.
    """
    x = np.asarray(rgb_linear, dtype=np.float64) * (2.0 ** float(exposure))
    x = np.clip(np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.clip(_colour().cctf_encoding(x, function="sRGB"), 0.0, 1.0)


def to_srgb8(rgb_linear, exposure: float = 0.0) -> np.ndarray:
    """Convert a linear image to 8-bit sRGB for display.

    Parameters
    ----------
    rgb_linear : array_like
        Linear Rec.709 colour, shape ``(H, W, 3)`` (any shape is accepted).
    exposure : float, optional
        Exposure in stops applied before clipping to [0, 1].

    Returns
    -------
    numpy.ndarray
        uint8 array of the same shape; e.g. linear 0.2140 maps to 128.

    References
    ----------
    IEC 61966-2-1:1999 (see :func:`encode_srgb`).
    """
    return np.round(encode_srgb(rgb_linear, exposure) * 255.0).astype(np.uint8)


def _png_image(pixels) -> Image.Image:
    """A Pillow image of 8-bit pixels ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` or ``(H, W, 4)``."""
    a = np.asarray(pixels)
    if a.dtype != np.uint8:
        raise ValueError(f"PNG previews need uint8 pixels, got {a.dtype}")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (3, 4))) or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"PNG previews need (H, W), (H, W, 3) or (H, W, 4) pixels, got {a.shape}")
    return Image.fromarray(np.ascontiguousarray(a))


def write_png(path: str | os.PathLike, rgb_linear, exposure: float = 0.0) -> Path:
    """Write an sRGB-encoded 8-bit PNG preview of a linear image, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ``.png`` file; its folder must exist.
    rgb_linear : array_like
        Linear Rec.709 colour, ``(H, W, 3)``; a uint8 array is taken as
        already encoded and written as is (used for heat maps).
    exposure : float, optional
        Exposure in stops (ignored for uint8 input).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        For pixels that are not ``(H, W)``, ``(H, W, 3)`` or ``(H, W, 4)``.

    References
    ----------
    IEC 61966-2-1:1999; W3C PNG Specification (Third Edition), 11.3.2 (``sRGB``).
    """
    path = Path(path)
    with atomic_write(path, "wb") as f:
        _save_png(f, rgb_linear, exposure)
    return path


def png_bytes(rgb_linear, exposure: float = 0.0) -> bytes:
    """The PNG :func:`write_png` writes, in memory (what a notebook displays).

    Parameters
    ----------
    rgb_linear, exposure
        As for :func:`write_png`.

    Returns
    -------
    bytes
    """
    buf = io.BytesIO()
    _save_png(buf, rgb_linear, exposure)
    return buf.getvalue()


def _save_png(f, rgb_linear, exposure):
    a = np.asarray(rgb_linear)
    image = _png_image(a if a.dtype == np.uint8 else to_srgb8(a, exposure))
    info = PngInfo()
    for kind, data in _SRGB_CHUNKS:
        info.add(kind, data)
    image.save(f, format="PNG", pnginfo=info)
