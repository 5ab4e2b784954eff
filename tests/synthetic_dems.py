"""Synthetic DEMs of the kinds of relief real users bring, shared by the terrain tests."""

from __future__ import annotations

import numpy as np


def caldera(n=64, cell=150.0):
    """A volcanic cone 9.6 km across with a caldera 2.8 km wide and 500 m deep: flanks of
    ~14 deg, inner walls of 30-60 deg that are ~3 % of the land, a floor with a little relief."""
    x = (np.arange(n) - (n - 1) / 2) * cell
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X, Y)
    rim = 1400.0 + 60.0 * np.sin(3.0 * np.arctan2(Y, X))
    s = np.clip((r - 0.75 * rim) / (0.25 * rim), 0.0, 1.0)
    H = np.where(r < rim, 1300.0 + 500.0 * (3 * s ** 2 - 2 * s ** 3), 1800.0 - 0.25 * (r - rim))
    return (H + 15.0 * np.sin(X / 700.0) * np.cos(Y / 900.0)).astype(np.float32)
