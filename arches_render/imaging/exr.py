"""OpenEXR input and output for renders, AOV layers and golden references.

Pixels are linear Rec.709 (Mitsuba's ``rgb`` film), stored as half floats with
lossless ZIP compression by default: half keeps 11 significant bits (relative
error <= 2**-11 ~ 0.05 %), far below the Monte Carlo noise of any render we
compare, and halves the size of the goldens kept in git.

Our metadata (scene, seed, spp, version, camera, ...) is stored as string
attributes named ``arches:<key>``. The prefix keeps them clear of the attribute
names OpenEXR reserves or types: a string attribute called ``version`` or
``chunkCount`` is silently dropped by the library, and ``owner`` or
``capDate`` have meanings of their own.

Typed OpenEXR standard attributes (``worldToCamera``, ``screenWindowWidth``, ...)
go in under their own names through ``attributes``, with the Python types the
OpenEXR bindings map to attribute types: a float32 ``(4, 4)`` array becomes an
``M44f`` (Imath layout: ``a[i, j]`` is ``x[i][j]``, for row vectors), a float32
``(2,)`` array a ``V2f``, a Python ``float`` a ``float`` (NumPy scalars are
refused by the bindings, hence the conversion here).

References
----------
.. [1] Kainz, F., Bogart, R., Stanczyk, P., Hillman, P. "Technical Introduction
   to OpenEXR", https://openexr.com/en/latest/TechnicalIntroduction.html
.. [2] "The OpenEXR Python Module", https://openexr.com/en/latest/python.html
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence, Union

import numpy as np

from ..atomic import atomic_write

__all__ = ["ExrImage", "ExrError", "write_exr", "read_exr", "HEADER_PREFIX", "HALF_MAX"]

HEADER_PREFIX = "arches:"
"""Prefix of the names under which :func:`write_exr` stores caller metadata."""

HALF_MAX = 65504.0
"""Largest finite half-float value; larger pixel values are clipped to it."""

# Attributes that describe the file layout rather than the image content; the
# reader never reports them as metadata.
_STRUCTURAL = frozenset({
    "channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
    "screenWindowCenter", "screenWindowWidth", "type", "name", "version", "chunkCount", "tiles",
})

_LETTER_ORDER = {c: i for i, c in enumerate("RGBAXYZUVW")}

# Default channel letters of a layer, by its number of components.
_DEFAULT_LETTERS = {1: ("Y",), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}

LayerSpec = Union[np.ndarray, "tuple[np.ndarray, Sequence[str] | str]"]


class ExrError(ValueError):
    """An EXR file is missing, unreadable or lacks the expected channels."""


@dataclass
class ExrImage:
    """An image read by :func:`read_exr`.

    Attributes
    ----------
    rgb : numpy.ndarray
        Linear Rec.709 colour, float32, shape ``(H, W, 3)``.
    header : dict of str to str
        Caller metadata written by :func:`write_exr` (prefix removed), plus the
        other string attributes a foreign writer may have stored.
    layers : dict of str to numpy.ndarray
        Extra layers, float32: ``(H, W)`` for a one-channel layer, ``(H, W, C)``
        otherwise, in the channel order given by :attr:`layer_channels`.
    layer_channels : dict of str to tuple of str
        Channel letters of each layer, e.g. ``('R', 'G', 'B')`` or ``('X', 'Y', 'Z')``.
    path : pathlib.Path or None
        The file the image was read from.
    """

    rgb: np.ndarray
    header: dict[str, str] = field(default_factory=dict)
    layers: dict[str, np.ndarray] = field(default_factory=dict)
    layer_channels: dict[str, tuple[str, ...]] = field(default_factory=dict)
    path: Path | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)`` of the image."""
        return self.rgb.shape[:2]


def _as_image(rgb, what: str) -> np.ndarray:
    a = np.asarray(rgb)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{what} must be an H x W x 3 array, got shape {a.shape}")
    return a


def _pixels(a: np.ndarray, half: bool) -> np.ndarray:
    a = np.asarray(a, dtype=np.float32)
    if half:
        # Values above the half range would become inf; clipping keeps them
        # finite and visibly saturated. NaNs pass through: they flag a bug that
        # the comparison must see.
        a = np.clip(a, -HALF_MAX, HALF_MAX).astype(np.float16)
    return np.ascontiguousarray(a)


def _layer_channels(name: str, spec: LayerSpec, shape: tuple[int, int],
                    half: bool) -> dict[str, np.ndarray]:
    if not isinstance(name, str) or not name or name.startswith(".") or name.endswith("."):
        raise ValueError(f"layer name {name!r} must be a non-empty string not starting or ending with '.'")
    if isinstance(spec, tuple):
        arr, letters = spec
        letters = tuple(letters)
    else:
        arr, letters = spec, None
    arr = np.asarray(arr)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3 or arr.shape[:2] != shape:
        raise ValueError(f"layer {name!r} has shape {arr.shape}; expected {shape} or {shape + (3,)}")
    n = arr.shape[2]
    if letters is None:
        if n not in _DEFAULT_LETTERS:
            raise ValueError(f"layer {name!r} has {n} channels: pass (array, channel_names)")
        letters = _DEFAULT_LETTERS[n]
    if len(letters) != n or len(set(letters)) != n or not all(isinstance(c, str) and c for c in letters):
        raise ValueError(f"layer {name!r}: {n} channels need {n} distinct names, got {letters!r}")
    return {f"{name}.{c}": _pixels(arr[..., i], half) for i, c in enumerate(letters)}


def write_exr(path: str | os.PathLike, rgb, header: Mapping[str, object] | None = None,
              layers: Mapping[str, LayerSpec] | None = None, half: bool = True,
              full_precision: Sequence[str] = (), attributes: Mapping[str, object] | None = None) -> Path:
    """Write a linear RGB image, metadata and optional layers to an OpenEXR file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ``.exr`` file; its folder must exist. The file appears
        complete or not at all (see :func:`arches_render.atomic.atomic_write`).
    rgb : array_like
        Linear Rec.709 colour, shape ``(H, W, 3)``.
    header : mapping of str to object, optional
        Metadata stored as string attributes ``arches:<key>`` (numbers are
        converted with :func:`str`), e.g. ``{'scene': 'arch', 'seed': 0, 'spp': 4096}``.
    layers : mapping of str to array_like or (array_like, channel names), optional
        Extra layers (AOVs). An ``(H, W)`` or ``(H, W, 1)`` array is written as
        channel ``name.Y``, an ``(H, W, 3)`` array as ``name.R``, ``name.G``,
        ``name.B``; pass ``(array, 'XYZ')`` to choose the channel letters
        (e.g. for normals or positions).
    half : bool, optional
        Store every channel as half float (default) rather than float32. Values
        beyond +-65504 are clipped to it; use ``half=False`` for data such as
        world positions or depth that need more than 11 significant bits.
    full_precision : sequence of str, optional
        Layers stored as float32 even when ``half`` is true; ``'rgb'`` names the
        colour channels (a golden reference keeps its mean in float32, its
        variances in half).
    attributes : mapping of str to object, optional
        Typed attributes stored under their own names, e.g. the OpenEXR standard
        ``worldToCamera`` (float32 ``(4, 4)`` array: M44f), ``screenWindowCenter``
        (float32 ``(2,)``: V2f) or ``nearClip`` (float). Names starting with
        :data:`HEADER_PREFIX` or naming a structural attribute are refused.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        For a malformed image, layer, or header key.

    Notes
    -----
    Compression is ZIP (lossless, 16 scanlines per block), which every EXR
    reader supports.

    References
    ----------
    Kainz et al., "Technical Introduction to OpenEXR" (see the module references).
    """
    import OpenEXR  # on use: keeps the golden harness (conftest) light

    rgb = _as_image(rgb, "rgb")
    shape = rgb.shape[:2]
    full = set(full_precision)
    unknown = full - {"rgb"} - set(layers or {})
    if unknown:
        raise ValueError(f"full_precision names layers that are not written: {sorted(unknown)}")
    channels = {c: _pixels(rgb[..., i], half and "rgb" not in full) for i, c in enumerate("RGB")}
    for name, spec in (layers or {}).items():
        new = _layer_channels(name, spec, shape, half and name not in full)
        clash = set(new) & set(channels)
        if clash:
            raise ValueError(f"layer {name!r} repeats channels {sorted(clash)}")
        channels.update(new)
    attrs: dict[str, object] = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (header or {}).items():
        if not isinstance(key, str) or not key:
            raise ValueError(f"header keys must be non-empty strings, got {key!r}")
        attrs[HEADER_PREFIX + key] = value if isinstance(value, str) else str(value)
    for key, value in (attributes or {}).items():
        if not isinstance(key, str) or not key or key.startswith(HEADER_PREFIX) or key in _STRUCTURAL - {
                "screenWindowCenter", "screenWindowWidth"}:
            raise ValueError(f"attribute name {key!r} is reserved or empty")
        attrs[key] = _typed(key, value)
    exr = OpenEXR.File(attrs, channels)
    path = Path(path)
    with atomic_write(path, "wb") as f:
        exr.write(f)
    return path


def _typed(key: str, value):
    # The bindings pick the attribute type from the Python type: matrices and
    # vectors must be float32 arrays of the right shape, scalars Python floats.
    if isinstance(value, np.ndarray) or isinstance(value, (list, tuple)):
        a = np.ascontiguousarray(value, np.float32)
        if a.shape not in ((4, 4), (2,), (3,)):
            raise ValueError(f"attribute {key!r}: arrays must be 4x4, 2 or 3 long, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"attribute {key!r} is not finite: {a}")
        return a
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating, str)):
        raise ValueError(f"attribute {key!r} has unsupported type {type(value).__name__}")
    return value if isinstance(value, str) else float(value)


def _header_strings(raw: Mapping[str, object]) -> dict[str, str]:
    ours = {k[len(HEADER_PREFIX):]: str(v) for k, v in raw.items() if k.startswith(HEADER_PREFIX)}
    foreign = {k: v for k, v in raw.items()
               if isinstance(v, str) and k not in _STRUCTURAL and not k.startswith(HEADER_PREFIX)}
    # Our own keys win when a foreign writer used the same bare name.
    return {**foreign, **ours}


def read_exr(path: str | os.PathLike) -> ExrImage:
    """Read an OpenEXR file written by :func:`write_exr` (or any RGB EXR).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.exr`` file. Only the first part of a multi-part file is read.

    Returns
    -------
    ExrImage
        Colour as float32 ``(H, W, 3)``, the metadata, and the layers.
        Channels that belong to no layer and are not ``R``, ``G``, ``B`` (e.g.
        ``A`` or ``Z``) become one-channel layers under their own name.

    Raises
    ------
    ExrError
        (a :class:`ValueError`) naming the file when it is missing, not an EXR
        file, damaged, or has no ``R``, ``G``, ``B`` channels.
    """
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise ExrError(f"EXR file {path} does not exist")
    try:
        exr = OpenEXR.File(str(path), separate_channels=True)
        raw_header = exr.header()
        raw = {name: np.asarray(ch.pixels) for name, ch in exr.channels().items()}
    except Exception as e:  # the bindings raise RuntimeError / TypeError without the path
        raise ExrError(f"cannot read EXR file {path}: {e}") from e
    missing = [c for c in "RGB" if c not in raw]
    if missing:
        raise ExrError(f"EXR file {path} has no channel(s) {missing}; channels: {sorted(raw)}")
    rgb = np.stack([raw.pop(c) for c in "RGB"], axis=-1).astype(np.float32)

    groups: dict[str, list[str]] = {}
    for name in raw:
        layer, _, letter = name.rpartition(".")
        groups.setdefault(layer or letter, []).append(letter if layer else "")
    layers, letters_of = {}, {}
    for layer, letters in groups.items():
        if letters == [""]:  # a bare channel such as 'A' or 'Z'
            layers[layer], letters_of[layer] = raw[layer].astype(np.float32), (layer,)
            continue
        # The file stores channels sorted by name; restore the usual order
        # (R, G, B, A / X, Y, Z), unknown names last.
        order = sorted(letters, key=lambda c: (_LETTER_ORDER.get(c, len(_LETTER_ORDER)), c))
        stack = [raw[f"{layer}.{c}"] for c in order]
        arr = stack[0] if len(stack) == 1 else np.stack(stack, axis=-1)
        layers[layer], letters_of[layer] = arr.astype(np.float32), tuple(order)
    return ExrImage(rgb=rgb, header=_header_strings(raw_header), layers=layers,
                    layer_channels=letters_of, path=path)
