"""Denoised beauty from Intel Open Image Denoise (OIDN), guided by albedo and normal AOVs.

The ``RT`` filter of OIDN takes the noisy linear beauty and two feature images of
the primary hits, the albedo and the shading normal (see
:mod:`arches_render.render.aovs`), and predicts the converged image. Our renders are
HDR (sun and sky radiance is not bounded by 1), so the filter runs in HDR mode; the
AOVs are averaged over as many samples as the beauty, hence not noise-free
(``clean_aux = False`` lets OIDN prefilter them).

The denoised image is an extra EXR layer (``denoised``): the raw beauty always
stays in ``R, G, B``, and golden tests compare the raw beauty only.

References
----------
Áfra, A. T. (2024). Intel Open Image Denoise, https://www.openimagedenoise.org
(``RT`` filter: ``color``, ``albedo``, ``normal``, ``hdr``, ``cleanAux``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["denoise"]


def denoise(beauty, albedo=None, normal=None, quality: str = "high") -> np.ndarray:
    """Denoise a linear HDR render with OIDN's ``RT`` filter.

    Parameters
    ----------
    beauty : array_like
        Linear Rec.709 radiance, ``(H, W, 3)``, non-negative.
    albedo : array_like, optional
        Albedo AOV in [0, 1], ``(H, W, 3)``.
    normal : array_like, optional
        Shading-normal AOV in [-1, 1], ``(H, W, 3)`` (needs ``albedo``).
    quality : {'high', 'balanced', 'fast'}
        OIDN quality preset.

    Returns
    -------
    numpy.ndarray
        float32 ``(H, W, 3)`` denoised radiance.

    Raises
    ------
    ValueError
        For mismatched shapes or a normal without albedo.

    References
    ----------
    Intel Open Image Denoise, ``RT`` filter (see module references).
    """
    import pyoidn  # on use: loads the OIDN library, only --denoise needs it

    c = np.ascontiguousarray(np.clip(np.nan_to_num(beauty, nan=0.0), 0.0, None), dtype=np.float32)
    if c.ndim != 3 or c.shape[2] != 3:
        raise ValueError(f"denoise: beauty must be (H, W, 3), got {c.shape}")
    aux = []
    for name, a, lo, hi in (("albedo", albedo, 0.0, 1.0), ("normal", normal, -1.0, 1.0)):
        if a is None:
            aux.append(None)
            continue
        a = np.ascontiguousarray(np.clip(np.nan_to_num(a, nan=0.0), lo, hi), dtype=np.float32)
        if a.shape != c.shape:
            raise ValueError(f"denoise: {name} has shape {a.shape}, the beauty {c.shape}")
        aux.append(a)
    if aux[1] is not None and aux[0] is None:
        raise ValueError("denoise: OIDN needs the albedo to use the normal")
    out = pyoidn.denoise(c, aux[0], aux[1], hdr=True, clean_aux=False, quality=quality)
    return np.asarray(out, dtype=np.float32)
