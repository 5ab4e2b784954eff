"""The convolution surface of material stacks (Peytavie et al. 2009, 3.3): values, bounds, tracing."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import variant

from arches_render.generators.layers.material_stacks import AIR, SAND, SOLID, MaterialStacks


def cave_stacks():
    """Bumpy ground, a cave, a floating slab and a column with four intervals (overflow path)."""
    rng = np.random.default_rng(3)
    H = 2.0 + rng.uniform(0.0, 1.5, (12, 10))
    S = MaterialStacks.from_heightfield(H, 0.5, z0=0.0, z1=6.0, dz=0.01,
                                        column=(("sand", 0.3), ("bedrock", None)))
    cols = np.array([23, 24, 33, 34, 35, 45])
    block = np.full((len(cols), 500), -1, dtype=np.int16)
    block[:, 60:120] = AIR              # a cave 0.6..1.2 m
    block[:, 400:440] = 1               # a slab floating at 4.0..4.4 m
    block[-1, 20:30] = AIR              # a fourth interval in the last column
    return S.rewrite(cols, 0, block)


def dense_occupancy(S, sub):
    """Voxels of ``s / sub`` by ``dz``: 1 where the stacks hold a solid material."""
    levels = S.dense_columns(np.arange(S.ncol), 0, S.n_levels)
    occ = np.isin(levels, SOLID).reshape(S.ny, S.nx, S.n_levels)
    return np.repeat(np.repeat(occ, sub, axis=0), sub, axis=1)   # (y, x, z)


@pytest.mark.parametrize("sigma_cells", [0.5, 1.0, 1.5])
def test_matches_brute_force_voxel_convolution(sigma_cells):
    """V_M from the prefix sums equals the count of occupied voxels in the kernel cube.

    Points are chosen so that the cube's faces lie on the voxel grid (x, y multiples of
    s / 4, z of dz), where the brute-force sum is exact.
    """
    variant()
    from arches_render.field import evaluate
    from arches_render.generators.layers.convolution_surface import ConvolutionSurface, paper_field
    S = cave_stacks()
    sub = 4
    occ = dense_occupancy(S, sub)
    h = S.cell / sub
    sigma = sigma_cells * S.cell
    r_xy = int(round(sigma / h))
    r_z = int(round(sigma / S.dz))
    rng = np.random.default_rng(0)
    n = 300
    ix = rng.integers(-r_xy, occ.shape[1] + r_xy, n)
    iy = rng.integers(-r_xy, occ.shape[0] + r_xy, n)
    iz = rng.integers(-r_z, occ.shape[2] + r_z, n)
    brute = np.empty(n)
    for k in range(n):
        block = occ[max(0, iy[k] - r_xy):max(0, iy[k] + r_xy), max(0, ix[k] - r_xy):max(0, ix[k] + r_xy),
                    max(0, iz[k] - r_z):max(0, iz[k] + r_z)]
        brute[k] = block.sum() * h * h * S.dz
    pts = np.stack([ix * h, iy * h, iz * S.dz], axis=1)
    f_brute = brute / (4 * sigma ** 3) - 1.0
    assert np.abs(paper_field(S, pts, sigma) - f_brute).max() < 1e-9
    exact = ConvolutionSurface(S, sigma=sigma, tilt=0.0)
    # float32 on the device: metres to ~1e-6 relative.
    assert np.abs(evaluate(exact, pts) / sigma - f_brute).max() < 2e-4
    assert exact.sums.overflow   # the four-interval column took the prefix-sum search
    # The default node adds the tie-break term, at most tilt_shift (module docstring).
    node = ConvolutionSurface(S, sigma=sigma)
    assert np.abs(evaluate(node, pts) - node.cpu_eval(pts)).max() < 2e-4 * sigma
    assert np.abs(evaluate(node, pts) / sigma - f_brute).max() < 2e-4 + node.tilt_shift / sigma


def test_paper_normalization():
    """f = 1 inside a full cube, -1 in empty space, the half-space gives F = h - z."""
    from arches_render.generators.layers.convolution_surface import paper_field
    S = MaterialStacks.from_heightfield(np.full((8, 8), 2.0), 0.5, z0=0.0, z1=4.0, dz=0.01)
    sigma = 0.5
    f = paper_field(S, np.array([[2.0, 2.0, 1.0], [2.0, 2.0, 3.5], [2.0, 2.0, 2.2]]), sigma)
    assert f == pytest.approx([1.0, -1.0, -0.2 / sigma])


def test_lipschitz_bound_holds_on_random_pairs():
    variant()
    from arches_render.field import evaluate
    from arches_render.generators.layers.convolution_surface import ConvolutionSurface
    S = cave_stacks()
    for sigma in (0.25, 0.5):
        node = ConvolutionSurface(S, sigma=sigma)
        lo, hi = node.bounds()
        rng = np.random.default_rng(1)
        a = rng.uniform(lo, hi, (20000, 3))
        b = a + rng.normal(0, 0.3, a.shape)
        fa, fb = evaluate(node, a), evaluate(node, b)
        ratio = np.abs(fa - fb) / np.linalg.norm(a - b, axis=1)
        assert ratio.max() <= node.lipschitz * (1 + 1e-3) + 1e-4
        assert ratio.max() > 0.5     # the test is not vacuous: the field varies


def test_distance_bounds_are_free_of_surface():
    """Every point within the ball (or the line interval) eval_bounds grants has F < 0."""
    variant()
    import mitsuba as mi
    from arches_render.generators.layers.convolution_surface import ConvolutionSurface
    S = cave_stacks()
    node = ConvolutionSurface(S)
    lo, hi = node.bounds()
    rng = np.random.default_rng(2)
    n = 40000
    P = rng.uniform(lo - 1.0, hi + 1.0, (n, 3))
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    p = mi.Point3f(*(mi.Float(P[:, k].astype(np.float32)) for k in range(3)))
    d = mi.Vector3f(*(mi.Float(u[:, k].astype(np.float32)) for k in range(3)))
    _, (ball,) = node.eval_bounds(p, (0.0,))
    _, (line,) = node.eval_bounds(p, (0.0,), d)
    ball, line = ball.numpy(), line.numpy()
    assert (ball > node.sigma).mean() > 0.1          # the coarse grid does its job
    for radius, dirs in ((ball, rng.normal(size=(n, 3))), (line, u * rng.choice([-1, 1], (n, 1)))):
        if dirs is not u:
            dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        Q = P + dirs * (radius * rng.uniform(0, 0.999, n))[:, None]
        F = node.cpu_eval(Q)
        assert np.all(F[radius > 0] < 1e-5)


def test_distance_bounds_far_outside_the_grid():
    """Beyond the stacks' grid the coarse cells say nothing, yet the node's box does: a
    point 20 m away is granted most of that (before, Hart's sigma / sqrt(3): every ray
    of a landscape holding a small layered patch crawled in 15 cm steps)."""
    variant()
    import mitsuba as mi
    from arches_render.generators.layers.convolution_surface import ConvolutionSurface
    node = ConvolutionSurface(cave_stacks())
    lo, hi = node.bounds()
    rng = np.random.default_rng(5)
    u = rng.normal(size=(500, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    P = 0.5 * (lo + hi) + u * (20.0 + 0.5 * np.linalg.norm(hi - lo))
    p = mi.Point3f(*(mi.Float(P[:, k].astype(np.float32)) for k in range(3)))
    _, (ball,) = node.eval_bounds(p, (0.0,))
    box = np.linalg.norm(np.maximum(np.maximum(lo - P, P - hi), 0.0), axis=1)
    assert np.all(box >= 20.0) and np.all(ball.numpy() >= box - 1e-3)


def test_material_ratio():
    variant()
    from arches_render.field import evaluate
    from arches_render.generators.layers.convolution_surface import MaterialRatio
    S = MaterialStacks.from_heightfield(np.full((8, 8), 2.0), 0.5, z0=0.0, z1=4.0, dz=0.01,
                                        column=(("sand", 1.0), ("bedrock", None)))
    r = MaterialRatio(S, [SAND], sigma=0.5)
    v = evaluate(r, np.array([[2.0, 2.0, 1.8], [2.0, 2.0, 0.3], [2.0, 2.0, 1.0], [2.0, 2.0, 3.9]]))
    assert v == pytest.approx([1.0, 0.0, 0.5, 0.0], abs=1e-4)


def test_sphere_trace_through_a_swept_arch_reaches_the_sky():
    """A sweep through a fin makes a hole: a ray through it escapes, a ray above hits."""
    variant()
    import mitsuba as mi
    from arches_render.generators.layers.convolution_surface import ConvolutionSurface
    from arches_render.generators.layers.sweep import sweep
    from arches_render.render.sphere_tracer import SphereTracer
    H = np.zeros((40, 40))
    H[:, 16:24] = 8.0                        # a fin along y, x in [8, 12]
    S = MaterialStacks.from_heightfield(H, 0.5, z0=-1.0, z1=10.0, dz=0.01,
                                        column=(("sandstone", 8.5),))
    profile = [[-2.0, -1.0], [2.0, -1.0], [2.0, 1.5], [0.0, 3.0], [-2.0, 1.5]]
    T = sweep(S, [[4.0, 10.0, 2.0], [16.0, 10.0, 2.0]], profile)

    def trace(stacks, z):
        tracer = SphereTracer(ConvolutionSurface(stacks), eps=1e-4)
        o = mi.Point3f(0.0, 10.0, z)
        hit, t = tracer.trace(o, mi.Vector3f(1.0, 0.0, 0.0), 1e4, mi.Bool(True))
        return bool(hit.numpy()[0]), float(t.numpy()[0])

    assert trace(S, 2.5)[0]                          # before the sweep: the fin is solid
    hit, _ = trace(T, 2.5)
    assert not hit                                   # through the arch to the sky
    hit, t = trace(T, 6.0)
    assert hit and t == pytest.approx(8.0, abs=0.05)  # above the hole: the fin's face


def test_column_tops_free_rays_skimming_the_ground():
    """Low over a layered terrain, where the coarse cells end, the window maxima of the
    columns' tops (:mod:`.column_tops`) grant free lengths: every point within the ball
    or the line interval stays below each level asked (also beside a lone spike, pushed
    towards it: a window radius or clearance off by sigma fails there), and points a
    metre or two over the ground get far more than the coarse grid's (measured: median
    3.6x on lines). Level 0.2 also checks the coarse grid's shrink along lines, which
    was taken after the line's slope divided it (0.16 m granted inside the level set)."""
    variant()
    import mitsuba as mi
    from arches_render.generators.layers import column_tops
    from arches_render.generators.layers.convolution_surface import ConvolutionSurface
    rng = np.random.default_rng(12)
    x = np.linspace(0.0, 1.0, 64)
    H = 2.0 + 1.2 * np.sin(7 * x)[:, None] * np.cos(5 * x)[None, :] + rng.uniform(0, 0.3, (64, 64))
    S = MaterialStacks.from_heightfield(H, 1.0, z0=0.0, z1=8.0, dz=0.02)
    node = ConvolutionSurface(S, sigma=0.5)
    n = 20000
    P = np.column_stack([rng.uniform(-5.0, 69.0, (n, 2)), rng.uniform(2.0, 6.0, n)])
    u = rng.normal(size=(n, 3)) * [1.0, 1.0, 0.2]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    p = mi.Point3f(*(mi.Float(P[:, k].astype(np.float32)) for k in range(3)))
    d = mi.Vector3f(*(mi.Float(u[:, k].astype(np.float32)) for k in range(3)))
    for c in (0.0, 0.2):
        _, (ball,) = node.eval_bounds(p, (c,))
        _, (line,) = node.eval_bounds(p, (c,), d)
        ball, line = ball.numpy(), line.numpy()
        for radius, dirs in ((ball, rng.normal(size=(n, 3))), (line, u * rng.choice([-1, 1], (n, 1)))):
            dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
            for frac in (rng.uniform(0, 0.999, n), np.full(n, 0.999)):
                Q = P + dirs * (radius * frac)[:, None]
                F = node.cpu_eval(Q)
                assert np.all(F[radius > 0] < -c + 1e-5), f"level {c}: F = {F[radius > 0].max():.4g}"
    # A lone spike in flat ground: points beside it, pushed to their balls' and lines'
    # ends towards it (where a window's radius or clearance off by sigma shows).
    G = np.full((40, 40), 1.0)
    G[20, 20] = 5.0
    spike = ConvolutionSurface(MaterialStacks.from_heightfield(G, 1.0, z0=0.0, z1=8.0, dz=0.02), sigma=0.5)
    P2 = np.column_stack([rng.uniform(10.0, 31.0, (n, 2)), rng.uniform(1.6, 6.0, n)])
    towards = np.array([20.5, 20.5, 3.0]) - P2
    towards[:, 2] *= rng.uniform(0.0, 1.0, n)
    towards /= np.linalg.norm(towards, axis=1, keepdims=True)
    p2 = mi.Point3f(*(mi.Float(P2[:, k].astype(np.float32)) for k in range(3)))
    d2 = mi.Vector3f(*(mi.Float(towards[:, k].astype(np.float32)) for k in range(3)))
    for c in (0.0, 0.2):
        for direction in (None, d2):
            _, (r2,) = spike.eval_bounds(p2, (c,), direction)
            r2 = r2.numpy()
            F = spike.cpu_eval(P2 + towards * (0.999 * r2)[:, None])
            assert np.all(F[r2 > 0] < -c + 1e-5), f"spike, level {c}: F = {F[r2 > 0].max():.4g}"
    # The coarse grid alone, as before the tops.
    node._tops.windows = []
    _, (coarse,) = node.eval_bounds(p, (0.0,), d)
    low = P[:, 2] < H.max() + 2.0
    assert np.median(line[low] / np.maximum(coarse.numpy()[low], 1e-6)) > 3.0
    assert column_tops.WINDOWS[0] * S.cell > node.sigma
