"""Small shared helpers for the test-suite (no fixtures: plain functions)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO / "scenes"


def variant():
    """Select the default variant and register our plugins (once)."""
    from arches_render.render.plugins import ensure_registered
    return ensure_registered()


def random_points(n, lo, hi, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(lo, hi, size=(n, 3))
