"""What a render layer looks like on a screen: 8-bit pictures of the beauty and of its AOVs.

The preview (:mod:`arches_render.preview`) shows any layer of a render
(:mod:`arches_render.render.aovs`) in the browser. Colour layers (``albedo``,
``beauty_clear``, ``transmittance``) are linear and get the sRGB encoding; the
others are data and get the usual false-colour pictures of a lookdev tool:

=================  ===============================================================
layer              picture
=================  ===============================================================
``normal``         ``(n + 1) / 2`` as RGB (a normal map: +X red, +Y green, +Z blue)
``depth``          near bright, far dark: ``1 - (d - d_1) / (d_99 - d_1)`` between the
                   1st and 99th percentiles of the hits; misses black
``position``       each axis scaled to the hits' range
``layers``         each material layer's weight times its colour (rock grey, sand tan,
                   grass green, snow white, ...: :data:`LAYER_COLOURS`), summed
``coverage``       field green, mesh blue
``steps`` and ray  a black-red-yellow-white heat map up to the 99th percentile
counts
=================  ===============================================================

References
----------
IEC 61966-2-1:1999 (sRGB encoding).
"""

from __future__ import annotations

import numpy as np

from .colour import view_to_uint8
from .report import heatmap

__all__ = ["BEAUTY", "DENOISED", "LAYER_COLOURS", "OTHER_COLOURS", "layer_to_uint8"]

#: The name of the beauty among the layers a preview offers.
BEAUTY = "beauty"
#: The denoised beauty (``arches-render render --denoise``'s layer): shown as the beauty is.
DENOISED = "denoised"

#: Colours of the usual material layers in the ``layers`` picture, by name.
LAYER_COLOURS = {"rock": (0.5, 0.5, 0.5), "sand": (0.9, 0.75, 0.45), "grass": (0.25, 0.65, 0.2),
                 "snow": (0.97, 0.97, 1.0), "scree": (0.65, 0.55, 0.5), "soil": (0.5, 0.32, 0.2),
                 "moss": (0.45, 0.55, 0.15), "ice": (0.6, 0.85, 1.0)}
#: Colours of other layers, in their order (then repeated).
OTHER_COLOURS = np.array([[0.85, 0.25, 0.25], [0.3, 0.45, 0.9], [0.6, 0.35, 0.75], [0.2, 0.75, 0.75],
                          [0.9, 0.5, 0.1], [0.8, 0.8, 0.2]])

_COLOUR_LAYERS = ("albedo", "beauty_clear", "transmittance")


def _unit(v: np.ndarray) -> np.ndarray:
    return np.round(np.clip(np.nan_to_num(v), 0.0, 1.0) * 255.0).astype(np.uint8)


def _robust_range(values: np.ndarray) -> tuple[float, float]:
    if values.size == 0:
        return 0.0, 1.0
    lo, hi = np.percentile(values, [1.0, 99.0])
    return float(lo), float(max(hi, lo + 1e-6))


def layer_to_uint8(name: str, array: np.ndarray, view: str = "srgb", exposure: float = 0.0,
                   channels=()) -> np.ndarray:
    """The 8-bit picture of one render layer (module docstring).

    Parameters
    ----------
    name : str
        :data:`BEAUTY`, :data:`DENOISED` or an AOV layer name (``albedo``, ``normal``,
        ``depth``, ...).
    array : numpy.ndarray
        ``(H, W, C)`` float values of the layer.
    view, exposure
        View transform and exposure (stops) of the beauty
        (:func:`arches_render.imaging.colour.view_to_uint8`); other layers ignore them.
    channels : sequence of str
        The layer's channel names (for ``layers``: the material layers' names, which
        choose their colours, :data:`LAYER_COLOURS`).

    Returns
    -------
    numpy.ndarray
        ``(H, W, 3)`` uint8 sRGB.
    """
    a = np.asarray(array, dtype=np.float32)
    if a.ndim == 2:
        a = a[..., None]
    if name in (BEAUTY, DENOISED):
        return view_to_uint8(a[..., :3], view, exposure)
    if name in _COLOUR_LAYERS:
        return view_to_uint8(a[..., :3], "srgb", 0.0)
    if name == "normal":
        return _unit((a[..., :3] + 1.0) * 0.5)
    if name == "depth":
        d = a[..., 0]
        hit = d > 0
        lo, hi = _robust_range(d[hit])
        v = np.where(hit, 1.0 - (d - lo) / (hi - lo), 0.0)
        return _unit(np.repeat(v[..., None], 3, axis=2))
    if name == "position":
        out = np.zeros(a.shape[:2] + (3,), np.float32)
        hit = np.any(a[..., :3] != 0.0, axis=2)
        for k in range(min(3, a.shape[2])):
            lo, hi = _robust_range(a[..., k][hit])
            out[..., k] = np.where(hit, (a[..., k] - lo) / (hi - lo), 0.0)
        return _unit(out)
    if name == "layers":
        names = list(channels) + [""] * (a.shape[2] - len(channels))
        others = iter(OTHER_COLOURS[np.arange(a.shape[2]) % len(OTHER_COLOURS)])
        colours = np.array([LAYER_COLOURS[n] if n in LAYER_COLOURS else next(others) for n in names[:a.shape[2]]])
        return _unit(np.einsum("hwc,ck->hwk", a, colours))
    if name == "coverage":
        out = np.zeros(a.shape[:2] + (3,), np.float32)
        out[..., 1] = a[..., 0]
        if a.shape[2] > 1:
            out[..., 2] = a[..., 1]
        return _unit(out)
    # Counts (steps, exhausted, unresolved, ...): a heat map of their sum.
    total = a.sum(axis=2)
    return heatmap(total, max(float(np.percentile(total, 99.0)), 1e-6))
