"""Local slope and core bounds of carved terrain (issue 21, item 2), and grazing rays
through carved cavities traced to the first sign change that dense sampling finds.

The bounds under test: ``eval_local`` slopes of skeletal sets (per primitive, over
the star distances a ball can hold), of the implicit heightfield (its sigmoid's
slope over the ball's vertical distances, the DEM's slope over the cell's
neighbourhood) and of their sum; the *cores* of carving sets (no matter where
one primitive alone carves below the level); and the erosion node's slopes in balls
where the erosion, not the terrain, makes the surface steep.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.field import evaluate  # noqa: E402
from arches_render.generators.terrain.falloff import energy_for_radius  # noqa: E402
from arches_render.generators.terrain.implicit_heightfield import ImplicitHeightfield  # noqa: E402
from arches_render.field.local_slopes import eval_local  # noqa: E402
from arches_render.generators.terrain.operators import Sum  # noqa: E402
from arches_render.generators.terrain.skeletal_set import SkeletalSet  # noqa: E402
from arches_render.render.sphere_tracer import SphereTracer  # noqa: E402
from arches_render.generators.terrain import geology as G  # noqa: E402
from arches_render.generators.terrain.erosion_node import Erosion  # noqa: E402

from test_terrain_field_nodes import _free_violation  # noqa: E402


def _terrain():
    """A canyon: a steep-walled valley along y in a tilted plateau, with fBm detail."""
    x = np.linspace(0.0, 120.0, 61)
    X, Y = np.meshgrid(x, x)
    H = 30.0 + 0.05 * Y - 25.0 / (1.0 + np.exp(-(np.abs(X - 60.0) - 12.0) / -2.0))
    return ImplicitHeightfield(H, (0, 0, 120, 120), R=8.0,
                               amplification=dict(amplitude=0.4, wavelength=6.0, octaves=3, seed=7))


def _tunnels(terrain):
    """Karst-like tunnels and undercuts below the surface: polylines of segments
    (grouped curves) and points, negative energies as the presets make them."""
    rng = np.random.default_rng(11)
    a, b, R, group = [], [], [], []
    for k in range(6):
        start = rng.uniform([10, 10, 0], [110, 110, 0])
        pts = start + np.cumsum(rng.normal(0, 6.0, (5, 3)) * [1, 1, 0.2], axis=0)
        z = terrain.elevation_np(pts[:, 0], pts[:, 1]) - rng.uniform(1.5, 4.0, len(pts))
        pts[:, 2] = z
        for i in range(len(pts) - 1):
            a.append(pts[i]), b.append(pts[i + 1]), R.append(4.0), group.append(k)
    # Undercuts along the canyon walls: points at the foot of each wall.
    for y in np.linspace(15, 105, 10):
        for xw in (48.0, 72.0):
            p = np.array([xw, y, terrain.elevation_np(np.array([xw]), np.array([y]))[0] - 1.0])
            a.append(p), b.append(p), R.append(3.0), group.append(len(group) + 100)
    a, b, R = np.array(a), np.array(b), np.array(R)
    e = -energy_for_radius(0.7 * R, R, terrain.T_np)
    e[:len(group) - 20] = e[0]  # one energy per curve
    return SkeletalSet(a, b, R, e, group=np.array(group), noise=dict(amplitude=0.15, wavelength=2.0, seed=3))


TERRAIN = _terrain()
TUNNELS = _tunnels(TERRAIN)
CARVED = Sum(TERRAIN, TUNNELS)
LO, HI = np.array([5.0, 5.0, 0.0]), np.array([115.0, 115.0, 40.0])


def _vec(a, cls=mi.Point3f):
    return cls(*(mi.Float(np.ascontiguousarray(a[:, i], dtype=np.float32)) for i in range(3)))


def _near_surface_points(node, n, seed):
    """Points where the field is within a few metres of its surface (where bounds matter)."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(LO, HI, (40 * n, 3))
    f = evaluate(node, p)
    keep = p[np.abs(f) < 3.0]
    assert len(keep) >= n
    return keep[:n]


@pytest.mark.parametrize("name", ["terrain", "tunnels", "carved"])
def test_local_slopes_hold_in_their_balls(name):
    """For every radius, ``|f(q1) - f(q2)| <= S |q1 - q2|`` for pairs in the ball, and
    the slopes are tighter than the global bound somewhere (else they buy nothing)."""
    node = {"terrain": TERRAIN, "tunnels": TUNNELS, "carved": CARVED}[name]
    radii = CARVED.slope_radii
    p = _near_surface_points(CARVED, 1500, seed=3)
    _, _, slopes = eval_local(node, _vec(p), (0.0,), None, None, radii)
    dr.eval(slopes)
    rng = np.random.default_rng(5)
    for S, rad in zip(slopes, radii):
        S = S.numpy().astype(np.float64)
        k = 8
        def in_ball():
            d = rng.normal(size=(len(p), k, 3))
            d /= np.linalg.norm(d, axis=2, keepdims=True)
            return p[:, None] + d * (rad * rng.uniform(0, 1, (len(p), k, 1)) ** (1 / 3) * 0.999)
        q1 = in_ball()
        q2 = q1 + rng.normal(size=q1.shape) * 0.02 * rad
        inside = np.linalg.norm(q2 - p[:, None], axis=2) < rad
        f1 = evaluate(node, q1.reshape(-1, 3)).reshape(len(p), k)
        f2 = evaluate(node, q2.reshape(-1, 3)).reshape(len(p), k)
        ratio = np.abs(f1 - f2) / np.maximum(np.linalg.norm(q1 - q2, axis=2), 1e-9)
        # float32 evaluation noise: 2e-5 m of field over the pair's distance.
        excess = ratio - S[:, None] - 2e-5 / np.maximum(np.linalg.norm(q1 - q2, axis=2), 1e-9)
        assert excess[inside].max() <= 1e-3 * S.max(), f"radius {rad:.3g}: slope exceeds its bound"
    assert np.median(slopes[-1].numpy()) < 0.5 * node.lipschitz


@pytest.mark.parametrize("level", [0.0, 2.0, 8.0])
def test_carving_bounds_are_free(level):
    """Distance bounds of the carving set at the levels the sum asks (its cores) and
    of the carved terrain: no point within a declared free ball holds ``f >= -level``."""
    rng = np.random.default_rng(int(level * 10) + 1)
    for node, c in ((TUNNELS, level + TERRAIN.T_np), (CARVED, level)):
        # Points outside the level set, within a few metres of it (the carving set:
        # in its cores, where it carves below the asked level).
        cand = np.random.default_rng(3).uniform(LO, HI, (400000, 3))
        fc = evaluate(node, cand)
        p = cand[(fc < -c - 0.3) & (fc > -c - 6.0)][:2000]
        assert len(p) > 200
        f, (d,) = node.eval_bounds(_vec(p), (c,))
        dr.eval(f, d)
        d = np.minimum(d.numpy().astype(np.float64), 1e3)
        sel = d > 0
        dirs = rng.normal(size=(sel.sum(), 12, 3))
        dirs /= np.linalg.norm(dirs, axis=2, keepdims=True)
        q = p[sel, None] + dirs * (d[sel, None, None] * rng.uniform(0, 1, (sel.sum(), 12, 1)) ** (1 / 3) * 0.999)
        assert evaluate(node, q.reshape(-1, 3)).max() + c < 1e-4
        assert sel.mean() > 0.3


def test_grazing_rays_in_carved_terrain_hit_the_first_sign_change():
    """Rays along the tunnels and the canyon walls, at grazing angles, from inside the
    cavities and from the air: each hits where 1 cm sampling finds the field's first
    positive value (within the tracer's tolerance band), or proves there is none;
    no ray is left unresolved after the second step budget."""
    rng = np.random.default_rng(17)
    n = 600
    # From points in the air or in the tunnels, nearly horizontal directions along
    # the canyon (y) and across it, a few degrees up or down.
    f0, o = np.zeros(0), np.zeros((0, 3))
    while len(o) < n:
        cand = rng.uniform(LO + [10, 10, 0], HI - [10, 10, 0], (4 * n, 3))
        fc = evaluate(CARVED, cand)
        o, f0 = np.vstack([o, cand[fc < -0.3]]), np.concatenate([f0, fc[fc < -0.3]])
    o = o[:n]
    az = rng.choice([np.pi / 2, 0.0, np.pi], n) + rng.normal(0, 0.25, n)
    el = rng.uniform(-0.12, 0.05, n)
    d = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    tracer = SphereTracer(CARVED, eps=2e-4, omega=1.6, max_steps=512)
    res = tracer.query(_vec(o), _vec(d, mi.Vector3f), mi.Float(60.0), mi.Bool(True))
    dr.eval(res.hit, res.t, res.exhausted, res.unresolved)
    hit, t, exhausted = res.hit.numpy(), res.t.numpy(), res.exhausted.numpy()
    ts = np.arange(0.0, 60.0, 0.01)
    f = evaluate(CARVED, (o[None] + ts[:, None, None] * d[None]).reshape(-1, 3)).reshape(len(ts), n)
    inside = f > 0
    found = inside.any(axis=0)
    t_ref = np.where(found, ts[np.argmax(inside, axis=0)], np.inf)
    band = -f < 2e-4 * np.maximum(ts[:, None], 1e-3)
    t_band = ts[np.argmax(band, axis=0)]
    assert found.mean() > 0.3 and (~found).mean() > 0.05  # both kinds are tested
    # Grazing rays may need the second budget (first-order bounds crawl along a wall
    # they nearly touch), never more: none is left unresolved, few are exhausted.
    assert not res.unresolved.numpy().any()
    assert exhausted.mean() < 0.05, f"{exhausted.sum()} rays needed the second budget"
    assert hit[found].all(), f"{(~hit[found]).sum()} of {found.sum()} rays missed rock"
    assert np.all(t[found] <= t_ref[found] + 0.02)
    assert np.all(t[hit] >= t_band[hit] - 0.02), "a ray stopped before the tolerance band"
    # A reported hit without a sampled crossing must be a tangency inside the band.
    assert np.all(band.any(axis=0)[hit & ~found])


def test_footprint_field_of_the_terrain_skips_octaves_and_keeps_its_bounds():
    """Seen from afar (cone radius ~ the fBm's wavelength), the implicit heightfield
    evaluates its footprint field: the value differs from full detail (level of
    detail does something), and its slopes and distance bounds hold for that field."""
    from arches_render.field.lod import Footprint
    origin, rate = np.array([60.0, -400.0, 200.0]), 0.01

    def footprint_field(q):
        fp = Footprint(mi.Float(rate * np.linalg.norm(q - origin, axis=1).astype(np.float32)), mi.Float(rate))
        f, _ = TERRAIN.eval_bounds(_vec(q), (), None, fp)
        return f.numpy().astype(np.float64)

    p = _near_surface_points(TERRAIN, 1500, seed=9)
    fp = Footprint(mi.Float(rate * np.linalg.norm(p - origin, axis=1).astype(np.float32)), mi.Float(rate))
    radii = CARVED.slope_radii
    f, (d,), slopes = TERRAIN.eval_local(_vec(p), (0.0,), None, fp, radii)
    dr.eval(f, d, slopes)
    assert np.abs(f.numpy() - evaluate(TERRAIN, p)).max() > 0.05
    rng = np.random.default_rng(2)
    for S, rad in zip(slopes, radii):
        dirs = rng.normal(size=p.shape)
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        q1 = p + dirs * rad * 0.5
        q2 = q1 + rng.normal(size=p.shape) * 0.02 * rad
        ratio = np.abs(footprint_field(q1) - footprint_field(q2)) / np.linalg.norm(q1 - q2, axis=1)
        assert np.all(ratio <= S.numpy() * (1 + 1e-3) + 2e-5 / np.linalg.norm(q1 - q2, axis=1))
    d = d.numpy().astype(np.float64)
    sel = d > 0
    dirs = rng.normal(size=(sel.sum(), 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    q = p[sel] + dirs * (d[sel, None] * rng.uniform(0, 1, (sel.sum(), 1)) ** (1 / 3) * 0.999)
    assert footprint_field(q).max() < 1e-4
    assert sel.mean() > 0.3


def _primitive_gaps(node, p):
    """``min_i (rho_i(p) - D_max,i)`` over the set's primitives (numpy): how far ``p`` is
    from the nearest support's outer envelope."""
    f32 = lambda x: np.asarray(x, dtype=np.float32).astype(np.float64)  # the kernel's numbers  # noqa: E731
    a, ba = f32(node.a_np), f32(node.b_np - node.a_np)
    R, core = f32(node.radius_np), f32(node.core_np)
    span = node.noise["span"] if node.noise else 0.0
    pa = p[:, None, :] - a[None]
    L2 = np.maximum(np.sum(ba * ba, axis=1), 1e-30)
    t = np.clip(np.sum(pa * ba[None], axis=2) / L2, 0.0, 1.0)
    r = np.linalg.norm(pa - t[..., None] * ba[None], axis=2)
    return np.min(np.maximum(r - core, 0.0) - R * (1.0 + span), axis=1)


def test_balls_that_miss_every_support_have_no_slope_from_the_set():
    """The set's local slope in a ball that reaches no primitive's support is 0: a
    primitive of the point's slope list counts only if the ball can touch its support
    (it used to count as if it did: a Jacksboro channel wall summed 14 against the one
    acting primitive's 4.75)."""
    radii = CARVED.slope_radii
    p = np.random.default_rng(8).uniform(LO, HI, (20000, 3))
    gap = _primitive_gaps(TUNNELS, p)
    _, _, slopes = eval_local(TUNNELS, _vec(p), (0.0,), None, None, radii)
    dr.eval(slopes)
    # (Outside the set's grid a ball that reaches the supports' box takes the global
    # slope: not asked here.)
    inside = np.broadcast_to(TUNNELS._cell(_vec(p))[3].numpy(), (len(p),))
    for S, rad in zip(slopes, radii):
        S = np.broadcast_to(S.numpy(), (len(p),))
        missed = inside & (gap > rad * (1.0 + 1e-4) + 1e-3)
        # Points in cells whose lists hold primitives (the cell tables' slope > 0):
        # where the old bound summed them.
        listed = missed & (np.broadcast_to(TUNNELS.local_lipschitz(_vec(p))[0].numpy(), (len(p),)) > 0)
        assert listed.sum() > 200, f"radius {rad:.3g}: too few test points"
        assert np.all(S[missed] == 0.0), f"radius {rad:.3g}: {np.sum(S[missed] > 0)} balls missing every support"


def _channels(terrain):
    """Noise-free carving polylines (river channels as the amplifier makes them):
    grouped segments of one energy per curve, radii 3-6 m, along the canyon floor."""
    rng = np.random.default_rng(12)
    a, b, R, group = [], [], [], []
    for k in range(5):
        x0 = rng.uniform(52.0, 68.0)
        ys = np.linspace(8.0, 112.0, 9)
        xs = x0 + np.cumsum(rng.normal(0.0, 2.0, len(ys)))
        pts = np.column_stack([xs, ys, terrain.elevation_np(xs, ys) - rng.uniform(0.5, 1.5, len(ys))])
        r = rng.uniform(3.0, 6.0)
        for i in range(len(pts) - 1):
            a.append(pts[i]), b.append(pts[i + 1]), R.append(r), group.append(k)
    R = np.array(R)
    return SkeletalSet(np.array(a), np.array(b), R, -energy_for_radius(0.6 * R, R, terrain.T_np), group=np.array(group))


CHANNELS = _channels(TERRAIN)
CUT = Sum(TERRAIN, CHANNELS)


def _line_points(name, rng):
    """Points and line directions for :func:`test_slopes_along_a_line_hold_on_it`: around
    the channels' segments (half the lines along their channel, within ~10 degrees), or
    near the carved terrain's surface (half the lines within 20 degrees of horizontal)."""
    if name == "channels":
        a, b = CHANNELS.a_np, CHANNELS.b_np
        k = rng.integers(0, len(a), 3000)
        p = a[k] + rng.uniform(0, 1, (len(k), 1)) * (b[k] - a[k]) + rng.normal(0, 4.0, (len(k), 3))
        acts = np.abs(evaluate(CHANNELS, p)) > 0.05  # where they act
        p, k = p[acts][:1000], k[acts][:1000]
        u = rng.normal(size=p.shape)
        u[::2] = (b[k] - a[k])[::2] / np.linalg.norm((b[k] - a[k])[::2], axis=1, keepdims=True) + 0.1 * u[::2]
    else:
        p = _near_surface_points(CUT, 1000, seed=13)
        u = rng.normal(size=p.shape)
        u[::2, 2] = rng.uniform(-0.35, 0.35, len(u[::2])) * np.linalg.norm(u[::2, :2], axis=1)
    return p, u / np.linalg.norm(u, axis=1, keepdims=True)


@pytest.mark.parametrize("name", ["channels", "terrain", "cut"])
def test_slopes_along_a_line_hold_on_it(name):
    """With a ray's direction the slopes bound the derivative along its line (noise-free
    skeletal sets, :mod:`.skeletal_bounds` "Along a line"; the implicit heightfield, from
    :mod:`.elevation_line`'s derivative terms): for pairs on the line within each
    radius, ``|f(q1) - f(q2)| <= S |q1 - q2|``, and ``S`` is at most the ball's. Lines
    along a channel, or climbing gently above the ground, get slopes well below the
    ball's. It fails if the set's bound drops the turning of ``grad r`` along the line."""
    node = {"channels": CHANNELS, "terrain": TERRAIN, "cut": CUT}[name]
    radii = CUT.slope_radii
    rng = np.random.default_rng(6)
    p, u = _line_points(name, rng)
    assert len(p) > 500
    _, _, along = eval_local(node, _vec(p), (0.0,), _vec(u, mi.Vector3f), None, radii)
    _, _, balls = eval_local(node, _vec(p), (0.0,), None, None, radii)
    dr.eval(along, balls)
    for S, B, rad in zip(along, balls, radii):
        S, B = (np.broadcast_to(x.numpy(), (len(p),)).astype(np.float64) for x in (S, B))
        assert np.all(S <= B * (1 + 1e-5) + 1e-9)
        s1 = rng.uniform(-1, 1, (len(p), 16)) * rad * 0.999
        s2 = np.clip(s1 + rng.normal(0, 0.02 * rad, s1.shape), -rad * 0.999, rad * 0.999)
        f1 = evaluate(node, (p[:, None] + s1[..., None] * u[:, None]).reshape(-1, 3)).reshape(s1.shape)
        f2 = evaluate(node, (p[:, None] + s2[..., None] * u[:, None]).reshape(-1, 3)).reshape(s1.shape)
        gap = np.maximum(np.abs(s1 - s2), 1e-9)
        # float32 evaluation noise: a few ulps of |f| (up to 43 deep in a channel) over the
        # pair's distance; pairs closer than 1e-3 rad measure only that noise.
        excess = np.abs(f1 - f2) / gap - S[:, None] - (2e-5 + 2e-6 * np.abs(f1)) / gap
        excess[gap < 1e-3 * rad] = -np.inf
        assert excess.max() <= 1e-3 * B.max(), f"radius {rad:.3g}: a line's slope exceeds its bound"
    # The chosen half of the lines, the smaller radius (the larger, 1.26 m against
    # channel radii of 3-6 m, turns too much): median along / ball measured 0.22 for
    # the channels, 0.38 for the terrain and the carved terrain.
    S, B = (np.broadcast_to(x.numpy(), (len(p),))[::2] for x in (along[1], balls[1]))
    assert np.median(S[B > 0] / B[B > 0]) < (0.4 if name == "channels" else 0.6)


def _flat_eroded(resistance):
    """A flat implicit terrain notched by a row of erosion spheres at its surface, under
    ``resistance``: the erosion's own terms (``S_D``, ``D L_rho``) set the true slope
    there, not the terrain's (about T / R)."""
    flat = ImplicitHeightfield(np.zeros((17, 17)), (0, 0, 60, 60), R=8.0)
    centres = np.column_stack([np.linspace(15, 45, 7), np.full(7, 30.0), np.zeros(7)])
    spheres = SkeletalSet(centres, None, 3.0, 2.0 * flat.T_np, combine="max")
    return Erosion(flat, spheres, resistance), flat, centres


@pytest.mark.parametrize("geology", ["thin_strata", "soft", "hard"])
def test_erosion_slopes_in_balls_hold_where_the_erosion_sets_them(geology):
    """The erosion's slope in a ball (erosion_node's docstring) keeps its distance bounds
    free where the erosion field and the strata make the surface steep (thin beds: the
    ``D L_rho`` term; soft rock: the ``S_D`` term; dropping either lets matter into the
    balls: checked), and in hard rock, where it is the terrain's slope alone. (That it
    is tighter than before is shown by step counts, not here: the child's own distance
    bounds, which the node keeps, hide the difference in these balls.)"""
    resistance = {"thin_strata": G.Strata(1.0, 0.25, 1.0), "soft": G.Constant(0.0),
                  "hard": G.Constant(1.0)}[geology]
    node, flat, centres = _flat_eroded(resistance)
    rng = np.random.default_rng(41)
    p = rng.uniform([10, 24, -5], [50, 36, 3], (400000, 3))
    v = evaluate(node, p)
    p = p[(v > -1.5) & (v < -1e-3)][:3000]
    assert len(p) > 1000
    for direction in (None, np.array([0.3, -0.2, 0.93])):
        if direction is not None:
            direction = direction / np.linalg.norm(direction)
        for level in (0.0, 0.3):
            worst, _ = _free_violation(node, p, level, direction, rng)
            assert worst < 1e-4, f"level {level}: f + c = {worst:.3g} inside a free region"


def _bridged():
    """The arch bridge's tree in small: a displaced slab across the canyon, its ends in
    the walls, blended (radius 4) with the carved terrain (a sum whose global bound is
    its tunnels' steepest cluster plus the terrain's)."""
    from arches_render.field.operators import Blend
    from arches_render.field.primitives import Box
    from arches_render.field.warps import Displace
    top = float(TERRAIN.elevation_np(np.array([40.0]), np.array([60.0]))[0])
    slab = Displace(Box((60.0, 60.0, top - 3.0), (20.0, 4.0, 3.0), rounding=1.0), amplitude=0.6,
                    wavelength=5.0, octaves=3, seed=7)
    return Blend(CARVED, slab, radius=4.0)


BRIDGED = _bridged()


def test_a_blend_bounds_its_seams_by_its_operands_slopes():
    """In a blend's seam (both operands near the level) the free lengths come from the
    operands' slopes in balls (``smax`` keeps the larger one: operators, "Local slopes of a
    blend"), not from the sum's global bound: no point declared free is in the solid, in
    balls and along lines both ways and ahead, and seam points get bounds far longer
    than Hart's with the global bound (the sum's 445, its tunnels' densest cluster): a
    quarter of them had exactly Hart's before (gain 1.0); now the 10th percentile is
    124. It fails with the smaller of the operands' slopes in place of the larger."""
    assert BRIDGED.slope_radii == CARVED.slope_radii
    rng = np.random.default_rng(8)
    top = float(TERRAIN.elevation_np(np.array([40.0]), np.array([60.0]))[0])
    p = rng.uniform([36.0, 52.0, top - 9.0], [84.0, 68.0, top + 4.0], (20000, 3))
    f = evaluate(BRIDGED, p)
    p = p[(f < 0.0) & (f > -2.0)][:3000]
    assert len(p) > 1000
    for direction in (None, np.array([0.6, -0.7, -0.39]), np.array([0.0, 0.3, 1.0]), np.array([1.0, 0.0, 0.0])):
        if direction is not None:
            direction = direction / np.linalg.norm(direction)
        for level in (0.0, 0.3):
            for ahead in ((False,) if direction is None else (False, True)):
                worst, share = _free_violation(BRIDGED, p, level, direction, rng, ahead=ahead)
                assert worst < 1e-4, f"level {level} (ahead: {ahead}): f + c = {worst:.3g} inside a free region"
                assert share > 0.5
    f, (d,) = BRIDGED.eval_bounds(_vec(p), (0.0,))
    dr.eval(f, d)
    gain = d.numpy() * BRIDGED.lipschitz / np.maximum(-f.numpy(), 1e-9)
    seam = np.abs(evaluate(CARVED, p) - evaluate(BRIDGED.children[1], p)) < 4.0
    assert seam.sum() > 1000
    assert np.percentile(gain[seam], 25) > 20.0
