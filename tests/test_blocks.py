"""Implicit blocks (implicit-blocks-2020): sampling, fracturing, block shapes per
structure type, the replicated field (seamless tiling, Lipschitz bound, distance
bounds), presence, determinism, scene node and CLI."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from helpers import SCENES, variant

variant()

from arches_render import field as F  # noqa: E402
from arches_render.generators.blocks.block_field import BlockField  # noqa: E402
from arches_render.generators.blocks.fracture_discs import (  # noqa: E402
    STRUCTURES, Discs, cut_edges, disc_images, fracture_discs)
from arches_render.generators.blocks.poisson_disc import poisson_disc_periodic  # noqa: E402
from arches_render.generators.blocks.replication import presence_table, replicate  # noqa: E402
from arches_render.generators.blocks.tile_cache import (  # noqa: E402
    TileParams, build_tile, cached_tile, load_tile, save_tile)

SIZE = 8.0


@pytest.fixture(scope="module")
def tiles():
    """One small tile per structure type (s = 8 m, r = 0.4 m: ~5,000 samples)."""
    return {st: build_tile(TileParams(structure=st, size=SIZE, point_radius=0.4, seed=3))
            for st in STRUCTURES}


def _extents(tile):
    return np.array([np.ptp(tile.vertices(i), axis=0) for i in range(tile.n_blocks)])


def _rng_points(n, lo, hi, seed=0):
    return np.random.default_rng(seed).uniform(lo, hi, (n, 3))


# -- sampling and fracturing --------------------------------------------------------

def test_poisson_disc_is_a_periodic_poisson_set_and_deterministic():
    r = 0.5
    p = poisson_disc_periodic(10.0, r, seed=5)
    assert np.all((p >= 0) & (p < 10.0))
    d, _ = cKDTree(p, boxsize=10.0).query(p, 2)
    assert d[:, 1].min() >= r * (1 - 1e-9)          # minimum distance on the torus
    # Maximal up to the trials: no room left for a sample anywhere (a random probe
    # is within 2r of some sample).
    probe = _rng_points(20000, 0, 10.0, 1)
    assert cKDTree(p, boxsize=10.0).query(probe)[0].max() < 2 * r
    assert np.array_equal(p, poisson_disc_periodic(10.0, r, seed=5))
    assert not np.array_equal(p, poisson_disc_periodic(10.0, r, seed=6))
    with pytest.raises(ValueError):
        poisson_disc_periodic(10.0, 6.0)


def test_segment_disc_cut():
    discs = Discs(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]]), np.array([1.0]))
    a = np.array([[0.5, 0.0, -1.0], [1.5, 0.0, -1.0], [0.0, 0.0, 0.5], [0.2, 0.1, 1.0]])
    b = np.array([[0.5, 0.0, 1.0], [1.5, 0.0, 1.0], [0.0, 0.0, 2.0], [0.2, 0.1, -0.1]])
    assert cut_edges(a, b, discs).tolist() == [True, False, False, True]
    # Periodic images: the disc at x = 0 also cuts a segment at x = 10 (s = 10).
    img = disc_images(discs, 10.0, [-1, -1, -1], [11, 1, 1])
    assert cut_edges(np.array([[10.2, 0, -1.0]]), np.array([[10.2, 0, 1.0]]), img).tolist() == [True]


def test_structure_types_have_their_fracture_sets():
    s = 20.0
    tab = fracture_discs("tabular", s, seed=1)
    beds = ~np.isfinite(tab.radius)
    assert beds.sum() == 10 and np.allclose(np.abs(tab.normal[beds, 2]), 1.0)  # spacing 2 m
    col = fracture_discs("columnar", s, seed=1)
    sets = col.normal[~np.isfinite(col.radius) | (col.radius >= s)]
    assert np.allclose(sets[:, 2], 0.0, atol=1e-9)   # continuous sets around the z axis
    rh = fracture_discs("rhombohedral", s, seed=1)
    assert np.all(np.abs(rh.normal).max(1) < 0.97)   # oblique to every axis
    with pytest.raises(ValueError):
        fracture_discs("cubist", s)


# -- block shapes -------------------------------------------------------------------

def test_columnar_blocks_are_elongated_along_the_column_axis(tiles):
    med = np.median(_extents(tiles["columnar"]), axis=0)
    assert med[2] > 3.0 * max(med[0], med[1])


def test_columnar_axis_follows_the_structure_axis():
    t = build_tile(TileParams(structure="columnar", size=SIZE, point_radius=0.4, axis=(1, 0, 0), seed=3))
    med = np.median(_extents(t), axis=0)
    assert med[0] > 3.0 * max(med[1], med[2])


def test_tabular_blocks_are_flat(tiles):
    med = np.median(_extents(tiles["tabular"]), axis=0)
    assert med[2] < 0.4 * min(med[0], med[1])


def _volume_median(ext):
    """Per-axis median extent, weighted by block box volume (slivers weigh little)."""
    w = ext.prod(1)
    out = []
    for k in range(3):
        o = np.argsort(ext[:, k])
        c = np.cumsum(w[o])
        out.append(ext[o[np.searchsorted(c, c[-1] / 2)], k])
    return np.array(out)


def test_equidimensional_and_polyhedral_blocks_are_not_elongated(tiles):
    for st in ("equidimensional", "polyhedral"):
        med = _volume_median(_extents(tiles[st]))
        assert med.max() < 2.0 * med.min(), (st, med)


def test_face_orientations_per_structure(tiles):
    def aligned(tile):
        # The largest hull face of each block (its first plane after the six box planes).
        return np.mean([np.abs(tile.planes(i)[0][6]).max() > 0.97 for i in range(tile.n_blocks)])
    assert aligned(tiles["equidimensional"]) > 0.7
    assert aligned(tiles["rhombohedral"]) < 0.2
    assert aligned(tiles["polyhedral"]) < 0.4


def test_blocks_contain_their_cluster_and_are_few_planes(tiles):
    t = tiles["prismatic"]
    assert 20 < t.n_blocks < 2000
    assert t.stats["samples_in_blocks"] > 0.85
    assert np.all(t.count <= 6 + 12)
    # Each block's centroid is inside it.
    for i in range(t.n_blocks):
        n, w = t.planes(i)
        assert np.all(n @ t.centroid[i] < w)


# -- the field -----------------------------------------------------------------------

def test_tiling_is_periodic_and_seamless(tiles):
    tile = tiles["equidimensional"]
    bf = BlockField(tile, smoothness=0.2)
    p = _rng_points(4000, -SIZE, 2 * SIZE, 2)
    v = F.evaluate(bf, p)
    assert (v > 0).mean() > 0.3                       # the tile is mostly rock
    for axis in range(3):
        shift = np.zeros(3)
        shift[axis] = SIZE
        assert np.abs(F.evaluate(bf, p + shift) - v).max() < 2e-4
    # Blocks straddle the tile faces (unwrapped clusters) ...
    lo = np.array([tile.vertices(i).min(0) for i in range(tile.n_blocks)])
    hi = np.array([tile.vertices(i).max(0) for i in range(tile.n_blocks)])
    straddle = np.any((lo < -0.1) | (hi > SIZE + 0.1), axis=1)
    assert straddle.sum() >= 5
    # ... and the field is continuous across them: no jump at x = s.
    q = _rng_points(4000, 0, SIZE, 3)
    q[:, 0] = SIZE
    eps = np.array([1e-3, 0.0, 0.0])
    jump = np.abs(F.evaluate(bf, q + eps) - F.evaluate(bf, q - eps))
    assert jump.max() <= bf.lipschitz * 2e-3 + 2e-4


@pytest.mark.parametrize("warp", [0.0, 0.08])
def test_block_field_is_lipschitz_with_its_reported_bound(tiles, warp):
    bf = BlockField(tiles["rhombohedral"], smoothness=0.25, warp=warp, warp_wavelength=0.3, seed=1)
    rng = np.random.default_rng(4)
    p = rng.uniform(-2, SIZE + 2, (30000, 3))
    for scale in (0.3, 0.03, 0.003):
        q = p + rng.normal(size=p.shape) * scale
        ratio = np.abs(F.evaluate(bf, p) - F.evaluate(bf, q)) / np.linalg.norm(p - q, axis=1)
        assert ratio.max() <= bf.lipschitz * (1 + 1e-3) + 1e-3 / scale
    if warp:
        assert bf.lipschitz == pytest.approx(1 + warp * 3.76 * 2 / 0.3, rel=1e-6)
        # The bound is not vacuous: the detail does steepen the field.
        assert ratio.max() > 1.05


def _cliff():
    return F.Intersection(F.Box([-4.0, 0.0, 3.0], [5.0, 8.0, 3.0]), F.Plane([1.0, 0.0, 0.3], [0.0, 0.0, 3.0]))


@pytest.fixture(scope="module")
def amplified(tiles):
    return replicate(_cliff(), tiles["prismatic"], [-8, -7, 0], [3, 7, 7], distance_range=(-1.0, 1.0),
                     min_slope=50.0, smoothness=0.2, warp=0.04, warp_wavelength=0.4, seed=2)


def test_replicated_field_lipschitz_and_distance_bounds(amplified):
    import drjit as dr
    import mitsuba as mi
    node = amplified
    assert node.lipschitz == node.children[1].lipschitz > 1.0
    rng = np.random.default_rng(5)
    p = rng.uniform([-4, -8, -1], [4, 8, 7], (20000, 3))
    q = p + rng.normal(size=p.shape) * 0.05
    ratio = np.abs(F.evaluate(node, p) - F.evaluate(node, q)) / np.linalg.norm(p - q, axis=1)
    assert ratio.max() <= node.lipschitz * (1 + 1e-3) + 2e-2
    # eval_bounds: nothing of the solid within the returned distance of an air point.
    P = mi.Point3f(*(mi.Float(p[:, k].astype(np.float32)) for k in range(3)))
    f, (d,) = node.eval_bounds(P, (0.0,))
    dr.eval(f, d)
    f, d = f.numpy(), d.numpy()
    air = (f < 0) & (d > 0)
    assert air.mean() > 0.3
    dirs = rng.normal(size=(air.sum(), 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for frac in (0.5, 0.9, 0.999):
        probe = p[air] + dirs * (frac * d[air])[:, None]
        assert F.evaluate(node, probe).max() < 1e-4
    # The bound is better than Hart's -f/L somewhere (empty-space skipping).
    assert np.mean(d[air] > -f[air] / node.lipschitz * 1.5) > 0.1


def test_blocks_that_keep_no_copy_leave_the_host_its_own_free_distances(tiles):
    """A presence table that keeps no block (a region far from the host's surface) makes
    ``t = -m`` everywhere: ``{t >= 0}`` is empty, so the union must step as the host alone.
    The block field answered Hart's ``m / L`` (~20 cm) everywhere instead, and held every
    ray of every_generator to 271 steps where 36 do."""
    import drjit as dr
    import mitsuba as mi
    host = _cliff()
    node = replicate(host, tiles["prismatic"], [40, 40, 40], [41, 41, 41], distance_range=(-1.0, 1.0),
                     min_slope=50.0, smoothness=0.2, warp=0.04, warp_wavelength=0.4, seed=2)
    blocks = node.children[1]
    assert blocks.n_present == 0
    rng = np.random.default_rng(3)
    p = rng.uniform([-8, -8, -1], [8, 8, 12], (4000, 3)).astype(np.float32)
    P = mi.Point3f(*(mi.Float(p[:, k]) for k in range(3)))
    f_host, (d_host,) = host.eval_bounds(P, (0.0,))
    f, (d,) = node.eval_bounds(P, (0.0,))
    dr.eval(f_host, d_host, f, d)
    air = f_host.numpy() < 0
    assert air.mean() > 0.3
    assert np.array_equal(f.numpy(), np.maximum(f_host.numpy(), -blocks.m_np))
    assert np.allclose(d.numpy()[air], d_host.numpy()[air])
    _, (d_blocks,) = blocks.eval_bounds(P, (0.0,))
    assert np.all(np.isinf(d_blocks.numpy()))


def test_presence_follows_distance_range_and_slope(tiles, amplified):
    host = _cliff()
    blocks = amplified.children[1]
    assert blocks.n_present > 5
    # Far in the air and deep inside: no block.
    far = np.column_stack([np.full(500, 3.5), np.linspace(-6, 6, 500), np.full(500, 3.0)])
    assert np.all(F.evaluate(blocks, far) <= -blocks.m_np + 1e-6)
    # On the flat top (slope 0 < 50 deg): no block above it.
    top = np.column_stack([np.linspace(-8, -3, 400), np.linspace(-6, 6, 400), np.full(400, 6.1)])
    assert np.all(F.evaluate(blocks, top) < 0)
    # Every present copy has a majority of anchors in the distance range.
    tile = blocks.tile
    T, b = blocks.presence.cells, blocks.presence.blocks
    anchors = tile.anchors[b] + (T * tile.size)[:, None, :]
    f = F.evaluate(host, anchors.reshape(-1, 3)).reshape(anchors.shape[:2])
    assert np.all(((f >= -1.0) & (f <= 1.0)).sum(1) > anchors.shape[1] / 2)
    # A narrower range keeps a subset; no slope test keeps a superset.
    narrow = presence_table(tile, host, [-8, -7, 0], [3, 7, 7], (-0.3, 0.3), 50.0).dense()
    flat = presence_table(tile, host, [-8, -7, 0], [3, 7, 7], (-1.0, 1.0), 0.0).dense()
    kept = blocks.presence.dense()
    assert np.all(kept >= narrow) and narrow.sum() < kept.sum()
    assert np.all(flat >= kept) and flat.sum() > kept.sum()


def test_presence_pruning_keeps_exactly_the_copies_a_full_test_keeps(tiles):
    """The Lipschitz pruning of virtual cells (and the region test moved before the
    anchors) drop only copies that fail anyway: the table equals a brute-force one
    that tests every anchor of every block of every virtual cell."""
    host, tile = _cliff(), tiles["equidimensional"]
    lo, hi, rng = np.array([-8.0, -7, 0]), np.array([3.0, 7, 7]), (-0.6, 0.4)
    got = presence_table(tile, host, lo, hi, rng, 0.0).dense()
    s = tile.size
    t_lo, t_hi = np.floor(lo / s).astype(int), np.floor(hi / s).astype(int)
    T = np.stack(np.meshgrid(*[np.arange(t_lo[a], t_hi[a] + 1) for a in range(3)], indexing="ij"),
                 -1).reshape(-1, 3)
    A = tile.anchors[None].astype(np.float64) + s * T[:, None, None, :]
    f = F.evaluate(host, A.reshape(-1, 3)).astype(np.float64).reshape(A.shape[:3])
    ref = ((f >= rng[0]) & (f <= rng[1])).sum(-1) > A.shape[2] / 2
    ref &= np.all((A[:, :, 0] >= lo) & (A[:, :, 0] <= hi), axis=-1)
    ref = ref.reshape(*(t_hi - t_lo + 1), tile.n_blocks)
    assert 0 < ref.sum() < ref.size / 4         # pruning had cells to drop
    assert np.array_equal(got, ref)


def test_fallen_blocks_rest_on_gentle_ground_and_thin_out_with_density(tiles):
    """``max_slope`` keeps copies on ground a block can rest on (the cliff's flat top,
    not its 73-degree wall nor the box's flat underside); ``density`` keeps each copy with the probability at its
    centroid, by a draw of its own: a subset, about that share, nothing where it is 0,
    the same copies for the same seed."""
    host, tile = _cliff(), tiles["equidimensional"]
    args = ([-8, -7, 0], [3, 7, 7], (-1.0, 1.0))
    ground = presence_table(tile, host, *args, 0.0, max_slope=30.0)
    everywhere = presence_table(tile, host, *args, 0.0)
    c = tile.centroid[ground.blocks] + ground.cells * tile.size
    assert len(c) > 20 and np.all(c[:, 2] > 4.0)     # on the top (z = 6), none down the wall
    assert np.all(everywhere.dense() >= ground.dense()) and len(everywhere.blocks) > len(ground.blocks)
    with pytest.raises(ValueError, match="min_slope <= max_slope"):
        presence_table(tile, host, *args, 50.0, max_slope=30.0)

    n = len(everywhere.blocks)
    full = presence_table(tile, host, *args, 0.0, density=np.ones((4, 4)), seed=1)
    assert np.array_equal(full.dense(), everywhere.dense())
    half = presence_table(tile, host, *args, 0.0, density=np.full((4, 4), 0.3), seed=1)
    k = len(half.blocks)
    assert np.all(everywhere.dense() >= half.dense())
    assert abs(k - 0.3 * n) < 4 * np.sqrt(n * 0.3 * 0.7), (k, n)
    assert np.array_equal(half.dense(), presence_table(tile, host, *args, 0.0, density=np.full((4, 4), 0.3),
                                                       seed=1).dense())
    other = presence_table(tile, host, *args, 0.0, density=np.full((4, 4), 0.3), seed=2)
    assert not np.array_equal(half.dense(), other.dense())
    west = np.zeros((4, 4))
    west[:, :2] = 1.0                               # x in [-8, -2.5): kept; east of it: none
    side = presence_table(tile, host, *args, 0.0, density=west, seed=1)
    cx = (tile.centroid[side.blocks] + side.cells * tile.size)[:, 0]
    assert len(cx) > 5 and np.all(cx < -2.5)
    for bad in (np.full((2, 2), 1.5), np.zeros(3)):
        with pytest.raises(ValueError, match="density"):
            presence_table(tile, host, *args, 0.0, density=bad)


def test_resting_blocks_touch_the_host_with_three_anchors(tiles):
    """``contact``: of the copies the majority rule keeps over the cliff's flat top (a
    distance range reaching 3 m into the air keeps blocks hovering over it), only those
    with at least three anchors within ``contact`` of the host or inside it stay: a
    subset, which drops every hovering copy and keeps some."""
    from arches_render.generators.blocks.replication import CONTACTS
    host, tile = _cliff(), tiles["equidimensional"]
    args = ([-8, -7, 0], [3, 7, 9], (-3.0, 1.0), 0.0)
    loose = presence_table(tile, host, *args, max_slope=30.0)
    resting = presence_table(tile, host, *args, max_slope=30.0, contact=0.1)

    def touching(p):
        A = tile.anchors[p.blocks].astype(np.float64) + (p.cells * tile.size)[:, None, :]
        f = F.evaluate(host, A.reshape(-1, 3)).astype(np.float64).reshape(A.shape[:2])
        return (f >= -0.1).sum(-1)

    assert np.all(loose.dense() >= resting.dense())
    assert len(resting.blocks) > 5 and np.all(touching(resting) >= CONTACTS)
    assert np.sum(touching(loose) < CONTACTS) > 5          # hovering copies were there to drop
    assert len(resting.blocks) == np.sum(touching(loose) >= CONTACTS)
    with pytest.raises(ValueError, match="contact"):
        presence_table(tile, host, *args, contact=-1.0)


def test_presence_by_resistance(tiles):
    host, tile = _cliff(), tiles["prismatic"]
    args = ([-8, -7, 0], [3, 7, 7], (-1.0, 1.0), 50.0)
    base = presence_table(tile, host, *args).dense()
    hard = presence_table(tile, host, *args, resistance=0.8, resistance_range=(0.5, 1.0)).dense()
    soft = presence_table(tile, host, *args, resistance=0.2, resistance_range=(0.5, 1.0)).dense()
    assert np.array_equal(hard, base) and not soft.any()
    # A stratum node: resistance = z, blocks only between z = 2 and 4 (anchor majority).
    strata = F.Plane([0.0, 0.0, -1.0], [0.0, 0.0, 0.0])   # field = z
    table = presence_table(tile, host, *args, resistance=strata, resistance_range=(2.0, 4.0))
    mid, t_lo = table.dense(), table.tiles_lo
    assert 0 < mid.sum() < base.sum()
    idx = np.argwhere(mid)
    z = (tile.centroid[idx[:, 3]] + (idx[:, :3] + t_lo) * tile.size)[:, 2]
    assert np.all((z > 1.0) & (z < 5.0))


def test_tiles_are_deterministic_and_cached(tmp_path):
    p = TileParams(structure="tabular", size=SIZE, point_radius=0.45, seed=9)
    a, b = build_tile(p), build_tile(p)
    for k in ("normals", "offsets", "start", "count", "anchors"):
        assert np.array_equal(getattr(a, k), getattr(b, k))
    c = build_tile(TileParams(structure="tabular", size=SIZE, point_radius=0.45, seed=10))
    assert c.offsets.shape != a.offsets.shape or not np.array_equal(c.offsets, a.offsets)
    cached = cached_tile(p, tmp_path)
    assert len(list(tmp_path.glob("*.npz"))) == 1 and np.array_equal(cached.offsets, a.offsets)
    again = cached_tile(p, tmp_path)
    assert again.stats == cached.stats
    save_tile(a, tmp_path / "t.npz")
    assert np.array_equal(load_tile(tmp_path / "t.npz").normals, a.normals)
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not a block tile"):
        load_tile(tmp_path / "bad.npz")
    assert a.nbytes() < 600_000


# -- scene node and CLI --------------------------------------------------------------

MINI = """
[render]
resolution = [40, 30]
[camera]
origin = [12.0, -6.0, 4.0]
target = [0.0, 0.0, 2.5]
[[lights]]
type = "sunsky"
elevation = 40.0
[materials.rock]
type = "triplanar"
preset = "limestone"
[field]
root = "b"
material = "rock"
[nodes.b]
type = "blocks"
host = { type = "box", center = [-3.0, 0.0, 2.5], size = [6.0, 8.0, 5.0] }
structure = "equidimensional"
tile_size = 6.0
point_radius = 0.35
region = [-2.0, -4.0, 0.0, 2.0, 4.0, 5.0]
seed = 1
"""


def _load(text, tmp_path):
    import tomllib

    from arches_render.scene import parse_scene
    return parse_scene(tomllib.loads(text), tmp_path / "s.toml")


def test_scene_node_builds_and_is_deterministic(tmp_path, monkeypatch):
    monkeypatch.setenv("ARCHES_RENDER_CACHE", str(tmp_path / "cache"))
    a = _load(MINI, tmp_path).field
    b = _load(MINI, tmp_path).field
    p = _rng_points(3000, [-2, -4, 0], [2, 4, 5], 7)
    va = F.evaluate(a, p)
    assert np.array_equal(va, F.evaluate(b, p))
    c = _load(MINI.replace("seed = 1", "seed = 2"), tmp_path).field
    assert not np.array_equal(va, F.evaluate(c, p))
    # The blocks change the host: some points are rock only because of them.
    host = a.children[0]
    assert np.any((va > 0) & (F.evaluate(host, p) < 0))


@pytest.mark.parametrize("edit, key", [
    ('structure = "equidimensional"', 'structure = "cubist"'),
    ("tile_size = 6.0", "tile_size = 0.5"),
    ("region = [-2.0, -4.0, 0.0, 2.0, 4.0, 5.0]", "region = [2.0, -4.0, 0.0, -2.0, 4.0, 5.0]"),
    ("seed = 1", "seed = 1\nwarp = -1.0"),
    ("seed = 1", "seed = 1\ndistance_range = [1.0, -1.0]"),
    ("seed = 1", "seed = 1\nspacng = 2.0"),
    ("seed = 1", 'seed = 1\ntile = "missing.npz"'),
])
def test_bad_blocks_keys_name_the_key(tmp_path, monkeypatch, edit, key):
    from arches_render.scene import SceneError
    monkeypatch.setenv("ARCHES_RENDER_CACHE", str(tmp_path / "cache"))
    with pytest.raises(SceneError) as err:
        _load(MINI.replace(edit, key), tmp_path)
    assert "nodes.b." in str(err.value)


def test_scene_density_max_slope_and_contact_keys(tmp_path, monkeypatch):
    """``density`` (an .npz grid over the region), ``max_slope`` and ``contact`` reach the
    presence table; bad values name their key."""
    from arches_render.npzfile import write_npz
    from arches_render.scene import SceneError
    monkeypatch.setenv("ARCHES_RENDER_CACHE", str(tmp_path / "cache"))
    for name, grid in (("zero", np.zeros((3, 2))), ("one", np.ones((3, 2))), ("bad", np.full((3, 2), 1.5))):
        with open(tmp_path / f"{name}.npz", "wb") as f:
            write_npz(f, {"density": grid})
    base = _load(MINI.replace("seed = 1", "seed = 1\nmin_slope = 0.0"), tmp_path).field.children[1]
    ones = _load(MINI.replace("seed = 1", 'seed = 1\nmin_slope = 0.0\ndensity = "one.npz"'), tmp_path)
    assert np.array_equal(ones.field.children[1].presence.dense(), base.presence.dense())
    zero = _load(MINI.replace("seed = 1", 'seed = 1\nmin_slope = 0.0\ndensity = "zero.npz"'), tmp_path)
    assert base.n_present > 0 and zero.field.children[1].n_present == 0
    # The host box's top faces up (flat); its side walls do not: max_slope 30 keeps fewer.
    flat = _load(MINI.replace("seed = 1", "seed = 1\nmin_slope = 0.0\nmax_slope = 30.0"), tmp_path)
    assert 0 < flat.field.children[1].n_present < base.n_present
    # contact: the blocks that rest on the host, a subset.
    rest = _load(MINI.replace("seed = 1", "seed = 1\nmin_slope = 0.0\ncontact = 0.05"), tmp_path)
    assert np.all(base.presence.dense() >= rest.field.children[1].presence.dense())
    assert 0 < rest.field.children[1].n_present < base.n_present
    for extra, key in (('density = "bad.npz"', "density"), ('density = "none.npz"', "density"),
                       ("max_slope = 40.0", "max_slope"),   # below min_slope's default 60
                       ("contact = -1.0", "contact")):
        with pytest.raises(SceneError) as err:
            _load(MINI.replace("seed = 1", "seed = 1\n" + extra), tmp_path)
        assert f"nodes.b.{key}" in str(err.value), str(err.value)


def test_cli_builds_a_tile_and_the_scene_uses_it(tmp_path, monkeypatch, capsys):
    from arches_render.cli import main
    monkeypatch.setenv("ARCHES_RENDER_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "s.toml"
    scene.write_text(MINI)
    out = tmp_path / "tile.npz"
    assert main(["blocks", str(scene), "-o", str(out), "-q"]) == 0
    assert "blocks from" in capsys.readouterr().out
    tile = load_tile(out)
    assert tile.params["structure"] == "equidimensional" and tile.n_blocks > 10
    # The scene with tile = "tile.npz" gives the same field as the parameters.
    keys = ('structure = "equidimensional"\n', "tile_size = 6.0\n", "point_radius = 0.35\n")
    text = MINI
    for k in keys:
        text = text.replace(k, "")
    from_file = _load(text.replace("seed = 1", 'seed = 1\ntile = "tile.npz"'), tmp_path).field
    p = _rng_points(2000, [-2, -4, 0], [2, 4, 5], 8)
    assert np.array_equal(F.evaluate(from_file, p), F.evaluate(_load(MINI, tmp_path).field, p))
    # Bad input: exit 2 with one line, no output written.
    assert main(["blocks", str(scene), "-o", str(tmp_path / "t.txt")]) == 2
    assert main(["blocks", str(SCENES / "boulders.toml"), "-o", str(tmp_path / "x.npz")]) == 2
    assert main(["blocks", str(scene), "--node", "nope", "-o", str(tmp_path / "y.npz")]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 3 and "Traceback" not in err
    assert not (tmp_path / "x.npz").exists() and not (tmp_path / "y.npz").exists()


@pytest.mark.parametrize("name", sorted(p.stem for p in SCENES.glob("blocks_*.toml")))
def test_shipped_blocks_scenes_mesh_lies_on_the_field(name):
    """Cross-check of the two geometries of a shipped scene: the marching-cubes mesh
    (what ``--geometry mesh`` renders) lies on the field's zero set, and the blocks
    are there (the amplified field differs from its host near the surface). The
    image comparison of field and mesh renders is in tests/test_render.py."""
    from arches_render.mesh.polygonize import polygonize
    from arches_render.scene import load_scene
    desc = load_scene(SCENES / f"{name}.toml")
    node = desc.field
    mesh = polygonize(node, 0.12)
    v = np.asarray(mesh.vertices)
    assert len(v) > 1000
    f = F.evaluate(node, v)
    # Distance of each vertex to the zero set, to first order |f| / |grad f| (central differences,
    # a step far below the voxel). Marching cubes places vertices on the zero set of the trilinear
    # interpolant: off the true surface by a small fraction of the voxel where the field is smooth,
    # more near block edges and corners. A mesh shifted by half a voxel, or sampled on a grid
    # offset from the one it is placed on, puts the typical vertex ~0.3 voxel off.
    h = 1e-3
    grad = np.stack([(F.evaluate(node, v + h * e) - F.evaluate(node, v - h * e)) / (2 * h)
                     for e in np.eye(3)], -1)
    dist = np.abs(f) / np.maximum(np.linalg.norm(grad, axis=-1), 1e-6) / 0.12  # in voxels
    assert np.median(dist) < 0.02 and np.quantile(dist, 0.9) < 0.08, (np.median(dist), np.quantile(dist, 0.9))
    host = F.evaluate(node.children[0], v)
    assert np.mean(f - host > 0.05) > 0.2           # many surface points belong to blocks
