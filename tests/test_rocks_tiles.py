"""Rock tiles (rock-piles-aperiodic-2009, Arches 2009): corner cubes, seeds, Voronoi, contacts,
erosion, meshes. Small grids (n = 4, 6 or 8 voxels per cell) keep these fast."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from arches_render.generators.rocks import aperiodic_tiles as at
from arches_render.generators.rocks import corner_cubes as cc
from arches_render.generators.rocks.anisotropic_voronoi import CellIndex, voronoi_labels
from arches_render.generators.rocks.contact_points import adjacent_label_pairs, bisect_contacts
from arches_render.generators.rocks.damped_erosion import damping_field, damping_piecewise, erode
from arches_render.generators.rocks.periodic_tile import build_periodic_tile, poisson_points
from arches_render.generators.rocks.rock_meshes import closed_oriented, mesh_rock
from arches_render.generators.rocks.seed_points import SeedParams, anisotropic_distance, cell_seeds
from arches_render.generators.rocks.tile_cache import cache_key
from arches_render.generators.rocks.tile_params import ErosionParams, TileParams

SMALL = TileParams(n=4, voxels_per_cell=6, seed=3, seeds=SeedParams(g_max=4.0, alpha=(0.6, 1.6)),
                   erosion=ErosionParams(steps=6))


# ----------------------------------------------------------------------------- corner cubes
def test_region_counts_match_the_paper():
    kinds = {}
    for mask, _ in cc.regions():
        kinds[bin(mask).count("1")] = kinds.get(bin(mask).count("1"), 0) + 1
    # 2 vertex, 12 edge, 48 face and 256 centre regions (section 3).
    assert kinds == {3: 2, 2: 12, 1: 48, 0: 256}
    for config in (0, 1, 77, 255):
        slots = at.cube_slots(config)
        assert len(slots) == 27
        assert len({(s, tuple(b)) for s, b in slots}) == 27


@pytest.mark.parametrize("n", [4, 5, 7])
def test_owner_is_the_lowest_dimensional_region_within_one_cell(n):
    """The closed-form owner equals the paper's sequential fill: a cell's seeds come from the
    vertex region within one cell of it, else the edge region, else the face, else the centre."""
    lo = -n - 2
    size = 2 * n + 5
    cells = np.array(list(itertools.product(range(lo, lo + size), repeat=3)))
    hits = np.zeros((4, size, size, size), np.int32)      # regions of each dimension within 1 cell
    who = np.zeros((4, size, size, size, 4), np.int64)    # (mask, L) of the last such region
    for L in itertools.product(range(-2, 3), repeat=3):
        for rm in cc.REGION_MASKS:
            rc = cc.region_cells(rm, n) + np.array(L) * n
            a = np.maximum(rc.min(0) - 1 - lo, 0)
            b = np.minimum(rc.max(0) + 2 - lo, size)
            if np.any(a >= b):
                continue
            dim = bin(rm).count("1")
            box = (dim, slice(a[0], b[0]), slice(a[1], b[1]), slice(a[2], b[2]))
            hits[box] += 1
            who[box] = [rm, *L]
    mask, base, rel = cc.cell_owners(cells, n)
    idx = tuple((cells - lo).T)
    dim = np.array([bin(m).count("1") for m in mask])
    assert np.all(hits[(dim, *idx)] == 1), "a cell is within one cell of two regions of its owner's kind"
    for higher in range(4):
        above = dim < higher
        assert np.all(hits[(np.full(len(cells), higher), *idx)][above] == 0)
    assert np.array_equal(who[(dim, *idx)], np.column_stack([mask, base]))


def test_owner_rejects_small_n():
    with pytest.raises(ValueError, match="n must be >= 4"):
        cc.cell_owners([[0, 0, 0]], 3)


def test_adjoining_cubes_share_their_face_edge_and_vertex_regions():
    """Cubes placed by a lattice colouring agree on every region they share (matching corners)."""
    seed = 11
    for L in [(0, 0, 0), (3, -2, 5)]:
        L = np.array(L)
        slots = {}
        for d in itertools.product((0, 1), repeat=3):
            corner = L + d
            cols = cc.lattice_colours(corner + np.array(list(itertools.product((0, 1), repeat=3)))[:, ::-1],
                                      seed)
            config = int(sum(int(c) << (i) for i, c in enumerate(cols)))
            for s, b in at.cube_slots(config):
                key = (int(cc.regions()[s][0]), tuple(corner + b))
                assert slots.setdefault(key, s) == s, f"region {key} differs between cubes"


def test_lattice_colouring_is_aperiodic():
    cols = cc.lattice_colours(np.array(list(itertools.product(range(96), range(6), range(6)))), 5)
    grid = cols.reshape(96, 6, 6)
    assert cc.period_of_colouring(grid, 48) is None
    assert 0.4 < grid.mean() < 0.6
    # The detector does find a period when there is one (the periodic tile's case).
    assert cc.period_of_colouring(np.tile(grid[:7], (12, 1, 1)), 48) == 7


# ----------------------------------------------------------------------------- seeds and metric
def test_seeds_depend_only_on_their_key():
    keys = np.array([5, 9, 5], dtype=np.uint64)
    s = cell_seeds([[0, 0, 0], [1, 0, 0], [7, 7, 7]], keys, SeedParams(seeds_per_cell=(1, 3)))
    a = s.offset[s.cell[:, 0] == 0]
    b = s.offset[s.cell[:, 0] == 7]
    assert np.array_equal(a, b) and len(a) >= 1
    assert np.all((s.offset >= 0) & (s.offset < 1))
    # g_k in [1, 4]: the eigenvalues of M_k are coefficients / g_k.
    m = s.metric
    M = np.array([[[r[0], r[3], r[4]], [r[3], r[1], r[5]], [r[4], r[5], r[2]]] for r in m])
    ev = np.linalg.eigvalsh(M)
    assert np.all(ev > 1 / 4 - 1e-9) and np.all(ev <= 1 + 1e-9)


def test_anisotropic_distance_is_the_papers_ellipsoid():
    s = cell_seeds([[0, 0, 0]], np.array([1], np.uint64),
                   SeedParams(alpha=(5.0, 5.0), beta=(1.0, 1.0), gamma=(1.0, 1.0), g_max=1.0))
    M = np.array([[s.metric[0, 0], s.metric[0, 3], s.metric[0, 4]],
                  [s.metric[0, 3], s.metric[0, 1], s.metric[0, 5]],
                  [s.metric[0, 4], s.metric[0, 5], s.metric[0, 2]]])
    w, vecs = np.linalg.eigh(M)
    assert np.allclose(w, [1, 1, 5])
    x = vecs[:, 2]   # the local frame's x axis (alpha = 5)
    p = s.position[0] + 0.3 * x
    assert np.isclose(anisotropic_distance(s, 0, p[None])[0], 5 * 0.09)


# ----------------------------------------------------------------------------- Voronoi, seamlessness
def _global_uid_labels(params, colour_seed, lo_cube, hi_cube):
    n, V = params.n, params.voxels_per_cell
    rng = [range(a * n - 2, b * n + 2) for a, b in zip(lo_cube, hi_cube)]
    cells = np.array(list(itertools.product(*rng)))
    m, base, rel = cc.cell_owners(cells, n)
    codes = cc.owner_colour_codes(m, base, lambda p: cc.lattice_colours(p, colour_seed))
    seeds = cell_seeds(cells, cc.cell_keys(m, codes, rel, params.seed), params.seeds)
    idx = CellIndex(seeds, cells.min(0), cells.max(0) - cells.min(0) + 1)
    g0 = np.array(lo_cube) * n * V
    labels = voronoi_labels(idx, g0, (np.array(hi_cube) - lo_cube) * n * V, V)
    return idx.seeds.uid[labels], g0


@pytest.mark.parametrize("colour_seed", [1])
def test_assembled_tiles_partition_space_like_the_global_diagram(colour_seed):
    """Rock volumes of all regions of a 2x2x1 block of corner cubes: no gap, no duplicate, and the
    same rocks as a Voronoi diagram of the whole block (rocks straddling cube faces included)."""
    params = SMALL
    n, V = params.n, params.voxels_per_cell
    lo_cube, hi_cube = np.array([0, 0, 0]), np.array([2, 2, 1])
    ref, g0 = _global_uid_labels(params, colour_seed, lo_cube, hi_cube)
    claims = np.zeros(ref.shape, np.int32)
    got = np.zeros(ref.shape, np.uint64)
    colour_of = lambda p: cc.lattice_colours(p, colour_seed)  # noqa: E731
    straddling = 0
    for L in itertools.product(*(range(a, b + 1) for a, b in zip(lo_cube, hi_cube))):
        L = np.array(L)
        for mask in cc.REGION_MASKS:
            code = int(cc.owner_colour_codes(np.array([mask]), L[None], colour_of)[0])
            index, rg0, labels, own = at.region_labels(mask, code, params)
            ii = np.argwhere((labels >= 0) & own[np.maximum(labels, 0)])
            gv = ii + rg0 + L * n * V - g0
            inside = np.all((gv >= 0) & (gv < ref.shape), axis=1)
            lab = labels[tuple(ii.T)]
            for k in np.unique(lab):
                cubes = np.unique(np.floor_divide(gv[lab == k], n * V), axis=0)
                straddling += len(cubes) > 1
            gv, lab = gv[inside], lab[inside]
            np.add.at(claims, tuple(gv.T), 1)
            got[tuple(gv.T)] = index.seeds.uid[lab]
    assert np.all(claims == 1), f"gaps: {(claims == 0).sum()}, duplicates: {(claims > 1).sum()}"
    assert np.array_equal(got, ref)
    assert straddling > 10   # rocks do cross cube faces


# ----------------------------------------------------------------------------- contacts, erosion
def test_contact_points_by_bisection_are_equidistant():
    s = cell_seeds(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 1]]), np.arange(3, dtype=np.uint64) + 40,
                   SeedParams(alpha=(0.5, 3.0), g_max=4.0))
    pairs = np.array([[0, 1], [0, 2], [1, 2]])
    c = bisect_contacts(s, pairs)
    di = anisotropic_distance(s, pairs[:, 0], c)
    dj = anisotropic_distance(s, pairs[:, 1], c)
    assert np.allclose(di, dj, rtol=1e-9, atol=1e-12)
    # On the segment, and at the analytic root t = sqrt(q_j) / (sqrt(q_i) + sqrt(q_j)).
    pi, pj = s.position[pairs[:, 0]], s.position[pairs[:, 1]]
    qi = anisotropic_distance(s, pairs[:, 0], pj)
    qj = anisotropic_distance(s, pairs[:, 1], pi)
    t = np.sqrt(qj) / (np.sqrt(qi) + np.sqrt(qj))
    assert np.allclose(c, pi + t[:, None] * (pj - pi), atol=1e-12)


def test_damping_function_of_the_paper():
    r = np.array([0.0, 0.1, 0.2, 0.3, 0.5, 1.0])
    assert np.allclose(damping_piecewise(r, 0.1, 0.3), [0, 0, 0.5, 1, 1, 1])


def test_erosion_spares_contact_points_and_rounds_corners():
    labels = np.full((20, 12, 12), -1, np.int32)
    labels[2:10, 2:10, 2:10] = 0
    labels[10:18, 2:10, 2:10] = 1
    pairs = adjacent_label_pairs(labels)
    assert pairs.tolist() == [[0, 1]]
    c = np.array([[10 / 10, 6 / 10, 6 / 10]])   # middle of the shared face (V = 10)
    omega = damping_field(labels, (0, 0, 0), 10, 2, pairs, c, 0.15, 0.4)
    rho = erode(labels, np.array([True, True]), omega, 3, 0.5)
    assert rho[9, 5, 5] == 1.0 and rho[10, 6, 6] == 1.0     # within a of the contact: intact
    assert rho[2, 2, 2] < rho[2, 6, 6] < 1.0                # a corner loses more than a face
    assert np.all(rho[labels < 0] == 0)


# ----------------------------------------------------------------------------- meshes
@pytest.fixture(scope="module")
def cube_rocks():
    """Rocks of the 27 regions of one corner cube, in cube coordinates (cells)."""
    params = TileParams(n=4, voxels_per_cell=8, seed=5, erosion=ErosionParams(steps=8))
    rocks = []
    for slot, base in at.cube_slots(0b10110010):
        mask, code = cc.regions()[slot]
        for r in at.build_region(mask, code, params, slot):
            r["vertices"] = r["vertices"] + base * params.n
            r["seed"] = r["seed"] + base * params.n
            rocks.append(r)
    return params, rocks


def test_every_rock_is_a_closed_manifold(cube_rocks):
    import trimesh
    params, rocks = cube_rocks
    assert len(rocks) > 100
    for r in rocks:
        m = trimesh.Trimesh(r["vertices"], r["faces"], process=False)
        assert m.is_watertight and m.is_winding_consistent and m.volume > 0
        assert len(m.split(only_watertight=False)) == 1
        assert closed_oriented(r["faces"])
        assert np.allclose(np.linalg.norm(r["normals"], axis=1), 1, atol=1e-4)
    bad = rocks[0]["faces"][1:]
    assert not closed_oriented(bad)
    assert not trimesh.Trimesh(rocks[0]["vertices"], bad, process=False).is_watertight


def test_closed_oriented_agrees_with_trimesh_on_broken_meshes(cube_rocks):
    """closed_oriented is trimesh's ``is_watertight and is_winding_consistent`` on rock
    meshes broken five ways: a face removed, one flipped, one repeated, a fin of two
    opposite faces on an edge (four faces there), and a degenerate face."""
    import trimesh
    _, rocks = cube_rocks
    rng = np.random.default_rng(5)
    seen = {True: 0, False: 0}
    for r in rocks[:40]:
        f = r["faces"]
        i = int(rng.integers(len(f)))
        broken = [f, np.delete(f, i, axis=0), np.concatenate([f[:i], f[i:i + 1, ::-1], f[i + 1:]]),
                  np.concatenate([f, f[i:i + 1]]), np.concatenate([f, f[i:i + 1], f[i:i + 1, ::-1]])]
        for g in broken:
            m = trimesh.Trimesh(r["vertices"], g, process=False)
            expected = bool(m.is_watertight and m.is_winding_consistent)
            assert closed_oriented(g) == expected
            seen[expected] += 1
        degenerate = f.copy()
        degenerate[i, 0] = degenerate[i, 1]
        assert not closed_oriented(degenerate)
    assert seen[True] == 40 and seen[False] == 160


def test_rocks_do_not_interpenetrate(cube_rocks):
    """Vertices of a rock lie outside its neighbours but for a contact tolerance (0.25 voxel)."""
    import trimesh
    params, rocks = cube_rocks
    tol = 0.25 / params.voxels_per_cell
    seeds = np.array([r["seed"] for r in rocks])
    checked, inside_total, deepest = 0, 0, 0.0
    for i in range(0, len(rocks), 2):
        mesh = trimesh.Trimesh(rocks[i]["vertices"], rocks[i]["faces"], process=False)
        near = np.nonzero(np.linalg.norm(seeds - seeds[i], axis=1) < 1.5)[0]
        for j in near[near != i]:
            v = rocks[j]["vertices"]
            inside = mesh.contains(v)                   # Embree ray queries
            if inside.any():
                _, depth, _ = trimesh.proximity.closest_point(mesh, v[inside])
                deepest = max(deepest, float(depth.max()))
                inside_total += int(inside.sum())
            checked += 1
    assert checked > 100
    assert deepest <= tol, f"a rock enters its neighbour by {deepest * params.voxels_per_cell:.3f} voxel"


def test_rocks_touch_at_contacts(cube_rocks):
    """Erosion is damped at contact points: many neighbours stay within a voxel of each other."""
    from scipy.spatial import cKDTree
    params, rocks = cube_rocks
    trees = [cKDTree(r["vertices"]) for r in rocks]
    seeds = np.array([r["seed"] for r in rocks])
    touching = pairs = 0
    for i in range(len(rocks)):
        for j in np.nonzero(np.linalg.norm(seeds - seeds[i], axis=1) < 1.2)[0]:
            if j <= i:
                continue
            pairs += 1
            d, _ = trees[i].query(rocks[j]["vertices"], k=1)
            touching += d.min() < 1.0 / params.voxels_per_cell
    assert pairs > 50 and touching > 0.5 * pairs


def test_region_build_is_deterministic():
    a = at.build_region(0, 201, SMALL, 0)
    b = at.build_region(0, 201, SMALL, 0)
    assert len(a) == len(b) > 0
    for x, y in zip(a, b):
        assert np.array_equal(x["vertices"], y["vertices"]) and np.array_equal(x["faces"], y["faces"])
        assert x["uid"] == y["uid"]
    c = at.build_region(0, 201, TileParams(**{**SMALL.__dict__, "seed": 4}), 0)
    assert not np.array_equal(np.array([r["seed"] for r in a[:5]]), np.array([r["seed"] for r in c[:5]]))


def test_cache_key_follows_parameters_and_seed():
    assert cache_key(SMALL) == cache_key(TileParams(**SMALL.__dict__))
    assert cache_key(SMALL) != cache_key(TileParams(**{**SMALL.__dict__, "seed": 99}))
    assert cache_key(SMALL) != cache_key(TileParams(**{**SMALL.__dict__, "n": 5}))


# ----------------------------------------------------------------------------- periodic tile
def test_periodic_tile_is_a_closed_periodic_packing():
    import trimesh
    params = TileParams(tiling="periodic", poisson_radius=0.14, periodic_voxels=40, seed=2,
                        erosion=ErosionParams(steps=6))
    pts = poisson_points(0.14, 2)
    d = pts[:, None] - pts[None]
    d -= np.round(d)
    dist = np.linalg.norm(d, axis=-1) + np.eye(len(pts)) * 9
    assert dist.min() >= 0.28 - 1e-12 and len(pts) > 10
    store = build_periodic_tile(params)
    again = build_periodic_tile(params)
    assert np.array_equal(store.vertices, again.vertices)
    assert len(store) == len(pts)
    for i in range(len(store)):
        v, f, _ = store.rock(i)
        m = trimesh.Trimesh(v, f, process=False)
        assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    # A rock crossing the tile's faces is stored whole, once: some rocks stick out of [0, P)^3.
    P = store.meta["cells_per_period"]
    out = [np.any((store.rock(i)[0] < 0) | (store.rock(i)[0] > P)) for i in range(len(store))]
    assert any(out)


# ----------------------------------------------------------------------------- coarse meshes
def test_a_rock_smaller_than_the_mesh_step_is_meshed_finer():
    """mesh_step 2 or 3 once raised scikit-image's "No surface found" on a rock whose
    voxels above 1/2 all fall between the step's samples (n = 6, seed 9, smoothing 1.5:
    68 rocks at step 2, 205 at step 3). Such a rock is meshed at the next finer step
    that sees it: a coarse step trades triangles, it does not take rocks out of a pile."""
    field = np.zeros((12, 12, 12), np.float32)
    field[5, 5, 5] = 0.9
    for axis in range(3):
        for d in (-1, 1):
            idx = [5, 5, 5]
            idx[axis] += d
            field[tuple(idx)] = 0.3
    assert field[::2, ::2, ::2].max() == 0 and field[::3, ::3, ::3].max() == 0
    fine = mesh_rock(field.copy(), (0, 0, 0), 8, 1)
    assert fine is not None and closed_oriented(fine[1])
    for step in (2, 3):
        mesh = mesh_rock(field.copy(), (0, 0, 0), 8, step)
        assert mesh is not None
        for a, b in zip(mesh, fine):
            assert np.array_equal(a, b)


def test_coarse_steps_keep_every_rock_of_a_region():
    """The region that first failed at step 2 (n = 6, seed 9, smoothing 1.5): at steps 2
    and 3 it builds, with a closed mesh for every rock of step 1, and fewer triangles."""
    base = dict(n=6, seed=9, erosion=ErosionParams(smoothing=1.5))
    mask, code = cc.regions()[20]
    rocks = {s: at.build_region(mask, code, TileParams(**base, mesh_step=s), 20) for s in (1, 2, 3)}
    uids = [r["uid"] for r in rocks[1]]
    assert len(uids) > 10
    tris = {s: sum(len(r["faces"]) for r in rocks[s]) for s in rocks}
    for s in (2, 3):
        assert [r["uid"] for r in rocks[s]] == uids
        assert all(closed_oriented(r["faces"]) for r in rocks[s])
    assert tris[3] < tris[2] < tris[1] / 2


def test_a_script_without_a_main_guard_gets_its_tiles_and_a_warning_not_a_hang(tmp_path):
    """Worker processes import the main script again (multiprocessing's rule); an unguarded
    script used to hang for ever (the forkserver preloaded it and waited on itself; then
    multiprocessing.Pool restarted the failing workers without end). Now the tiles are
    built in the script's own process, bitwise as the workers build them, with one warning
    naming the remedy."""
    import subprocess
    import sys
    script = tmp_path / "unguarded.py"
    script.write_text(
        "import numpy as np\n"
        "from arches_render.generators.rocks.aperiodic_tiles import build_aperiodic_tiles\n"
        "from arches_render.generators.rocks.seed_points import SeedParams\n"
        "from arches_render.generators.rocks.tile_params import ErosionParams, TileParams\n"
        "p = TileParams(n=4, voxels_per_cell=6, seed=3, seeds=SeedParams(g_max=4.0, alpha=(0.6, 1.6)),\n"
        "               erosion=ErosionParams(steps=6))\n"
        "a = build_aperiodic_tiles(p, workers=3)\n"  # processes (threads up to 2)
        "b = build_aperiodic_tiles(p, workers=1)\n"
        "keys = ('vertices', 'normals', 'faces', 'vstart', 'seed', 'radius', 'uid', 'slot', 'anchors')\n"
        "same = all(np.array_equal(getattr(a, k), getattr(b, k)) for k in keys)\n"
        "print('built', len(a), same)\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1].endswith(" True"), out.stdout
    remedy = "its top level is not guarded: guard it with 'if __name__ == \"__main__\":'"
    assert remedy in out.stderr, out.stderr[-2000:]


def test_an_unguarded_script_building_tiles_through_the_cache_does_not_wait_on_itself(tmp_path):
    """The cache's builder holds the entry's lock while its workers run; a worker that
    re-runs an unguarded script asks for the same entry. It must not wait for that lock
    (the parent waits for it: both hung for ever, found rendering a rock pile scene from
    a script); it stops, and the parent builds the tiles itself, with the warning."""
    import subprocess
    import sys
    script = tmp_path / "unguarded_cache.py"
    script.write_text(
        "import sys\n"
        "from arches_render.generators.rocks import tile_cache\n"
        "from arches_render.generators.rocks.seed_points import SeedParams\n"
        "from arches_render.generators.rocks.tile_params import ErosionParams, TileParams\n"
        "p = TileParams(n=4, voxels_per_cell=6, seed=5, seeds=SeedParams(g_max=4.0, alpha=(0.6, 1.6)),\n"
        "               erosion=ErosionParams(steps=6))\n"
        "store, where = tile_cache.load_or_build(p, folder=sys.argv[1], workers=3)\n"  # processes
        "print('tiles', len(store), where)\n")
    out = subprocess.run([sys.executable, str(script), str(tmp_path / "cache")], capture_output=True, text=True,
                         timeout=240, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1].endswith(" built"), out.stdout
    assert "guard it with 'if __name__ == \"__main__\":'" in out.stderr, out.stderr[-2000:]
    assert "would wait for the parent's cache lock" in out.stderr


def test_tiles_built_in_threads_are_the_bits_built_inline():
    """Up to ``THREAD_WORKERS`` workers are threads of this process (no process start, no
    kernels loaded again); the regions they build are the inline build's, bit for bit, in
    the same order, and this process's numba keeps its own thread count."""
    import numba

    from arches_render.generators.rocks.aperiodic_tiles import THREAD_WORKERS, build_aperiodic_tiles
    from arches_render.generators.rocks.seed_points import SeedParams
    from arches_render.generators.rocks.tile_params import ErosionParams
    assert THREAD_WORKERS >= 2 and at._threadsafe_kernels()
    p = TileParams(n=4, voxels_per_cell=6, seed=3, seeds=SeedParams(g_max=4.0, alpha=(0.6, 1.6)),
                   erosion=ErosionParams(steps=6))
    threads = numba.get_num_threads()
    done = []
    a = build_aperiodic_tiles(p, workers=2, progress=lambda d, n: done.append((d, n)))
    b = build_aperiodic_tiles(p, workers=1)
    assert numba.get_num_threads() == threads
    assert done[-1][0] == done[-1][1] == 318 and len(done) == 8
    assert a.meta["worker_cpu_seconds"] == 0.0 and len(a) > 100
    for k in ("vertices", "normals", "faces", "vstart", "seed", "radius", "uid", "slot", "anchors"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=k)
