"""Shots an artist would choose: close views of the landforms an amplification made (issue 14).

``amplify`` writes named cameras: close shots at human or drone height aimed at
the most significant 3-D landforms, and an overview. How they are chosen:

Landforms
    The primitives of the tree (every ``skeletal_set``: carving spheres and
    tunnels, hoodoo symbols, erosion spheres) are binned on a horizontal grid of
    ``G = 10 F`` (``F`` the landform size): a cell is one landform-sized piece of
    coast, canyon wall or cave network. For the 24 fullest cells, the amplified
    field and the plain terrain (DEM and detail, no landform) are sampled on a
    voxel grid over the cell (48 voxels across): the *3-D volume* is the volume of
    air with matter above it in the amplified field (caves, arches, overhangs,
    undercuts) plus, for hoodoos, the matter standing above the plain surface, plus
    a quarter of the ground only lowered (a 2.5-D change).
    Landforms are ranked by it.
Views
    Around the centroid of each landform's primitives, cameras on 16 azimuths at 4
    distances (a feature of size ``F`` spanning about 1/1.5, 1/3, 1/6 and 1/12 of the
    frame's half width, at most 1.5 times the landform's extent) and 5 heights
    above the ground under them (1.7, 6, 20, 60 and 150 m) look at it. A camera
    must stand in air (the amplified field below ``-0.25 m`` there), above any water
    by 0.5 m, over the DEM (not the far field), and look down or up by less than
    ``0.6 x`` half the vertical field of view (else the target is raised or lowered),
    so the horizon is in the frame, and looking up, the ground at a wall's foot. Each
    view casts a 32 x 18 grid of rays
    (Embree) against the mesh of the amplified field around the landform (banded
    polygonization), the DEM mesh of the rest of the tile (not over the landform,
    where the DEM's surface would close the mouths of its caves), the water, and the
    far field's ground around the tile as the scene will show it (a refined crop's
    DEM around it; without it, a crop inside a caldera framed the caldera's far wall
    for sky): its *cover* is
    the fraction of rays whose first hit lies where the amplified field differs
    from the plain terrain (more than 0.75 voxel from the plain surface), its *sky*
    the fraction of the top two rows that escape upwards, its *block* the fraction
    of rays stopped within a fifth of the distance to the landform. Score:
    ``min(cover, 0.45) - max(cover - 0.65, 0)`` times ``(0.5 + 0.5 sky)``, minus
    ``block / 2``; views without sky in the top rows are dropped, and so are views
    that are not *legible* (issue 34, :func:`legibility`): less than 8 % sky in the
    frame, less than 10 % of it *background* (ground at least three times as far as the
    near ground: a slope filling the frame, square on or oblique, has none), more than
    40 % of the frame on one smooth sheet of ground (a slope seen square on), or a
    landform with less than 20 % *contrast* against its surroundings (the share of its
    outline in the frame where the depth steps, the sky begins or the surface creases).
    On the NM canyon DEM this replaced a sand slope filling 70 % of the frame (one
    sheet 57 %) by an undercut outcrop with a stratified mesa behind it, and a camera
    at 1.7 m against a slope (41 %) by one at 6 m that shows the slope's notches, the
    mesa and the sky.
Choice
    The close shots are the best view of each landform in the order of
    ``3-D volume x cover``, then further views of the best landforms (azimuths at
    least 60 degrees apart) until there are ``count``: first among the views that
    frame their landform in :data:`MIN_COVER` of the frame or more, and only where
    those are too few, among views that frame less of it. After the first, a shot is
    the best view of a height class no shot has yet (eye 1.7-6 m, drone 20-60 m,
    aerial 150 m: :data:`HEIGHT_CLASSES`) where one scores at least half the view it
    replaces: on the NM canyon DEM the third of three shots at eye height (a slope
    filling half the frame) became a drone shot 20 m up along the line of undercuts
    in the valley, the mesas behind. Aerial views frame landforms of the DEM's
    scale; small ones (NM's 17 m) they show too small to be chosen. The scene's one
    sun is chosen for the first shot (lit from behind, turned aside); a later shot that would look
    within ``clear`` degrees of it (a white sky, the landform against the light) is
    replaced, by the same rule over the views that look away from it, and kept only
    where no such view frames a landform.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from arches_render import field as F
from arches_render.field.node import evaluate

from .accessibility import RayCaster, heightfield_mesh
from .banded import polygonize_banded

__all__ = ["landform_cells", "landform_volume", "close_shots", "choose_shots", "view_azimuth", "Shot"]

_RAYS = (32, 18)
_HEIGHTS = (1.7, 6.0, 20.0, 60.0, 150.0)
#: The close shots' height classes (issue 34): the candidate heights (:data:`_HEIGHTS`, m
#: above the ground) of a person's eye, a drone and an aircraft.
HEIGHT_CLASSES = {"eye": (1.7, 6.0), "drone": (20.0, 60.0), "aerial": (150.0,)}
#: A view of a height class no shot has yet is preferred when it scores at least this
#: share of the best view it displaces (:func:`_select`).
CLASS_SCORE = 0.5
#: The share of a shot's frame its landform covers, under which a view is taken only where
#: better ones are too few (issue 34: 3-D landforms in 1 % of every close shot's pixels; an
#: aerial view of Maunga Whau's crater framed its lava-tube mouths in 0.4 %).
MIN_COVER = 0.01
_SPANS = (1.5, 3.0, 6.0, 12.0)
#: The steepest aim, up or down, in half vertical fields of view: the horizon stays in the
#: frame, and so does ground below the eye. (With the limit on looking down only, cameras
#: below a caldera's walls looked up at them by over two half fields: wall and sky, no floor.)
PITCH = 0.6
_AZIMUTHS = 16

#: Neighbouring rays whose hit distances differ by at most this fraction of the larger lie
#: on one sheet (:func:`legibility`).
SHEET_STEP = 0.08
#: Neighbouring rays whose surfaces' normals differ by more than this (degrees) see a crease
#: between them (:func:`legibility`'s contrast).
CREASE = 35.0
#: Hits at least this many times as far as the near ground (the 10th percentile of the hit
#: distances) are the frame's *background* (:func:`legibility`).
BACKGROUND_DEPTH = 3.0
#: A legible view: at least this share of sky and of background, and at most this share of
#: the frame on one sheet (:func:`legibility`). The background share replaced a depth ratio
#: (90th over 10th percentile of the hit distances, at least 2), which an oblique slope
#: filling the frame passed: rendered at 96x54 from the shipped DEMs' cameras, the slopes
#: (NM canyon's and Jacksboro's ``undercut_1``, Aletsch's) have 2.2-3.0 and a background of
#: 3-7 %, the shots a photographer would keep (canyon walls receding into haze, cliffed
#: coasts, an undercut outcrop before mesas) 19-49 %.
#: The contrast's threshold: over the candidate views of six DEMs (NM canyon, Jacksboro,
#: Maunga Whau, Devil's Slide, the eroded coast and mesas) that show their landform, the
#: median contrast is 0.37-0.87 and the tenth percentile 0.19-0.59; rendered at 640x360,
#: the close shots chosen without it that had under 0.2 were a brown slope filling two
#: thirds of the frame (NM ``undercut_3``, 0.13) and a cliff whose landform, the fallen
#: blocks, lay unseen at its foot (mesas ``cliff_3``, 0.07); those chosen instead show the
#: valley and its mesas beside a wall, and the blocks before the stratified escarpment.
LEGIBLE = {"sky": 0.08, "background": 0.1, "one_surface": 0.4, "contrast": 0.2}


class Shot(dict):
    """A camera: ``origin``, ``target``, ``fov`` (a ``[cameras.NAME]`` table) and its
    measures ``cover``, ``sky``, ``volume_m3``, ``height_m`` (kept out of the table)."""

    def table(self):
        """The ``[cameras.NAME]`` keys."""
        return {"origin": [float(v) for v in self["origin"]], "target": [float(v) for v in self["target"]],
                "fov": float(self["fov"])}


def _primitives(root):
    """Centres and reaches ``(N, 3), (N,)`` of every skeletal-set primitive in the tree."""
    mids, reach = [], []
    for n in root.walk():
        if n.kind == "skeletal_set":
            mids.append(0.5 * (n.a_np + n.b_np))
            reach.append(n.radius_np + n.core_np + 0.5 * np.linalg.norm(n.b_np - n.a_np, axis=1))
    if not mids:
        return np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(mids), np.concatenate(reach)


def landform_cells(root, extent, feature, cells=24):
    """The fullest landform-sized cells of the tree's primitives.

    Returns
    -------
    list of (numpy.ndarray, numpy.ndarray, numpy.ndarray)
        ``(lo, hi, centroid)``: the box of the primitives' supports in the cell (clipped
        to the tile) and the mean of their centres, fullest first.
    """
    P, reach = _primitives(root)
    if not len(P):
        return []
    x0, y0, x1, y1 = extent
    G = 10.0 * feature
    key = np.floor((P[:, :2] - [x0, y0]) / G).astype(np.int64)
    ids, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    out = []
    for k in np.argsort(-counts, kind="stable")[:cells]:
        m = inverse == k
        lo = (P[m] - reach[m, None]).min(axis=0)
        hi = (P[m] + reach[m, None]).max(axis=0)
        lo[:2] = np.maximum(lo[:2], [x0, y0])
        hi[:2] = np.minimum(hi[:2], [x1, y1])
        if np.all(hi > lo):
            out.append((lo, hi, P[m].mean(axis=0)))
    return out


def landform_volume(root, plain, box, cells=48, reach=None):
    """3-D volume (m^3) of the landform in ``box = (lo, hi, ...)`` (module docstring) and the voxel size.

    With ``reach`` (metres), only the air a camera could look into counts: air under
    matter within ``reach`` of open sky (air with no matter above it in its column),
    the distance taken through the air (6-connected voxel steps), so a tunnel network
    deep in the rock counts only its first ``reach`` inside each cave mouth
    (:mod:`.preset_ranking`)."""
    lo, hi = (np.asarray(v, np.float64) for v in box[:2])
    voxel = float(np.max(hi - lo)) / cells
    axes = [np.arange(lo[i] + 0.5 * voxel, hi[i], voxel) for i in range(3)]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    amp = evaluate(root, pts).reshape(X.shape) > 0
    base = evaluate(plain, pts).reshape(X.shape) > 0
    # Air with matter above it in the same column (caves, arches, undercuts).
    above = np.flip(np.logical_or.accumulate(np.flip(amp, axis=2), axis=2), axis=2)
    above = np.concatenate([above[..., 1:], np.zeros_like(above[..., :1])], axis=2)
    overhang = ~amp & above
    standing = amp & ~base  # hoodoos and other positive landforms
    # Lowered ground (a dent, a wider channel) counts a quarter: a 2.5-D change.
    lowered = base & ~amp & ~overhang
    if reach is not None and overhang.any():
        from scipy.ndimage import binary_dilation
        steps = max(1, int(math.ceil(reach / voxel)))
        overhang &= binary_dilation(~amp & ~above, iterations=steps, mask=~amp)
    return float((overhang.sum() + standing.sum() + 0.25 * lowered.sum()) * voxel ** 3), voxel


def _local_mesh(root, box, voxel, margin):
    """Mesh of the amplified field in ``box`` grown by ``margin``, without the box's cut faces."""
    lo, hi = np.asarray(box[0]) - margin, np.asarray(box[1]) + margin
    cut = F.Box(0.5 * (lo + hi), 0.5 * (hi - lo))
    try:
        m = polygonize_banded(F.Intersection(root, cut), voxel, normals=False)
    except ValueError:  # no surface in the box at this voxel: no view of this landform
        return None
    V, Fc = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    if not len(Fc):
        return None
    c = V[Fc].mean(axis=1)
    inner = np.all((c > lo + 0.75 * voxel) & (c < hi - 0.75 * voxel), axis=1)
    if not inner.any():
        return None
    return trimesh.Trimesh(V, Fc[inner], process=False)


def _rays(origin, target, fov, aspect, up=(0.0, 0.0, 1.0)):
    o, t = np.asarray(origin, float), np.asarray(target, float)
    fwd = (t - o) / np.linalg.norm(t - o)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    tup = np.cross(right, fwd)
    tx = math.tan(math.radians(fov) / 2)
    ty = tx / aspect
    w, h = _RAYS
    u = (np.arange(w) + 0.5) / w * 2 - 1
    v = 1 - (np.arange(h) + 0.5) / h * 2
    U, Vv = np.meshgrid(u, v)
    d = fwd + (U * tx)[..., None] * right + (Vv * ty)[..., None] * tup
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


class _Scene:
    """Ray casters of one landform's neighbourhood: local amplified mesh, tile DEM mesh, water,
    and the casters of what lies around the tile (``around``: the far field's ground, shared
    by every landform)."""

    def __init__(self, local, tile, water, around=()):
        self.local = RayCaster(local) if local is not None and len(local.faces) else None
        self.casters = [self.local] * (self.local is not None) + [
            RayCaster(m) for m in (tile, water) if m is not None and len(m.faces)] + list(around)

    def first_hit(self, O, D, far):
        """``(t, t_local, n)``: the first hit's distance over every mesh, the local mesh's
        alone, and the unit normal of the triangle hit first (0 on a miss)."""
        t, n = np.full(len(O), np.inf), np.zeros((len(O), 3))
        tl = np.full(len(O), np.inf)
        for c in self.casters:
            tc, nc = c.first_hit(O, D, far)
            nearer = tc < t
            t, n[nearer] = np.where(nearer, tc, t), nc[nearer]
            if c is self.local:
                tl = tc
        return t, tl, n


def _score(scene, plain, origins, targets, fov, aspect, voxel, dist):
    """Scores, covers, skies and :func:`legibility` of many views at once (one batch of rays)."""
    D = np.stack([_rays(o, t, fov, aspect) for o, t in zip(origins, targets)])  # (n, h, w, 3)
    n, h, w, _ = D.shape
    flat = D.reshape(-1, 3)
    O = np.repeat(np.asarray(origins, float), h * w, axis=0)
    far = np.repeat(50.0 * np.asarray(dist, float) + 1e4, h * w)
    t, tl, normal = scene.first_hit(O, flat, float(far.max()))
    hit = np.isfinite(t) & (t < far)
    on_local = hit & (tl <= t * (1 + 1e-6))
    differs = np.zeros(len(flat), bool)
    if on_local.any():
        P = O[on_local] + flat[on_local] * t[on_local, None]
        differs[on_local] = np.abs(evaluate(plain, P)) > 0.75 * voxel
    cover = differs.reshape(n, -1).mean(axis=1)
    hit = hit.reshape(n, h, w)
    sky = ((~hit[:, :2]) & (D[:, :2, :, 2] > 0)).reshape(n, -1).mean(axis=1)
    near = (np.isfinite(t) & (t < np.repeat(0.2 * np.asarray(dist, float), h * w))).reshape(n, -1).mean(axis=1)
    score = (np.minimum(cover, 0.45) - np.maximum(cover - 0.65, 0.0)) * (0.5 + 0.5 * sky) - 0.5 * near
    measures = legibility(D.reshape(n, h, w, 3), t.reshape(n, h, w), hit, differs.reshape(n, h, w),
                          normal.reshape(n, h, w, 3))
    return score, cover, sky, measures


def legibility(D, t, hit, landform=None, normals=None):
    """Legibility of views from their ray grids (issue 34): per view,

    * ``sky``: the share of the frame whose rays escape upwards;
    * ``depth``: the 90th over the 10th percentile of the hit distances (reported, not judged);
    * ``background``: the share of the frame whose rays hit at least ``BACKGROUND_DEPTH``
      times as far as the near ground (the 10th percentile): a frame with foreground,
      subject and distance has some; a slope that fills the frame, square on or oblique,
      has next to none, though its distances may span two or three times;
    * ``one_surface``: the share of the frame on the largest *smooth sheet*, rays joined to
      their four neighbours where both hit within ``SHEET_STEP`` of each other's distance (a
      slope that fills the frame is one sheet; silhouettes, the subject against its
      background and receding ground break sheets);
    * ``contrast``: the landform's contrast against its surroundings, the share of its
      outline (pairs of neighbouring rays, one on the landform and one not) across which
      the depth steps (:func:`_depth_steps`), the sky begins, or the surface turns by
      more than ``CREASE`` degrees (with ``normals``): an arch against the sky, an
      overhang before receding ground or an undercut band in a wall stands off its
      surroundings (near 1); a landform seen only as a patch of a surface that runs on
      around it, in depth and in orientation, has none (near 0). 0 where no ray hits the
      landform, or every ray does (no surroundings in the frame).

    Parameters
    ----------
    D : numpy.ndarray
        ``(n, h, w, 3)`` unit ray directions of ``n`` views.
    t : numpy.ndarray
        ``(n, h, w)`` hit distances.
    hit : numpy.ndarray
        ``(n, h, w)`` whether each ray hit.
    landform : numpy.ndarray, optional
        ``(n, h, w)`` whether each ray hits the landform (the amplified field where it
        differs from the plain terrain); without it no contrast is judged.
    normals : numpy.ndarray, optional
        ``(n, h, w, 3)`` unit normals of the surfaces hit (either side).

    Returns
    -------
    dict of numpy.ndarray
        ``sky``, ``depth``, ``background``, ``one_surface``, ``contrast`` (each ``(n,)``)
        and ``legible``, whether a view passes :data:`LEGIBLE`'s thresholds (the
        contrast's only with ``landform``).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    n, h, w = t.shape
    sky = ((~hit) & (D[..., 2] > 0)).reshape(n, -1).mean(axis=1)
    depth, background, sheet, contrast = np.ones(n), np.zeros(n), np.zeros(n), np.zeros(n)
    # Ray pairs of the grid: each ray with its right and its lower neighbour.
    idx = np.arange(h * w).reshape(h, w)
    a = np.concatenate([idx[:, :-1].ravel(), idx[:-1].ravel()])
    b = np.concatenate([idx[:, 1:].ravel(), idx[1:].ravel()])
    # The rays beyond each pair, on a's side and on b's (the pair's own ray at the frame's edge).
    before = np.concatenate([np.concatenate([idx[:, :1], idx[:, :-2]], axis=1).ravel(),
                             np.concatenate([idx[:1], idx[:-2]]).ravel()])
    after = np.concatenate([np.concatenate([idx[:, 2:], idx[:, -1:]], axis=1).ravel(),
                            np.concatenate([idx[2:], idx[-1:]]).ravel()])
    for i in range(n):
        ti, hits = t[i].ravel(), hit[i].ravel()
        if hits.sum() >= 8:
            near, far = np.percentile(ti[hits], [10, 90])
            depth[i] = far / max(near, 1e-9)
            background[i] = np.count_nonzero(hits & (ti >= BACKGROUND_DEPTH * near)) / (h * w)
        with np.errstate(invalid="ignore"):  # (inf - inf between two misses: not joined)
            join = hits[a] & hits[b] & (np.abs(ti[a] - ti[b]) <= SHEET_STEP * np.maximum(ti[a], ti[b]))
        graph = coo_matrix((np.ones(int(join.sum())), (a[join], b[join])), shape=(h * w, h * w))
        label = connected_components(graph, directed=False)[1][hits]
        sheet[i] = np.bincount(label).max() / (h * w) if len(label) else 0.0
        if landform is not None:
            on = landform[i].ravel()
            outline = on[a] != on[b]
            if outline.any():
                steps = _depth_steps(D[i], ti, hits, a, b, before, after)
                if normals is not None:
                    ni = normals[i].reshape(-1, 3)
                    steps |= np.abs(np.einsum("ij,ij->i", ni[a], ni[b])) < math.cos(math.radians(CREASE))
                contrast[i] = np.count_nonzero(outline & steps) / np.count_nonzero(outline)
    legible = (sky >= LEGIBLE["sky"]) & (background >= LEGIBLE["background"]) & (sheet <= LEGIBLE["one_surface"])
    if landform is not None:
        legible &= contrast >= LEGIBLE["contrast"]
    return {"sky": sky, "depth": depth, "background": background, "one_surface": sheet, "contrast": contrast,
            "legible": legible}


def _depth_steps(D, t, hit, a, b, before, after):
    """Whether the depth steps between the rays of each pair ``(a, b)`` of one view's grid:
    one of them misses, or the inverse depth ``1 / z`` (``z`` along the view axis) at
    each differs from its extrapolation from the other side's two rays (``before, a``
    and ``b, after``) by more than ``SHEET_STEP`` of the larger. ``1 / z`` is affine in
    the image over any plane, so ground receding to the horizon or a slope seen
    obliquely runs on (the sheets' distance test breaks them row by row), and a
    silhouette before farther ground or sky steps."""
    forward = D.reshape(-1, 3).mean(axis=0)
    forward /= np.linalg.norm(forward)
    with np.errstate(divide="ignore", invalid="ignore"):
        wz = np.where(hit, 1.0 / (t * (D.reshape(-1, 3) @ forward)), np.nan)
    wa, wb = wz[a], wz[b]
    wa0 = np.where(np.isfinite(wz[before]), wz[before], wa)
    wb1 = np.where(np.isfinite(wz[after]), wz[after], wb)
    tol = SHEET_STEP * np.fmax(wa, wb)
    with np.errstate(invalid="ignore"):
        runs_on = (np.abs(wb - (2 * wa - wa0)) <= tol) | (np.abs(wa - (2 * wb - wb1)) <= tol)
    return ~(hit[a] & hit[b] & runs_on)


def close_shots(root, plain, heights, extent, feature, water_level=None, water_mesh=None, count=3,
                fov=50.0, aspect=16 / 9, margin=0.0, progress=None, sun=None, surroundings=None):
    """Close shots of the most significant 3-D landforms (see the module docstring).

    Parameters
    ----------
    root : Node
        The amplified tree.
    plain : Node
        The terrain alone (``implicit_heightfield`` with its detail, no landform).
    heights : numpy.ndarray
        ``(ny, nx)`` DEM over ``extent`` (for the tile mesh and the ground under cameras).
    extent : sequence of 4 floats
    feature : float
        Landform size ``F`` (m).
    water_level : numpy.ndarray, optional
        ``(ny, nx)`` water levels (NaN: dry).
    water_mesh : trimesh.Trimesh, optional
        Water surfaces (occluders).
    count : int
        Close shots wanted.
    fov, aspect : float
        Horizontal field of view (degrees) and image aspect.
    margin : float
        Cameras keep this far (m) inside the tile's border.
    progress : callable, optional
        ``progress(done, total)`` over landforms.
    sun : callable, optional
        ``sun(first) -> (azimuth, clear)``: the azimuth towards the sun chosen for the
        first shot (degrees) and how near it the later shots may look (degrees).
    surroundings : trimesh.Trimesh, optional
        The ground around the tile that the scene shows (its far field,
        :func:`.far_field.far_field_mesh`): an occluder of every view, so that sky a
        view would show over the tile alone but the far field hides is not counted
        (a refined crop inside a caldera looked at its wall across the crop).

    Returns
    -------
    list of Shot
        Best first; fewer than ``count`` only when the tree has no landform or no view
        of one shows sky.
    """
    x0, y0, x1, y1 = extent
    H = np.asarray(heights, np.float64)
    ny, nx = H.shape
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    tile = heightfield_mesh(H, extent, max(1, int(math.ceil(max(nx, ny) / 512))))
    tile_centres = tile.triangles_center
    boxes = landform_cells(root, extent, feature)
    vfov2 = math.atan(math.tan(math.radians(fov) / 2) / aspect)
    around = [RayCaster(surroundings)] if surroundings is not None and len(surroundings.faces) else []
    found = []
    for b, box in enumerate(boxes):
        volume, voxel = landform_volume(root, plain, box)
        if progress:
            progress(b + 1, len(boxes))
        if volume <= 0:
            continue
        found.append((volume, box, voxel))
    found.sort(key=lambda x: -x[0])
    views = []
    for volume, box, voxel in found[:8]:
        lo, hi, centre = box
        size = 0.5 * float(np.linalg.norm(hi[:2] - lo[:2]))
        grow = max(2.0 * voxel, 0.25 * size)
        local = _local_mesh(root, box, voxel, grow)
        # The local mesh replaces the DEM's there: the DEM's surface spans the mouths of the
        # caves and undercuts carved under it and would hide every one of them.
        c, m = tile_centres, grow - voxel
        away = ~((c[:, 0] > lo[0] - m) & (c[:, 0] < hi[0] + m) & (c[:, 1] > lo[1] - m) & (c[:, 1] < hi[1] + m))
        scene = _Scene(local, trimesh.Trimesh(tile.vertices, tile.faces[away], process=False), water_mesh, around)
        # Every candidate camera at once: spans x azimuths x heights.
        sp, az, hh = (a.ravel() for a in np.meshgrid(_SPANS, 2 * np.pi * np.arange(_AZIMUTHS) / _AZIMUTHS,
                                                       _HEIGHTS, indexing="ij"))
        dist = np.minimum(sp * feature, 1.5 * max(size, feature)) / math.tan(math.radians(fov) / 2)
        ox, oy = centre[0] + dist * np.cos(az), centre[1] + dist * np.sin(az)
        inside = (ox > x0 + margin) & (ox < x1 - margin) & (oy > y0 + margin) & (oy < y1 - margin)
        sp, az, hh, dist, ox, oy = (a[inside] for a in (sp, az, hh, dist, ox, oy))
        best = []
        if len(ox):
            ground = plain.elevation_np(ox, oy).astype(np.float64)
            floor = ground.copy()
            if water_level is not None:
                wl = water_level[np.clip(np.round((oy - y0) / dy).astype(int), 0, ny - 1),
                                 np.clip(np.round((ox - x0) / dx).astype(int), 0, nx - 1)]
                floor = np.where(np.isfinite(wl), np.maximum(ground, wl + 0.5), ground)
            origins = np.column_stack([ox, oy, floor + hh])
            free = evaluate(root, origins) < -0.25  # in air, not grazing matter
            origins, dist, az, ground, hh = origins[free], dist[free], az[free], ground[free], hh[free]
            targets = np.repeat(centre[None], len(origins), axis=0)
            horiz = np.hypot(*(targets[:, :2] - origins[:, :2]).T)
            # Looking down too steeply leaves no horizon in the frame, and looking up too
            # steeply no ground: the aim is raised or lowered to at most PITCH half fields.
            pitch = np.clip(np.arctan2(targets[:, 2] - origins[:, 2], horiz), -PITCH * vfov2, PITCH * vfov2)
            targets[:, 2] = origins[:, 2] + np.tan(pitch) * horiz
            if len(origins):
                score, cover, sky, legible = _score(scene, plain, origins, targets, fov, aspect, voxel, dist)
                for k in np.nonzero((sky >= 0.5) & legible["legible"])[0]:
                    best.append(Shot(origin=origins[k], target=targets[k], fov=fov, cover=float(cover[k]),
                                     sky=float(sky[k]), volume_m3=volume, height_m=float(origins[k, 2] - ground[k]),
                                     score=float(score[k]), azimuth=float(az[k]), landform=len(views),
                                     height_class=_height_class(hh[k]),
                                     **{f"legible_{m}": (bool(v[k]) if m == "legible" else float(v[k]))
                                        for m, v in legible.items()}))
        best.sort(key=lambda s: -s["score"])
        views.append(best)
    return choose_shots(views, count, sun)


def choose_shots(views, count, sun=None):
    """The close shots among each landform's views (module docstring, "Choice").

    Parameters
    ----------
    views : list of list of Shot
        Per landform, its legible views, best first (``score``); each view has
        ``cover``, ``volume_m3``, ``azimuth`` (radians, of its position around the
        landform), ``landform``, ``origin`` and ``target``.
    count : int
        Shots wanted.
    sun : callable, optional
        As for :func:`close_shots`.

    Returns
    -------
    list of Shot
    """
    order = sorted(range(len(views)), key=lambda i: -(views[i][0]["volume_m3"] * views[i][0]["cover"])
                   if views[i] else 0.0)
    shots = _select(views, order, count)
    if sun is None or not shots:
        return shots
    # The later shots turned away from the sun where their landforms allow it (module
    # docstring, "Choice"); the first one, which the sun was chosen for, stays.
    towards, clear = sun(shots[0])
    away = lambda s: abs((view_azimuth(s) - towards + 180.0) % 360.0 - 180.0) >= clear  # noqa: E731
    if all(away(s) for s in shots[1:]):
        return shots
    turned = _select(views, order, count, away)
    return turned + [s for s in shots if not any(s is t for t in turned)][:count - len(turned)]


def _height_class(height):
    """The :data:`HEIGHT_CLASSES` name of a candidate height."""
    return next(name for name, heights in HEIGHT_CLASSES.items() if float(height) in heights)


def view_azimuth(camera):
    """The azimuth a camera looks in (degrees counter-clockwise from +x) from its
    ``origin`` and ``target``."""
    (x0, y0), (x1, y1) = camera["origin"][:2], camera["target"][:2]
    return math.degrees(math.atan2(y1 - y0, x1 - x0))


def _select(views, order, count, ok=None):
    """Up to ``count`` shots (module docstring, "Choice") from each landform's views
    (best first) in the landforms' ``order``; after the first, only views that ``ok``
    accepts (a landform whose best accepted view frames none of it gives none), and
    among those the best of a height class no shot has yet, where there is one. Views
    that frame their landform in :data:`MIN_COVER` of the frame come first; views that
    frame less of it, but some, only fill up what they leave short of ``count``."""
    shots = []
    for least in (MIN_COVER, 0.0):
        _take(views, order, count, ok, shots, least)
    return shots


def _take(views, order, count, ok, shots, least):
    """:func:`_select`'s rules over the views that cover more than ``least`` of their
    frame (at least ``least`` where it is not 0), appended to ``shots``."""
    def covers(v):
        return v["cover"] > 0 and v["cover"] >= least

    def fresh(v, best):
        return (v.get("height_class") not in {x.get("height_class") for x in shots}
                and covers(v) and v["score"] >= CLASS_SCORE * best["score"])

    for i in order:
        if len(shots) >= count:
            break
        if not views[i] or any(x["landform"] == views[i][0]["landform"] for x in shots):
            continue
        if not shots:
            s = views[i][0]
        else:
            accepted = [v for v in views[i] if ok is None or ok(v)]
            s = next((v for v in accepted if fresh(v, accepted[0])), accepted[0] if accepted else None)
        if s is not None and covers(s):
            shots.append(s)
    # More views of the best landforms, azimuths at least 60 degrees apart, until there
    # are enough: first of the height classes not yet taken, then of any.
    for new_class_only in (True, False):
        for i in order:
            for s in views[i]:
                if len(shots) >= count:
                    break
                if any(s is x for x in shots) or not covers(s) or (ok is not None and not ok(s)):
                    continue
                if new_class_only and not fresh(s, views[i][0]):
                    continue
                same = [x for x in shots if x["landform"] == s["landform"]]
                gap = min((abs((s["azimuth"] - x["azimuth"] + math.pi) % (2 * math.pi) - math.pi) for x in same),
                          default=math.pi)
                if gap >= math.radians(60):
                    shots.append(s)
