"""Metered exposure: the stops a camera's averaging meter would set for a render.

A reflected-light meter assumes the scene averages to middle grey. With ``Y`` the
Rec. 709 luminance of each pixel of the linear beauty, the log-average luminance

    Y_avg = exp(mean(log(delta + Y))),

(a geometric mean: a bright sky and dark rock weigh by their ratios, not their
differences) is mapped to the key value ``a`` (0.18, middle grey):

    exposure = log2(a / Y_avg)    stops,

clamped to ``[-MAX_STOPS, MAX_STOPS]``. A scene's ``[render] exposure`` overrides it;
the value used is written to the render's EXR header (``exposure``) beside whether it
was metered.

References
----------
Reinhard, E., Stark, M., Shirley, P., Ferwerda, J. (2002). Photographic tone
reproduction for digital images. ACM TOG 21(3), 267-276 (log-average luminance,
key value 0.18).
ITU-R BT.709-6 (2015). Luminance weights.
"""

from __future__ import annotations

import math

import numpy as np

from .compare import LUMINANCE_WEIGHTS

__all__ = ["KEY_VALUE", "MAX_STOPS", "metered_exposure", "exposure_of"]

#: Middle grey: what the log-average luminance is exposed to.
KEY_VALUE = 0.18
#: Largest correction a meter applies, in stops either way.
MAX_STOPS = 8.0
#: Keeps log() finite on black pixels (a thousandth of middle grey).
DELTA = 1.8e-4


def metered_exposure(rgb, key: float = KEY_VALUE) -> float:
    """Exposure in stops that maps the log-average luminance of ``rgb`` to ``key``.

    Parameters
    ----------
    rgb : numpy.ndarray
        ``(H, W, 3)`` linear Rec. 709 beauty (NaN or negative values count as black).
    key : float
        Key value, the grey the average is exposed to.

    Returns
    -------
    float
        Stops, in ``[-MAX_STOPS, MAX_STOPS]`` (0 for an empty image).
    """
    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.size == 0:
        return 0.0
    y = np.tensordot(np.nan_to_num(rgb[..., :3], nan=0.0, posinf=0.0, neginf=0.0), LUMINANCE_WEIGHTS, axes=1)
    y_avg = math.exp(float(np.mean(np.log(DELTA + np.maximum(y, 0.0)))))
    return float(np.clip(math.log2(key / y_avg), -MAX_STOPS, MAX_STOPS))


def exposure_of(settings, rgb) -> tuple[float, bool]:
    """``(stops, metered)``: a scene's ``[render] exposure`` if it sets one, else the
    metered exposure of ``rgb``."""
    if settings.exposure is not None:
        return float(settings.exposure), False
    return metered_exposure(rgb), True
