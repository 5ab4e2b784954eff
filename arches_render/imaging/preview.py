"""Display previews of linear renders: sRGB encoding and PNG output.

The encoding is colour-science's sRGB transfer function (IEC 61966-2-1) applied
after exposure and clipping to [0, 1]; no tone mapping, so a preview shows the
numbers the golden tests compare, with highlights above 1 clipped.

PNGs are written by a small encoder on top of :mod:`zlib`: it writes to a file
object, so the output goes through :func:`arches_render.atomic.atomic_write`
directly, and it needs no Mitsuba import. Importing Mitsuba loads Dr.Jit and
libLLVM, which :func:`arches_render.backend.set_variant` must do first (it
picks the libLLVM), so an image helper must not trigger it. (Mitsuba's
``mi.util.write_bitmap`` also writes asynchronously by default.)

References
----------
.. [1] IEC 61966-2-1:1999, Multimedia systems and equipment - Colour
   measurement and management - Part 2-1: Default RGB colour space - sRGB.
.. [2] W3C, "Portable Network Graphics (PNG) Specification (Third Edition)",
   https://www.w3.org/TR/png-3/
"""

from __future__ import annotations

import os
import struct
import warnings
import zlib
from pathlib import Path

import numpy as np

from ..atomic import atomic_write

__all__ = ["encode_srgb", "to_srgb8", "write_png", "encode_png"]


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


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def encode_png(pixels: np.ndarray, srgb: bool = True) -> bytes:
    """Encode 8-bit pixels as a PNG file.

    Parameters
    ----------
    pixels : numpy.ndarray
        uint8 array, ``(H, W)`` (grey), ``(H, W, 3)`` (RGB) or ``(H, W, 4)`` (RGBA).
    srgb : bool, optional
        Tag the image as sRGB (``sRGB`` and ``gAMA`` chunks) so viewers do not
        re-interpret its colours.

    Returns
    -------
    bytes
        The PNG file.

    Raises
    ------
    ValueError
        For another dtype or shape.

    References
    ----------
    W3C PNG Specification (Third Edition), sections 5 (chunks), 7.3 (filtering)
    and 11.3.2 (``sRGB``/``gAMA``).
    """
    a = np.asarray(pixels)
    if a.dtype != np.uint8:
        raise ValueError(f"encode_png needs uint8 pixels, got {a.dtype}")
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[2] not in (1, 3, 4) or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"encode_png needs (H, W), (H, W, 3) or (H, W, 4) pixels, got {a.shape}")
    h, w, c = a.shape
    colour_type = {1: 0, 3: 2, 4: 6}[c]
    rows = a.reshape(h, w * c)
    # Filter type 2 ("Up") for every row: smooth renders compress better as
    # differences to the previous row, and it is one numpy subtraction.
    up = rows.copy()
    up[1:] -= rows[:-1]  # uint8 arithmetic wraps modulo 256, as the filter requires
    raw = np.concatenate([np.full((h, 1), 2, np.uint8), up], axis=1).tobytes()
    out = [b"\x89PNG\r\n\x1a\n", _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, colour_type, 0, 0, 0))]
    if srgb:
        out += [_chunk(b"sRGB", b"\x00"), _chunk(b"gAMA", struct.pack(">I", 45455))]
    out += [_chunk(b"IDAT", zlib.compress(raw, 6)), _chunk(b"IEND", b"")]
    return b"".join(out)


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

    References
    ----------
    IEC 61966-2-1:1999; W3C PNG Specification (Third Edition).
    """
    a = np.asarray(rgb_linear)
    pixels = a if a.dtype == np.uint8 else to_srgb8(a, exposure)
    data = encode_png(pixels)
    path = Path(path)
    with atomic_write(path, "wb") as f:
        f.write(data)
    return path
