"""Procedural heightmaps from the field language's fBm.

The heightmap samples the same :class:`~arches_render.field.Noise` node that scenes
use elsewhere (one construction tree, one noise), on the plane ``z = 0``:

    h(x, y) = offset + amplitude * shape(n(x, y)),

where ``n`` is fBm normalized to about ``[0, 1]``, ``shape`` optionally folds it into
ridges (``1 - |2n - 1|``, Musgrave's ridged multifractal idea) and raises it to
``power`` (values > 1 widen valleys and sharpen peaks). With ``edge_falloff`` the
relief fades to ``offset`` over that many metres at the border of the tile, so the
tile meets a plain without a cliff.

References
----------
Musgrave, F. K., Kolb, C. E., Mace, R. S. (1989). The synthesis and rendering of
eroded fractal terrains. SIGGRAPH '89.
"""

from __future__ import annotations

import numpy as np


def fbm_heightmap(extent, resolution, amplitude=30.0, wavelength=80.0, octaves=6, lacunarity=2.0,
                  gain=0.5, seed=0, ridged=False, power=1.0, offset=0.0, edge_falloff=0.0):
    """Sample an fBm heightmap.

    Parameters
    ----------
    extent : sequence of 4 floats
        ``(x0, y0, x1, y1)`` in metres.
    resolution : sequence of 2 ints
        ``(nx, ny)`` samples, each >= 2.
    amplitude, offset : float
        Height range and base elevation in metres.
    wavelength : float
        Period of the first octave in metres.
    octaves : int
        fBm octaves.
    lacunarity, gain : float
        Frequency and amplitude ratios between octaves.
    seed : int
        Noise seed: the same seed gives the same heights.
    ridged : bool
        Fold the noise into ridges.
    power : float
        Exponent applied to the normalized noise.
    edge_falloff : float
        Width in metres of the border over which the relief fades out (0: none).

    Returns
    -------
    numpy.ndarray
        ``(ny, nx)`` float64 heights.
    """
    from arches_render.field import Noise, evaluate
    from arches_render.field.noise import fbm_range

    x0, y0, x1, y1 = extent
    nx, ny = int(resolution[0]), int(resolution[1])
    xs, ys = np.linspace(x0, x1, nx), np.linspace(y0, y1, ny)
    X, Y = np.meshgrid(xs, ys)
    pts = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    noise = Noise(1.0, wavelength, octaves, lacunarity, gain, seed)
    n = evaluate(noise, pts).astype(np.float64).reshape(ny, nx)
    # Gradient noise rarely exceeds ~0.7 of its bound: map that range onto [0, 1].
    typical = 0.7 * fbm_range(octaves, gain) / 1.5
    u = np.clip(0.5 + 0.5 * n / typical, 0.0, 1.0)
    if ridged:
        u = 1.0 - np.abs(2.0 * u - 1.0)
    u = u ** float(power)
    if edge_falloff > 0:
        border = np.minimum(np.minimum(X - x0, x1 - X), np.minimum(Y - y0, y1 - Y))
        t = np.clip(border / edge_falloff, 0.0, 1.0)
        u = u * t * t * (3.0 - 2.0 * t)
    return offset + amplitude * u
