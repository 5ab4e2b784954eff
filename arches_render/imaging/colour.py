"""Named view transforms: from linear Rec.709 renders to display-referred previews.

Mitsuba's ``rgb`` variants render linear Rec.709 (sRGB primaries, D65). A preview
(PNG, MP4) needs a *view transform* that maps scene-linear values to display code
values. The views:

==================  ====================================================================
name                transform
==================  ====================================================================
``srgb``            (default) exposure, clip to [0, 1], sRGB transfer function
                    (IEC 61966-2-1) computed by colour-science: no tone mapping, so the
                    preview shows the numbers the golden tests compare
``aces``            ACES 2.0 output transform, SDR 100 nits, Rec.709 / sRGB display
``aces-p3``         ACES 2.0 output transform, SDR 100 nits, Display P3
``untonemapped``    OpenColorIO's "Un-tone-mapped" view of the sRGB display (the same
                    numbers as ``srgb``, through OCIO: a cross-check of the config)
==================  ====================================================================

The ACES views come from OpenColorIO's built-in config ``studio-config-latest``,
which ships inside the ``opencolorio`` wheel: nothing is downloaded. The render's
colour space in that config is ``Linear Rec.709 (sRGB)``.

References
----------
.. [1] IEC 61966-2-1:1999, Default RGB colour space - sRGB.
.. [2] Academy Color Encoding System, ACES 2.0 Output Transforms,
   https://docs.acescentral.com/
.. [3] OpenColorIO, "Built-in configs",
   https://opencolorio.readthedocs.io/en/latest/guides/using_ocio/builtin_configs.html
"""

from __future__ import annotations

import functools

import numpy as np

from .preview import encode_srgb

__all__ = ["VIEWS", "DEFAULT_VIEW", "OCIO_CONFIG", "RENDER_COLORSPACE", "apply_view", "view_to_uint8",
           "ocio_config"]

OCIO_CONFIG = "studio-config-latest"
"""Name of the OpenColorIO built-in config of the ACES views."""

RENDER_COLORSPACE = "Linear Rec.709 (sRGB)"
"""Colour space of Mitsuba's ``rgb`` output in :data:`OCIO_CONFIG`."""

DEFAULT_VIEW = "srgb"

#: View name -> ``None`` (colour-science sRGB) or an OCIO ``(display, view)``.
VIEWS = {
    "srgb": None,
    "aces": ("sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)"),
    "aces-p3": ("Display P3 - Display", "ACES 2.0 - SDR 100 nits (P3 D65)"),
    "untonemapped": ("sRGB - Display", "Un-tone-mapped"),
}


@functools.lru_cache(maxsize=1)
def ocio_config():
    """OpenColorIO's built-in :data:`OCIO_CONFIG` (loaded offline from the wheel).

    Returns
    -------
    PyOpenColorIO.Config
    """
    import PyOpenColorIO as ocio  # on use: only the ACES views need it
    return ocio.Config.CreateFromBuiltinConfig(OCIO_CONFIG)


@functools.lru_cache(maxsize=8)
def _cpu_processor(display: str, view: str):
    import PyOpenColorIO as ocio
    proc = ocio_config().getProcessor(RENDER_COLORSPACE, display, view, ocio.TRANSFORM_DIR_FORWARD)
    return proc.getDefaultCPUProcessor()


def apply_view(rgb_linear, view: str = DEFAULT_VIEW, exposure: float = 0.0) -> np.ndarray:
    """Display-referred values of a linear Rec.709 image under a named view.

    Parameters
    ----------
    rgb_linear : array_like
        Linear Rec.709 colour, ``(H, W, 3)``.
    view : str
        A key of :data:`VIEWS`.
    exposure : float
        Exposure in stops applied first (``2 ** exposure``).

    Returns
    -------
    numpy.ndarray
        float32 display code values in [0, 1], shape ``(H, W, 3)``.

    Raises
    ------
    ValueError
        For an unknown view (the message lists the views).

    References
    ----------
    IEC 61966-2-1:1999 (``srgb``); ACES 2.0 output transforms through OpenColorIO's
    ``studio-config-latest`` (the other views).
    """
    if view not in VIEWS:
        raise ValueError(f"unknown view '{view}'; allowed: {', '.join(VIEWS)}")
    if VIEWS[view] is None:
        return encode_srgb(rgb_linear, exposure).astype(np.float32)
    x = np.asarray(rgb_linear, dtype=np.float32) * np.float32(2.0 ** float(exposure))
    # OCIO works in place on a contiguous float32 RGB buffer.
    x = np.ascontiguousarray(np.nan_to_num(x, nan=0.0, posinf=HUGE, neginf=0.0), dtype=np.float32)
    _cpu_processor(*VIEWS[view]).applyRGB(x)
    return np.clip(x, 0.0, 1.0)


HUGE = 65504.0  # +inf stand-in that keeps OCIO's arithmetic finite


def view_to_uint8(rgb_linear, view: str = DEFAULT_VIEW, exposure: float = 0.0) -> np.ndarray:
    """8-bit display image of a linear render under a named view (see :func:`apply_view`).

    Returns
    -------
    numpy.ndarray
        uint8 ``(H, W, 3)``.
    """
    return np.round(apply_view(rgb_linear, view, exposure) * 255.0).astype(np.uint8)
