"""Rock piles in scenes: tiling of space, the three support kinds, flat meshes, the tile cache,
``[[rock_piles]]`` validation and the ``arches-render rocks`` command."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from helpers import REPO, variant

from arches_render.generators.rocks import instancing as ins
from arches_render.generators.rocks import tile_cache
from arches_render.generators.rocks.rock_store import RockStore
from arches_render.generators.rocks.tile_params import ErosionParams, TileParams

TINY = TileParams(n=4, voxels_per_cell=4, seed=1, erosion=ErosionParams(steps=2, smoothing=0.6), anchors=16)
PERIODIC = TileParams(tiling="periodic", poisson_radius=0.14, periodic_voxels=40, seed=2,
                      erosion=ErosionParams(steps=4))


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    d = tmp_path_factory.mktemp("rock_cache")
    old = os.environ.get("ARCHES_RENDER_CACHE")
    os.environ["ARCHES_RENDER_CACHE"] = str(d)
    yield d
    if old is None:
        os.environ.pop("ARCHES_RENDER_CACHE")
    else:
        os.environ["ARCHES_RENDER_CACHE"] = old


@pytest.fixture(scope="module")
def aperiodic(cache):
    store, source = tile_cache.load_or_build(TINY, cache, workers=2)
    return store


@pytest.fixture(scope="module")
def periodic(cache):
    return tile_cache.load_or_build(PERIODIC, cache)[0]


# ----------------------------------------------------------------------------- tile set and cache
def test_tile_set_counts_and_cache_round_trip(aperiodic, cache):
    # One rock per cell of the 318 regions, less the few eroded away: 16 + 96 + 384 + 2048 cells.
    assert 0.9 * 2544 <= len(aperiodic) <= 2544
    assert len(aperiodic.slot_start) == 319
    tile_cache.clear_memory()
    again, source = tile_cache.load_or_build(TINY, cache)
    assert source == "disk"
    for k in ("vertices", "faces", "seed", "anchors", "uid"):
        assert np.array_equal(getattr(again, k), getattr(aperiodic, k))
    assert tile_cache.load_or_build(TINY, cache)[1] == "memory"


def test_damaged_cache_file_is_rebuilt(cache, periodic):
    path = cache / f"rocks-{tile_cache.cache_key(PERIODIC)}.npz"
    assert path.is_file()
    path.write_bytes(b"not an npz")
    tile_cache.clear_memory()
    store, source = tile_cache.load_or_build(PERIODIC, cache)
    assert source == "built" and np.array_equal(store.vertices, periodic.vertices)
    assert isinstance(RockStore.load(path), RockStore)


def test_tiles_are_deterministic_for_a_seed(tmp_path, periodic):
    a = tile_cache.build_tiles(PERIODIC)
    assert np.array_equal(a.vertices, periodic.vertices) and np.array_equal(a.faces, periodic.faces)


# ----------------------------------------------------------------------------- tiling of space
@pytest.mark.parametrize("which", ["aperiodic", "periodic"])
def test_candidates_cover_the_extent_once(which, aperiodic, periodic):
    store = aperiodic if which == "aperiodic" else periodic
    lo, hi = np.array([-3.0, -2.0, -5.0]), np.array([9.0, 7.0, 4.0])
    ids, offs = ins.candidate_rocks(store, lo, hi, 5)
    p = store.seed[ids] + offs
    assert np.all((p >= lo) & (p < hi))
    assert len(np.unique(np.round(p, 6), axis=0)) == len(p)          # no rock twice
    volume = np.prod(hi - lo)
    assert 0.85 * volume < len(ids) < 1.1 * volume                   # about one rock per cell


def test_different_colourings_give_different_piles(aperiodic):
    lo, hi = np.zeros(3), np.full(3, 12.0)
    a = ins.candidate_rocks(aperiodic, lo, hi, 1)[0]
    b = ins.candidate_rocks(aperiodic, lo, hi, 2)[0]
    assert not np.array_equal(np.sort(a), np.sort(b))


# ----------------------------------------------------------------------------- supports
def _sphere_supports(radius):
    variant()
    import trimesh

    from arches_render import field as F
    c = np.array([0.3, -0.2, 0.1])
    field = ins.FieldSupport(F.Sphere(c, radius))
    shape = ins.ShapeSupport("sphere", c, radius=radius)
    mesh = ins.MeshSupport(trimesh.creation.icosphere(subdivisions=5, radius=radius).apply_translation(c))
    return c, field, shape, mesh


def test_three_support_kinds_select_the_same_rocks(aperiodic):
    radius, cell = 3.0, 0.5
    c, field, shape, mesh = _sphere_supports(radius)
    lo, hi = (c - radius - 1) / cell, (c + radius + 1) / cell
    ids, offs = ins.candidate_rocks(aperiodic, lo, hi, 3)
    keeps = {}
    for name, sup in (("field", field), ("shape", shape), ("mesh", mesh)):
        keeps[name], stats = ins.select_rocks(aperiodic, ids, offs, sup, cell, np.zeros(3), 0.5)
        assert stats["instanced"] > 100
    assert np.mean(keeps["field"] == keeps["shape"]) > 0.99
    assert np.mean(keeps["mesh"] == keeps["shape"]) > 0.97


def test_selected_rocks_neither_float_nor_sink_too_deep(aperiodic):
    radius, cell = 4.0, 0.4
    c, _, shape, _ = _sphere_supports(radius)
    lo, hi = (c - radius - 1) / cell, (c + radius + 1) / cell
    ids, offs = ins.candidate_rocks(aperiodic, lo, hi, 4)
    keep, stats = ins.select_rocks(aperiodic, ids, offs, shape, cell, np.zeros(3), 0.6)
    r_max = stats["r_max"]
    seeds = (aperiodic.seed[ids] + offs) * cell
    depth = shape.depth(seeds)
    assert np.all(depth[keep] <= 2 * r_max)                     # the paper's 2 R_max rule
    assert np.any(depth[~keep] > 2 * r_max)                      # ... which removed deep rocks
    K = aperiodic.n_anchors
    anchors = (aperiodic.anchors.reshape(-1, K, 3)[ids] + offs[:, None]) * cell
    frac = (shape.inside(anchors.reshape(-1, 3)).reshape(-1, K).sum(1) + shape.inside(seeds)) / (K + 1)
    assert np.all(frac[keep] >= 0.6)                              # no floating rock
    shallow = (depth > 0.5 * r_max) & (depth < 1.5 * r_max)
    assert np.all(keep[shallow])                                  # the shell is complete


def test_open_mesh_is_rejected():
    import trimesh
    m = trimesh.creation.icosphere()
    m.faces = m.faces[1:]
    with pytest.raises(ValueError, match="closed"):
        ins.MeshSupport(m)


# ----------------------------------------------------------------------------- buffers and meshes
def test_instance_buffers_bake_transforms(periodic):
    shape = ins.ShapeSupport("box", [0, 0, 0], size=[6, 6, 2])
    ids, offs = ins.candidate_rocks(periodic, np.full(3, -8.0), np.full(3, 8.0), 0)
    keep, _ = ins.select_rocks(periodic, ids, offs, shape, 0.5, np.array([1.0, 2.0, 3.0]))
    inst = ins.RockInstances(periodic, ids[keep], offs[keep], 0.5, np.array([1.0, 2.0, 3.0]))
    bufs = ins.instance_buffers(inst, max_triangles=20_000)
    assert len(bufs) > 1 and sum(b["rocks"] for b in bufs) == len(inst)
    nv = periodic.vstart[inst.ids + 1] - periodic.vstart[inst.ids]
    assert sum(len(b["positions"]) for b in bufs) == nv.sum()
    for b in bufs:
        assert b["faces"].max() < len(b["positions"]) and b["faces"].dtype == np.uint32
    # One rock, found by its first vertex: world = origin + (local + offset) * cell.
    k = 0
    v, f, _ = periodic.rock(inst.ids[k])
    want = np.array([1.0, 2.0, 3.0]) + (v[0] + inst.offsets[k]) * 0.5
    allpos = np.concatenate([b["positions"] for b in bufs])
    assert np.min(np.linalg.norm(allpos - want, axis=1)) < 1e-5


def _scene_text(pile, extra=""):
    return f"""
[camera]
origin = [0.0, -9.0, 3.0]
target = [0.0, 0.0, 0.0]
fov = 40.0
[[lights]]
type = "constant"
radiance = 1.0
{extra}
[[rock_piles]]
{pile}
"""


def test_scene_meshes_carry_object_space_texture_coordinates(tmp_path, cache):
    variant()
    import mitsuba as mi

    from arches_render.render.renderer import build_scene, render_image
    from arches_render.scene import load_scene
    p = tmp_path / "pile.toml"
    p.write_text(_scene_text('support = { shape = "sphere", center = [0.0, 0.0, 0.0], radius = 1.5 }\n'
                             'rock_size = 0.35\ntiling = "periodic"\npoisson_radius = 0.14\nseed = 2\n'
                             'erosion = { steps = 4 }\npreset = "basalt"'))
    desc = load_scene(p)
    assert desc.materials["rock_pile0"]["space"] == "object"
    scene = build_scene(desc, width=48, height=32)
    shapes = [s for s in scene.shapes() if s.id().startswith("rock_pile0")]
    assert len(shapes) == len(desc.rock_piles[0].buffers())
    assert shapes and all(s.has_attribute("vertex_objp") for s in shapes)
    # Each mesh carries its buffer's object-space positions, not the placeholder it was declared with.
    for shape, buffer in zip(shapes, desc.rock_piles[0].buffers()):
        np.testing.assert_array_equal(mi.traverse(shape)["vertex_objp"].numpy(), buffer["objp"].ravel())
        assert np.ptp(buffer["objp"]) > 0
    assert desc.rock_piles[0].stats["instanced"] > 20
    img = render_image(scene, 4)
    assert img[12:20, 20:28].mean() > 0.01              # rocks in front of the camera, lit
    assert isinstance(scene, mi.Scene)


@pytest.mark.parametrize("pile, key, msg", [
    ('support = "nowhere"\nrock_size = 0.3', "support", "unknown node"),
    ('support = "field"\nrock_size = 0.3', "support", "no [field]"),
    ('support = { shape = "cone", center = [0, 0, 0] }\nrock_size = 0.3', "shape", "must be one of"),
    ('support = { mesh = "nope.ply" }\nrock_size = 0.3', "mesh", "no such file"),
    ('support = { shape = "sphere", center = [0, 0, 0] }\nrock_size = -1.0', "rock_size", "must be"),
    ('support = { shape = "sphere", center = [0, 0, 0] }\nrock_size = 0.3\nn = 3', "n", "[4, 12]"),
    ('support = { shape = "sphere", center = [0, 0, 0] }\nrock_size = 0.3\nseeds_per_cell = [3, 1]',
     "seeds_per_cell", "min <= max"),
    ('support = { shape = "sphere", center = [0, 0, 0] }\nrock_size = 0.3\nerosion = { rate = 2.0 }',
     "erosion.rate", "(0, 1]"),
    ('support = { shape = "sphere", center = [0, 0, 0] }\nrock_size = 0.3\nvoxels_per_cell = 7',
     "voxels_per_cell", "even"),
    ('support = { shape = "sphere", center = [0, 0, 0] }\nrock_size = 0.3\ncolour = 1', "colour", "unknown key"),
    ('support = { shape = "sphere", center = [0, 0, 0] }\nrock_size = 0.001', "rock_size", "too small"),
    ('support = { node = { type = "plane", normal = [0, 0, 1] } }\nrock_size = 0.3', "extent", "unbounded"),
    ('support = { shape = "sphere", center = [0, 0, 0] }\nrock_size = 0.3\nmaterial = "x"\npreset = "basalt"',
     "preset", "either"),
    ('support = { shape = "sphere", center = [0, 0, 0] }\nrock_size = 0.3\nextent = [0, 0, 0, 1, -1, 1]',
     "extent", "x1 > x0"),
])
def test_bad_rock_pile_tables_name_key_and_range(tmp_path, pile, key, msg):
    from arches_render.scene import SceneError, load_scene
    p = tmp_path / "bad.toml"
    p.write_text(_scene_text(pile))
    with pytest.raises(SceneError) as err:
        load_scene(p)
    text = str(err.value)
    assert "bad.toml" in text and key in text and msg in text, text


def test_open_support_mesh_file_is_a_scene_error(tmp_path):
    import trimesh

    from arches_render.scene import SceneError, load_scene
    m = trimesh.creation.icosphere()
    m.faces = m.faces[1:]
    m.export(tmp_path / "open.ply")
    p = tmp_path / "s.toml"
    p.write_text(_scene_text('support = { mesh = "open.ply" }\nrock_size = 0.3'))
    with pytest.raises(SceneError, match="closed"):
        load_scene(p)


# ----------------------------------------------------------------------------- CLI
def _cli(*args, env=None):
    return subprocess.run([sys.executable, "-m", "arches_render.cli", *args], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=600)


def test_rocks_command_builds_then_reuses_the_cache(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(_scene_text('support = { shape = "box", center = [0, 0, 0], size = [2, 2, 1] }\n'
                                 'rock_size = 0.3\ntiling = "periodic"\npoisson_radius = 0.15\nseed = 8\n'
                                 'erosion = { steps = 3 }\npreset = "basalt"'))
    env = dict(os.environ, ARCHES_RENDER_CACHE=str(tmp_path / ".cache"))  # a new cache folder
    out = tmp_path / "tiles.npz"
    r = _cli("rocks", str(scene), "-o", str(out), "-q", env=env)
    assert r.returncode == 0, r.stderr
    assert "built" in r.stdout and out.is_file()
    store = RockStore.load(out)
    assert len(store) > 10 and store.meta["tiling"] == "periodic"
    assert (tmp_path / ".cache" / ".gitignore").is_file()
    r2 = _cli("rocks", str(scene), "-o", str(tmp_path / "again.npz"), "-q", env=env)
    assert r2.returncode == 0 and "from cache" in r2.stdout
    assert np.array_equal(RockStore.load(tmp_path / "again.npz").vertices, store.vertices)

    bad = _cli("rocks", str(scene), "-o", str(tmp_path / "tiles.txt"), env=env)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and ".npz" in bad.stderr
    bad = _cli("rocks", str(scene), "-o", str(out), "--pile", "3", env=env)
    assert bad.returncode == 2 and "--pile" in bad.stderr
    bad = _cli("rocks", str(REPO / "scenes" / "default.toml"), "-o", str(out), env=env)
    assert bad.returncode == 2 and "rock_piles" in bad.stderr and "Traceback" not in bad.stderr
