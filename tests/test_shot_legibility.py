"""Legibility of close-shot views (``generators/terrain/shots.py``, :func:`legibility`,
issue 34) on synthetic ray grids: sky, background, one sheet and the landform's contrast."""

from __future__ import annotations

import numpy as np


def test_legibility_rejects_a_slope_that_fills_the_frame_and_keeps_a_landscape():
    """``shots.legibility`` on three ray grids: a plane seen square on (one sheet, no sky,
    no background) and a hillside seen obliquely under a strip of sky (its distances span
    over twice: the depth ratio that judged views before passed it) are not legible; a
    view over receding ground with a block in front and sky above is."""
    from arches_render.generators.terrain.shots import LEGIBLE, legibility
    h, w = 18, 32
    v = np.linspace(0.4, -0.4, h)[:, None] * np.ones((1, w))
    u = np.ones((h, 1)) * np.linspace(-0.5, 0.5, w)[None]
    D = np.stack([np.ones((h, w)), u, v], axis=-1)
    D /= np.linalg.norm(D, axis=-1, keepdims=True)
    # A wall 20 m ahead across the whole frame.
    wall_t = 20.0 / D[..., 0]
    # Ground 10 m below the camera, a block 30 m ahead in the middle columns, sky above.
    down = D[..., 2] < -1e-3
    ground_t = np.where(down, 10.0 / np.maximum(-D[..., 2], 1e-9), np.inf)
    block = (np.abs(u) < 0.15) & (v > -0.2) & (v < 0.1)
    view_t = np.where(block, 30.0 / D[..., 0], ground_t)
    # A hillside at 38 degrees, its contours 30 degrees off the view axis and its foot
    # 35 m ahead at the camera's height, up to its crest 20 m above: sky beyond.
    k, c, s = np.tan(np.radians(38)), np.cos(np.radians(30)), np.sin(np.radians(30))
    rise = k * c * D[..., 0] + k * s * D[..., 1] - D[..., 2]
    with np.errstate(divide="ignore"):
        slope_t = np.where(rise > 0, k * c * 35.0 / rise, np.inf)
    slope_t = np.where(slope_t * D[..., 2] <= 20.0, slope_t, np.inf)
    t = np.stack([wall_t, view_t, slope_t])
    hit = np.isfinite(t)
    out = legibility(np.stack([D, D, D]), np.where(hit, t, np.inf), hit)
    assert not out["legible"][0] and out["one_surface"][0] > 0.9 and out["sky"][0] == 0.0
    assert out["background"][0] == 0.0
    assert out["legible"][1], {k: v[1] for k, v in out.items()}
    assert out["background"][1] >= LEGIBLE["background"]
    assert not out["legible"][2]
    assert out["sky"][2] >= LEGIBLE["sky"] and out["depth"][2] > 2.0, {k: v[2] for k, v in out.items()}
    assert out["background"][2] < LEGIBLE["background"], {k: v[2] for k, v in out.items()}


def test_legibility_judges_the_landforms_contrast_against_its_surroundings():
    """The landform's contrast (``shots.legibility``): on the receding-ground view of the
    test above, a block standing before the ground stands off it (its outline breaks in
    depth all round: contrast 1, legible); the same rays with the landform a patch of the
    ground itself (its distances run on across the outline, and so do the normals) have
    none and are not legible, though sky, background and sheets are the same; turned 60
    degrees from the ground (a crease all round) it has contrast 1; a frame the landform
    fills, or one without it, has 0."""
    from arches_render.generators.terrain.shots import LEGIBLE, legibility
    h, w = 18, 32
    v = np.linspace(0.4, -0.4, h)[:, None] * np.ones((1, w))
    u = np.ones((h, 1)) * np.linspace(-0.5, 0.5, w)[None]
    D = np.stack([np.ones((h, w)), u, v], axis=-1)
    D /= np.linalg.norm(D, axis=-1, keepdims=True)
    down = D[..., 2] < -1e-3
    ground_t = np.where(down, 10.0 / np.maximum(-D[..., 2], 1e-9), np.inf)
    block = (np.abs(u) < 0.15) & (v > -0.2) & (v < 0.1)
    view_t = np.where(block, 30.0 / D[..., 0], ground_t)
    patch = (np.abs(u) < 0.2) & (v < -0.25)
    t = np.stack([view_t, ground_t, ground_t, ground_t])
    hit = np.isfinite(t)
    landform = np.stack([block, patch, np.ones_like(block), np.zeros_like(block)])
    out = legibility(np.stack([D] * 4), t, hit, landform)
    assert out["contrast"][0] == 1.0 and out["legible"][0], {k: v[0] for k, v in out.items()}
    assert out["contrast"][1] < 0.05 and not out["legible"][1], {k: v[1] for k, v in out.items()}
    for k in (1, 2, 3):
        assert out["sky"][k] >= LEGIBLE["sky"] and out["one_surface"][k] <= LEGIBLE["one_surface"]
        assert out["background"][k] >= LEGIBLE["background"], {k_: v[k] for k_, v in out.items()}
    assert out["contrast"][2] == 0.0 and out["contrast"][3] == 0.0
    # The same patch turned 60 degrees from the ground (a hollow's wall, lit apart from
    # it): its outline is a crease, and the view is legible.
    n = np.zeros((4, h, w, 3))
    n[..., 2] = 1.0
    n[1][patch] = [np.sin(np.radians(60)), 0.0, np.cos(np.radians(60))]
    turned = legibility(np.stack([D] * 4), t, hit, landform, n)
    assert turned["contrast"][1] == 1.0 and turned["legible"][1], {k: v[1] for k, v in turned.items()}
    assert turned["contrast"][0] == 1.0 and turned["contrast"][2] == 0.0
    # Without the landform's rays no contrast is judged (as before).
    assert legibility(D[None], ground_t[None], hit[1][None])["legible"][0]
