"""Physics of the terrain-amplification processes (Paris et al. 2019, section 6):
hydrology (depression filling, Freeman MFD drainage area), accessibility of sea
erosion, shallow erosion intensity, invasion percolation, hoodoo grammar, and
the DEM reader's edge cases."""

from __future__ import annotations

import numpy as np
import pytest

from arches_render.field import heightmaps
from arches_render.generators.terrain import hydrology as hy
from arches_render.generators.terrain.accessibility import accessibility, heightfield_mesh
from arches_render.generators.terrain.shallow_erosion import erosion_intensity, poisson_thin


# -- hydrology --------------------------------------------------------------------------------
def _has_lower_neighbour(Z):
    ny, nx = Z.shape
    c = Z[1:-1, 1:-1]
    ok = np.zeros_like(c, dtype=bool)
    for a in (-1, 0, 1):
        for b in (-1, 0, 1):
            if a or b:
                ok |= Z[1 + a:ny - 1 + a, 1 + b:nx - 1 + b] < c
    return ok


def test_depression_filling_is_the_least_pit_free_surface():
    from skimage.morphology import reconstruction
    rng = np.random.default_rng(3)
    H = rng.normal(size=(80, 120)).cumsum(axis=0) * 0.2 + rng.normal(size=(80, 120))
    assert not _has_lower_neighbour(H).all()  # the input has pits
    Z = hy.fill_depressions(H)
    # Independent reference: morphological reconstruction by erosion from the border.
    seed = H.copy()
    seed[1:-1, 1:-1] = H.max()
    np.testing.assert_array_equal(Z, reconstruction(seed, H, method="erosion"))
    assert np.all(Z >= H) and np.array_equal(Z[0], H[0]) and np.array_equal(Z[:, -1], H[:, -1])
    # With epsilon every interior cell drains to a strictly lower neighbour: no pit, no flat.
    Ze = hy.fill_depressions(H, epsilon=1e-6)
    assert _has_lower_neighbour(Ze).all()
    assert np.all(Ze >= Z) and (Ze - Z).max() < 1e-6 * H.size


def test_flow_accumulation_cone_matches_analytic_specific_catchment():
    # A cone h = 100 - r: the area draining through a ring cell of width dx at radius r
    # is the ring's share of the disc, A / dx = (r + dx/2)^2 / (2 r) (Freeman 1991's test).
    dx = 2.0
    x = (np.arange(161) - 80) * dx
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X, Y)
    A = hy.flow_accumulation(100.0 - r, dx, fill=False)
    for R0 in (20.0, 60.0, 120.0):
        ring = np.abs(r - R0) < dx / 2
        analytic = (R0 + dx / 2) ** 2 / (2 * R0)
        # Freeman's dispersion lets some flow cross a ring cell sideways: a few % high.
        assert A[ring].mean() / dx == pytest.approx(analytic, rel=0.07)
        # Multiple flow directions are isotropic on a cone (D8 would vary by ~40 % here).
        assert A[ring].std() / A[ring].mean() < 0.03
    # Mass balance: every cell's area leaves through the border.
    assert A.max() < A.size * dx * dx


def test_flow_accumulation_valley_matches_analytic_discharge():
    # V-shaped valley h = s|x| + t y: flow lines follow -grad h and meet the channel
    # (x = 0) at y' = y - (t/s)|x|; the channel discharge at y_c is the area of the
    # points whose flow line meets it upstream of y_c.
    s, t, dx = 1.0, 0.1, 1.0
    W, L = 60, 120
    x = np.arange(-W, W + 1.0)
    y = np.arange(0, L + 1.0)
    X, Y = np.meshgrid(x, y)
    A = hy.flow_accumulation(s * np.abs(X) + t * Y, dx)
    xs = np.linspace(-W - 0.5, W + 0.5, 20001)
    for jc in (20, 60, 100):
        analytic = np.clip((L + 0.5) - (jc - 0.5) - (t / s) * np.abs(xs), 0, None).sum() * (xs[1] - xs[0])
        assert A[jc, W] == pytest.approx(analytic, rel=0.005)


def test_flow_accumulation_drains_a_pit_after_filling():
    x = np.linspace(-1, 1, 41)
    X, Y = np.meshgrid(x, x)
    H = X + 0.3 * Y - 2.0 * np.exp(-((X - 0.1) ** 2 + Y ** 2) / 0.02)  # a crater on a tilted plane
    A = hy.flow_accumulation(H, 1.0)
    # Nothing is trapped: the whole grid leaves through the low (x = -1) border column.
    low_border = A[:, 0].sum() + A[0, 1:].sum() + A[-1, 1:].sum()
    assert low_border >= 0.999 * H.size - 1e-6
    assert len(hy.pits(H)) >= 1 and len(hy.pits(hy.fill_depressions(H, 1e-6))) == 0


def test_stream_power_peaks_in_the_channel():
    x = np.arange(-30, 31.0)
    X, Y = np.meshgrid(x, np.arange(0, 80.0))
    sigma, A, s = hy.stream_power(0.5 * np.abs(X) + 0.2 * Y, 1.0)
    j = 40
    np.testing.assert_allclose(sigma, np.sqrt(A) * s)
    assert s[j, 30] == pytest.approx(0.2) and s[j, 10] == pytest.approx(np.hypot(0.5, 0.2))
    assert np.argmax(sigma[j]) == 30 and sigma[j, 30] > 3 * np.median(sigma[j])


# -- erosion intensity, sampling --------------------------------------------------------------
def test_erosion_intensity_corners():
    beta = 0.3
    assert erosion_intensity(0.4, 0.0, beta) == 0.0          # no stress, no erosion
    assert erosion_intensity(1.0, 1.0, beta) == pytest.approx(beta)
    assert erosion_intensity(0.0, 1.0, beta) == pytest.approx(1.0)
    rho = np.linspace(0, 1, 11)
    e = erosion_intensity(rho, 0.8, beta)
    assert np.all(np.diff(e) < 0)                             # softer rock erodes more


def test_poisson_thinning_keeps_the_minimum_distance():
    from scipy.spatial import cKDTree
    rng = np.random.default_rng(0)
    P = rng.random((5000, 2)) * 10
    keep = poisson_thin(P, 0.5, rng)
    d, _ = cKDTree(P[keep]).query(P[keep], k=2)
    assert d[:, 1].min() >= 0.5
    # Maximal: every dropped candidate is within 0.5 of a kept point.
    d2, _ = cKDTree(P[keep]).query(P)
    assert d2.max() < 0.5



@pytest.mark.parametrize("dim, radius", [(2, 0.3), (3, 0.5), (3, 2.0)])
def test_poisson_thinning_is_the_greedy_pass_in_the_random_order(dim, radius):
    # Brute force: candidate i (in the generator's order) is kept iff no kept point
    # lies within radius. A cliff-like stack (many candidates in one column, spread
    # in z) and points on cell boundaries exercise the grid's neighbour runs.
    rng = np.random.default_rng(dim)
    P = rng.random((1500, dim)) * 6.0
    P[:300, :2] = 3.0 + 0.2 * rng.random((300, 2))
    if dim == 3:
        P[:300, 2] = 20.0 * rng.random(300)
    P[300:400] = np.round(P[300:400] / radius) * radius
    keep = poisson_thin(P, radius, np.random.default_rng(7))
    order = np.random.default_rng(7).permutation(len(P))
    kept = []
    for i in order:
        if all(np.sum((P[i] - P[j]) ** 2) > radius * radius for j in kept):
            kept.append(i)
    np.testing.assert_array_equal(keep, np.sort(kept))
    with pytest.raises(ValueError, match="finite"):
        poisson_thin(np.full((1, dim), np.nan), radius, rng)

# -- accessibility -----------------------------------------------------------------------------
def _cliff_with_cave():
    import trimesh
    from skimage.measure import marching_cubes
    v = 0.5
    xs, ys, zs = np.arange(-20, 30 + v, v), np.arange(-20, 20 + v, v), np.arange(-5, 25 + v, v)
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    box = np.minimum.reduce([X, 28 - X, Y + 18, 18 - Y, Z + 3, 20 - Z])   # cliff face at x = 0
    P = np.stack([X, Y, Z], -1)
    a, b = np.array([-5.0, 0, 8]), np.array([12.0, 0, 8])                  # a cave 12 m deep, r = 3
    t = np.clip((P - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    cave = np.linalg.norm(P - a - t[..., None] * (b - a), axis=-1) - 3.0
    V, F, _, _ = marching_cubes(np.minimum(box, cave), 0.0, spacing=(v, v, v))
    return trimesh.Trimesh(V + [xs[0], ys[0], zs[0]], F[:, ::-1], process=False)


def test_accessibility_is_lower_inside_a_cave_than_on_an_open_cliff():
    mesh = _cliff_with_cave()
    pts = np.array([[0.0, 0.0, 15.0],    # open cliff face above the cave
                    [0.0, 10.0, 5.0],    # open cliff face beside it
                    [14.99, 0.0, 8.0],   # back wall of the cave
                    [8.0, 0.0, 10.99]])  # cave ceiling, 8 m in
    nrm = np.array([[-1.0, 0, 0], [-1, 0, 0], [-1, 0, 0], [0, 0, -1]])
    alpha = accessibility(mesh, pts, nrm, distance=20.0, rays=64, seed=1)
    assert alpha[0] > 0.9 and alpha[1] > 0.9
    assert alpha[2] < 0.3 and alpha[3] < 0.3
    # Deterministic for a seed.
    np.testing.assert_array_equal(alpha, accessibility(mesh, pts, nrm, 20.0, rays=64, seed=1))


def test_ray_caster_first_hit_gives_the_distance_and_the_hit_triangles_normal():
    """``RayCaster.first_hit``: the same distances as ``hit_distance`` (inf on a miss) and
    the unit normal of the face hit (the cliff's face, its top, the back of its cave)."""
    from arches_render.generators.terrain.accessibility import RayCaster
    caster = RayCaster(_cliff_with_cave())
    O = np.array([[-20.0, 10.0, 5.0], [10.0, 10.0, 60.0], [-20.0, 0.0, 8.0], [-20.0, 0.0, 200.0]])
    D = np.array([[1.0, 0, 0], [0, 0, -1.0], [1.0, 0, 0], [0, 0, 1.0]])
    t, n = caster.first_hit(O, D, 100.0)
    np.testing.assert_allclose(t, caster.hit_distance(O, D, 100.0), rtol=1e-6)
    # (marching cubes at 0.5 m voxels puts the faces within a fraction of a voxel)
    np.testing.assert_allclose(t[:3], [20.0, 40.0, 35.0], atol=0.3)
    assert np.isinf(t[3]) and not n[3].any()
    np.testing.assert_allclose(np.linalg.norm(n[:3], axis=1), 1.0, rtol=1e-6)
    # Plane faces exactly (up to float32 rounding of the vertices, ~1e-7); the cave's
    # rounded back as marching cubes facets it.
    np.testing.assert_allclose(np.abs(n[:2]), [[1, 0, 0], [0, 0, 1]], atol=1e-6)
    assert abs(n[2, 0]) > 0.95


def test_accessibility_of_a_valley_floor_falls_with_its_depth():
    x = np.linspace(-50, 50, 101)
    X, Y = np.meshgrid(x, x)
    out = []
    for depth in (2.0, 20.0, 60.0):
        H = depth * np.clip(np.abs(X) / 10.0, 0, 1)  # flat floor 20 m wide between walls
        mesh = heightfield_mesh(H, (-50, -50, 50, 50))
        out.append(accessibility(mesh, [[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], 100.0, rays=256, seed=0)[0])
    assert out[0] > out[1] > out[2]


# -- DEM reading -------------------------------------------------------------------------------
def test_dem_png16_tiff_npy_agree(tmp_path):
    import imageio.v3 as iio
    import tifffile
    rng = np.random.default_rng(0)
    raw = rng.integers(0, 65536, (20, 30), dtype=np.uint16)
    iio.imwrite(tmp_path / "a.png", raw)
    tifffile.imwrite(tmp_path / "a.tif", raw.astype(np.float32))
    np.save(tmp_path / "a.npy", raw.astype(np.float64))
    png = heightmaps.read_dem(tmp_path / "a.png")
    assert png.normalised and np.allclose(png.heights * 65535, raw)
    np.testing.assert_array_equal(heightmaps.read_dem(tmp_path / "a.tif").heights, raw)
    np.testing.assert_array_equal(heightmaps.read_dem(tmp_path / "a.npy").heights, raw)


def test_dem_nodata_is_filled_with_the_nearest_height(tmp_path):
    import tifffile
    H = np.tile(np.arange(10.0), (8, 1))
    H[2:4, 6:8] = np.nan
    np.save(tmp_path / "n.npy", H)
    dem = heightmaps.read_dem(tmp_path / "n.npy")
    assert dem.filled == 4 and np.all(np.isfinite(dem.heights)) and "no-data" in dem.notes[0]
    assert set(np.unique(dem.heights[2:4, 6:8])) <= {5.0, 6.0, 7.0, 8.0}
    # GeoTIFF no-data tag (GDAL_NODATA, 42113).
    T = np.tile(np.arange(6.0, dtype=np.float32), (6, 1))
    T[0, 0] = -9999
    tifffile.imwrite(tmp_path / "t.tif", T, extratags=[(42113, "s", 0, "-9999", True)])
    got = heightmaps.read_dem(tmp_path / "t.tif")
    assert got.filled == 1 and got.heights[0, 0] in (0.0, 1.0)


@pytest.mark.parametrize("shape,message", [((1, 1), "at least 2x2"), ((1, 50), "at least 2x2"),
                                           ((4, 4, 4, 4), "2-D")])
def test_dem_too_small_or_not_2d(tmp_path, shape, message):
    np.save(tmp_path / "s.npy", np.zeros(shape))
    with pytest.raises(heightmaps.DEMError, match=message):
        heightmaps.read_dem(tmp_path / "s.npy")


def test_dem_all_nodata_flat_and_unknown(tmp_path):
    np.save(tmp_path / "nan.npy", np.full((5, 5), np.nan))
    with pytest.raises(heightmaps.DEMError, match="no valid height"):
        heightmaps.read_dem(tmp_path / "nan.npy")
    np.save(tmp_path / "flat.npy", np.full((5, 5), 7.0))
    flat = heightmaps.read_dem(tmp_path / "flat.npy")
    assert np.all(flat.heights == 7.0) and any("flat" in n for n in flat.notes)
    (tmp_path / "x.jpg").write_bytes(b"nope")
    with pytest.raises(heightmaps.DEMError, match="unknown DEM format"):
        heightmaps.read_dem(tmp_path / "x.jpg")
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(heightmaps.DEMError, match="cannot read"):
        heightmaps.read_dem(tmp_path / "bad.png")


_DEM_MEMORY_PROBE = """
import json, resource, sys
import numpy as np
from arches_render.field import heightmaps
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
dem = heightmaps.read_dem(sys.argv[1], max_samples=1000 * 1000)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"grown_mb": (peak - base) / 1024, "shape": dem.heights.shape, "step": dem.step,
                  "source": dem.source_shape, "corner": float(dem.heights[:50, :50].min()),
                  "rest": float(dem.heights[60:, 60:].max()), "notes": dem.notes}))
"""


def test_dem_20000_squared_is_reduced_with_bounded_memory(tmp_path):
    import json
    import subprocess
    import sys
    path = tmp_path / "huge.npy"
    # A sparse file: 20,000^2 float16 samples (800 MB logical) that cost no disk.
    big = np.lib.format.open_memmap(path, mode="w+", dtype=np.float16, shape=(20000, 20000))
    big[:1000, :1000] = 3.0  # one corner block of real data
    big.flush()
    del big
    # ru_maxrss is the peak of the whole process: measured in a fresh one, where nothing
    # before the read has raised it (in this process, earlier tests' renders have).
    run = subprocess.run([sys.executable, "-c", _DEM_MEMORY_PROBE, str(path)], capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["shape"] == [1000, 1000] and got["step"] == 20 and got["source"] == [20000, 20000]
    assert got["corner"] == 3.0 and got["rest"] == 0.0
    assert got["grown_mb"] < 200, got  # never the 800 MB (or 3.2 GB as float64) of the whole array
    assert "reduced" in got["notes"][0]


def test_dem_huge_png_is_refused_clearly(tmp_path, monkeypatch):
    import imageio.v3 as iio
    iio.imwrite(tmp_path / "p.png", np.zeros((40, 40), np.uint16))
    monkeypatch.setattr(heightmaps, "DECODE_LIMIT", 1000)
    with pytest.raises(heightmaps.DEMError, match="more than a PNG can be decoded"):
        heightmaps.read_dem(tmp_path / "p.png")


def test_accessibility_of_open_ground_is_one_at_any_reach():
    # A ray that meets nothing comes back with its tfar unchanged; at a reach that is not a
    # float32 number (13.7) it must still count as escaping.
    mesh = heightfield_mesh(np.zeros((11, 11)), (-50, -50, 50, 50))
    for reach in (13.7, 20.0, 0.3):
        a = accessibility(mesh, [[1.0, 2.0, 0.0]], [[0.0, 0.0, 1.0]], reach, rays=64, seed=0)
        assert a[0] == 1.0


# -- geology of the river preset ----------------------------------------------------------------
@pytest.mark.parametrize("zlo,zhi,spacing", [(0.0, 160.0, 20.0), (-40.0, 1500.0, 15.0), (100.0, 104.0, 30.0)])
def test_river_beds_cover_the_relief_irregularly_within_their_ranges(zlo, zhi, spacing):
    from arches_render.generators.terrain.presets import MAX_BEDS, bed_planes
    beds = bed_planes(zlo, zhi, spacing, np.random.default_rng(5))
    z = np.array([b["point"][2] for b in beds])
    R = np.array([b["R"] for b in beds])
    w = np.array([b["weight"] for b in beds])
    used = max(spacing, 2.0 * (zhi - zlo) / (MAX_BEDS - 5))  # widened where beds would outnumber the cap
    assert 2 <= len(beds) <= MAX_BEDS
    # The relief and a spacing beyond each end are covered: no gap wider than 1.5 spacings.
    assert z[0] <= zlo and z[-1] >= zhi
    gaps = np.diff(z) / used
    assert np.all(gaps >= 0.5) and np.all(gaps <= 1.5)
    assert np.all((R >= 0.15 * used) & (R <= 0.45 * used)) and np.all((w >= -0.85) & (w <= -0.3))
    if len(beds) >= 4:  # irregular: not one repeated bed (the periodic strata this replaced)
        assert np.ptp(gaps) > 0.1 and np.ptp(R / used) > 0.05 and np.ptp(w) > 0.05
    # Same generator state, same beds.
    assert bed_planes(zlo, zhi, spacing, np.random.default_rng(5)) == beds
