"""Checks of rendered landscape shots (issue 14): sky above, ground below the horizon, no tile walls.

A shot is rendered with AOVs at a low resolution and judged per pixel from the
camera's own geometry (the direction of every pixel) and the AOV layers:

* the *top rows* of an outdoor shot see the sky (no primary hit);
* every pixel whose whole footprint lies below the horizon (all ray directions
  point down by more than ``margin`` pixels) has a hit in all its samples
  (``coverage.field + coverage.mesh == 1``): no view of the sky's lower
  hemisphere;
* no primary hit lies on a wall of the field's bounding prism: its position is
  within ``tol`` of a vertical side of the field's box and its normal faces out
  of that side.
"""

from __future__ import annotations

import math

import numpy as np


def pixel_rays(camera, width, height):
    """Unit directions of the pixel centres and the ``z`` range of each pixel's footprint.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray, numpy.ndarray)
        ``(H, W, 3)`` centre directions, ``(H, W)`` largest and smallest ``d_z``
        over the pixel's four corners (Mitsuba's perspective camera, ``fov`` along x).
    """
    o, t = np.asarray(camera.origin, float), np.asarray(camera.target, float)
    up = np.asarray(camera.up, float)
    fwd = (t - o) / np.linalg.norm(t - o)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, fwd)
    tx = math.tan(math.radians(camera.fov) / 2)
    ty = tx * height / width

    def dirs(u, v):  # u, v in [0, 1] from the top left corner
        d = (fwd[None, None] + ((2 * u - 1) * tx)[..., None] * right[None, None]
             + ((1 - 2 * v) * ty)[..., None] * true_up[None, None])
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    j, i = np.mgrid[0:height, 0:width].astype(float)
    centre = dirs((i + 0.5) / width, (j + 0.5) / height)
    corners = np.stack([dirs((i + a) / width, (j + b) / height)[..., 2] for a in (0, 1) for b in (0, 1)])
    return centre, corners.max(axis=0), corners.min(axis=0)


def render_shots(desc, width, height, spp=1, seed=0) -> dict:
    """Render every camera of ``desc`` with AOVs: ``{name: (beauty, layers)}``.

    One scene is built and its camera moved between shots (a parameter edit): the
    kernels compile once, not once per camera.
    """
    from helpers import variant
    variant()
    from arches_render.render.jobs import set_camera
    from arches_render.render.renderer import build_scene, render_layers
    scene = build_scene(desc, "field", width, height, aovs=True)
    shots = {}
    for name, cam in desc.cameras.items():
        set_camera(scene, cam.origin, cam.target, cam.up, cam.fov)
        rgb, layers = render_layers(scene, spp, seed)
        shots[name] = (np.asarray(rgb), layers)
    return shots


def shot_report(desc, layers, camera, width, height, sky_rows=2, margin=1.0, tol=None):
    """Judge a rendered shot (see the module docstring).

    Parameters
    ----------
    desc : SceneDescription
    layers : dict
        AOV layers of the render (``coverage``, ``position``, ``normal``).
    camera : Camera
    width, height : int
    sky_rows : int
        Top rows that must be sky.
    margin : float
        Pixels below the horizon before a miss counts.
    tol : float, optional
        Distance from a prism side within which a hit counts as on the wall
        (default 2 % of the field box's horizontal size).

    Returns
    -------
    dict
        ``top_sky`` (fraction of the top rows with no hit), ``below_horizon_misses``
        (fraction of the below-horizon pixels not fully covered), ``below_horizon_pixels``,
        ``wall_hits`` (fraction of all pixels whose hit is on a prism wall), ``hits``,
        ``tile_share`` (fraction of the ground pixels whose hit lies over the field's box,
        not the far field around it).
    """
    cov = layers["coverage"][0].sum(axis=-1)
    _, zmax, _ = pixel_rays(camera, width, height)
    pix = math.radians(camera.fov) / width
    below = zmax < -math.sin(margin * pix)
    out = dict(top_sky=float((cov[:sky_rows] == 0).mean()),
               below_horizon_pixels=int(below.sum()),
               below_horizon_misses=float((cov[below] < 0.999).mean()) if below.any() else 0.0,
               hits=float((cov > 0).mean()))
    walls = 0.0
    if desc.field is not None:
        lo, hi = (np.asarray(v, float) for v in desc.field.bounds())
        tol = 0.02 * float(max(hi[0] - lo[0], hi[1] - lo[1])) if tol is None else tol
        P = layers["position"][0]
        N = layers["normal"][0]
        fcov = layers["coverage"][0][..., 0]
        on = np.zeros(P.shape[:2], bool)
        for axis in (0, 1):
            for side, sign in ((lo[axis], -1.0), (hi[axis], 1.0)):
                near = np.abs(P[..., axis] - side) < tol
                facing = sign * N[..., axis] > 0.8
                on |= near & facing & (fcov > 0.5)
        walls = float(on.mean())
        ground = cov > 0.5  # the field's and the meshes' (the far field is a mesh)
        over = ((P[..., 0] >= lo[0]) & (P[..., 0] <= hi[0]) & (P[..., 1] >= lo[1]) & (P[..., 1] <= hi[1]))
        out["tile_share"] = float((over & ground).sum() / max(ground.sum(), 1))
    out["wall_hits"] = walls
    return out


def skyline_report(rgb, layers, band=1):
    """Where a shot's ground meets its sky: how flat that line is, what makes it, and how
    much it stands out (issue 34: an overview's far field fades into haze, never a ruled
    line against the sky).

    Per column, the skyline is the first row from the top with a hit in every sample
    (``coverage``), below at least ``band + 1`` rows of sky (no hit at all); its
    contrast is ``|L_ground - L_sky| / L_sky`` of the luminances (Rec. 709) of the
    ``band`` rows just below and just above it.

    Returns
    -------
    dict
        ``skyline_columns`` (share of columns with such a skyline), ``skyline_flat``
        (share of those within a row of the median skyline row), ``skyline_far`` (share
        of those whose ground below the skyline is the far field, a mesh) and
        ``skyline_contrast`` (median contrast; 0 without a skyline).
    """
    cov = layers["coverage"][0]
    full, mesh = cov.sum(axis=-1) > 0.999, cov[..., 1] > 0.5
    none = cov.sum(axis=-1) == 0.0
    lum = np.asarray(rgb, np.float64)[..., :3] @ [0.2126, 0.7152, 0.0722]
    rows, far, contrast = [], [], []
    for c in range(full.shape[1]):
        hit = np.flatnonzero(full[:, c])
        r = int(hit[0]) if hit.size else -1
        if r <= band or r + band >= full.shape[0] or not none[r - band - 1:r - 1, c].all():
            continue
        sky = lum[r - band - 1:r - 1, c].mean()
        ground = lum[r + 1:r + 1 + band, c].mean()
        rows.append(r)
        far.append(bool(mesh[r + 1:r + 1 + band, c].all()))
        contrast.append(abs(ground - sky) / max(sky, 1e-6))
    if not rows:
        return dict(skyline_columns=0.0, skyline_flat=0.0, skyline_far=0.0, skyline_contrast=0.0)
    rows = np.asarray(rows)
    return dict(skyline_columns=len(rows) / full.shape[1],
                skyline_flat=float(np.mean(np.abs(rows - np.median(rows)) <= 1)),
                skyline_far=float(np.mean(far)), skyline_contrast=float(np.median(contrast)))
