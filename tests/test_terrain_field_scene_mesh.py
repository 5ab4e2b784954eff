"""Terrain field nodes in scene files (.npz primitive arrays, key errors) and the
banded polygonizer (mesh equal to the dense marching-cubes mesh of the same grid)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import variant

variant()

from arches_render.field import Union, evaluate  # noqa: E402
from arches_render.generators.terrain import geology as G  # noqa: E402
from arches_render.generators.terrain.erosion_node import Erosion  # noqa: E402
from arches_render.generators.terrain.implicit_heightfield import ImplicitHeightfield  # noqa: E402
from arches_render.generators.terrain.operators import LocalWarp, Sum  # noqa: E402
from arches_render.generators.terrain.skeletal_files import load_npz, save_npz  # noqa: E402
from arches_render.generators.terrain.skeletal_set import SkeletalSet  # noqa: E402
from arches_render.generators.terrain.banded import BandStats, polygonize_banded, polygonize_dense  # noqa: E402
from arches_render.scene import SceneError, load_scene  # noqa: E402

HEAD = """
[camera]
origin = [50.0, -80.0, 60.0]
target = [50.0, 50.0, 0.0]
[[lights]]
type = "constant"
[field]
root = "world"
"""

WORLD = """
[nodes.world]
type = "sum"
children = ["eroded", "caves"]

[nodes.eroded]
type = "erosion"
child = "terrain"
field = { type = "skeletal_set", file = "ero.npz", noise = { amplitude = 0.2, wavelength = 3.0, seed = 1 } }
resistance = "rho"

[nodes.caves]
type = "skeletal_set"
file = "caves.npz"
noise = { amplitude = 0.15, wavelength = 2.0 }

[nodes.terrain]
type = "implicit_heightfield"
source = "file"
file = "dem.npy"
extent = [0.0, 0.0, 100.0, 100.0]
R = 8.0
amplification = { amplitude = 0.5, wavelength = 6.0, octaves = 2 }

[nodes.rho]
type = "resistance_fault"
child = { type = "resistance_blend", children = [
    { type = "resistance_turbulence", wavelength = 6.0, amplitude = 0.3 },
    { type = "resistance_strata", spacing = 5.0, R = 1.5, weight = -0.4 },
    { type = "resistance_plane", point = [0, 0, 2], normal = [0, 0, 1], R = 2.0, weight = 0.3 },
    { type = "resistance_skeleton", a = [50, 50, 0], R = 10.0, weight = 0.2 } ] }
point = [50.0, 50.0, 0.0]
normal = [1.0, 0.0, 0.0]
slip = [0.0, 0.0, 2.0]
width = 1.5
"""


def _arrays(seed=0):
    rng = np.random.default_rng(seed)
    x = np.linspace(0, 1, 33)
    X, Y = np.meshgrid(x, x)
    dem = 10.0 * np.sin(3 * X) * np.cos(2 * Y) + 5 * X
    ero = dict(a=rng.uniform([15, 15, -4], [45, 45, 8], (60, 3)), radius=rng.uniform(3, 6, 60),
               energy=rng.uniform(0.5, 3, 60))
    ca = rng.uniform([55, 55, -3], [80, 80, 3], (40, 3))
    caves = dict(a=ca, b=ca + rng.normal(0, 4, ca.shape), radius=np.full(40, 4.0), energy=np.full(40, -9.0),
                 core=np.full(40, 0.8), group=np.repeat(np.arange(20), 2))
    caves["b"][1::2] = caves["a"][1::2]
    return dem, ero, caves


def _python_tree(dem, ero, caves):
    terrain = ImplicitHeightfield(dem, (0, 0, 100, 100), R=8.0,
                                  amplification=dict(amplitude=0.5, wavelength=6.0, octaves=2))
    rho = G.Fault(G.Blend(G.Turbulence(6.0, 0.3), G.Strata(5.0, 1.5, -0.4),
                          G.StrataPlane([0, 0, 2], [0, 0, 1], 2.0, 0.3), G.LocalSkeleton([50, 50, 0], None, 10.0, 0.2)),
                  [50, 50, 0], [1, 0, 0], [0, 0, 2], 1.5)
    e = SkeletalSet(ero["a"], None, ero["radius"], ero["energy"], noise=dict(amplitude=0.2, wavelength=3.0, seed=1))
    c = SkeletalSet(caves["a"], caves["b"], caves["radius"], caves["energy"], caves["core"], group=caves["group"],
                    noise=dict(amplitude=0.15, wavelength=2.0))
    return Sum(Erosion(terrain, e, rho), c)


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("terrain_scene")
    dem, ero, caves = _arrays()
    np.save(d / "dem.npy", dem)
    save_npz(d / "ero.npz", **ero)
    save_npz(d / "caves.npz", **caves)
    (d / "world.toml").write_text(HEAD + WORLD)
    return d


def test_scene_round_trip_equals_python_tree(scene_dir):
    scene = load_scene(scene_dir / "world.toml")
    ref = _python_tree(*_arrays())
    p = np.random.default_rng(1).uniform([0, 0, -15], [100, 100, 15], (20000, 3))
    np.testing.assert_allclose(evaluate(scene.field, p), evaluate(ref, p), atol=1e-5)
    assert scene.field.lipschitz == pytest.approx(ref.lipschitz)
    back = load_npz(scene_dir / "caves.npz")
    np.testing.assert_array_equal(back["group"], _arrays()[2]["group"])


def test_inline_arrays_and_other_nodes(tmp_path):
    text = HEAD + """
[nodes.world]
type = "local_warp"
child = { type = "sum", children = ["hoodoo", "ground"] }
control = { type = "skeletal_set", a = [[30, 30, 5]], radius = 20.0 }
amplitude = 1.0
wavelength = 5.0

[nodes.ground]
type = "implicit_heightfield"
extent = [0, 0, 60, 60]
resolution = [17, 17]
amplitude = 4.0
wavelength = 30.0
R = 6.0
T = 4.0
bumps = { center = [[30, 30]], radius = [10.0], height = [5.0] }

[nodes.hoodoo]
type = "skeletal_set"
a = [[30, 30, 0], [30, 30, 8]]
b = [[30, 30, 8], [30, 30, 14]]
radius = [4.0, 5.0]
energy = 8.0
combine = "max"
"""
    (tmp_path / "s.toml").write_text(text)
    root = load_scene(tmp_path / "s.toml").field
    assert isinstance(root, LocalWarp)
    hoodoo = root.children[0].children[0]
    assert hoodoo.n == 2 and hoodoo.combine == "max"
    # Summed with the terrain (air value -T = -4) the hoodoo (energy 8) stands
    # above it: matter where 8 g(d/R) > 4, i.e. d < R sqrt(1 - 2^(-1/3)) = 0.454 R.
    f = evaluate(root, np.array([[30.0, 30.0, 12.0], [32.0, 30.0, 12.0], [33.0, 30.0, 12.0]]))
    assert f[0] > 0 and f[1] > 0 > f[2]


BAD = [
    ('type = "skeletal_set"\nfile = "missing.npz"', "nodes.world.file", "no such file"),
    ('type = "skeletal_set"\nfile = "wrong.npz"', "nodes.world.file", "missing array"),
    ('type = "skeletal_set"\na = [[0, 0, 0]]\nradius = -1.0', "nodes.world.a", "radius must be > 0"),
    ('type = "skeletal_set"\na = [[0, 0, 0]]\nradius = 1.0\nnoise = { amplitude = 0.9 }', "nodes.world.a",
     "amplitude"),
    ('type = "skeletal_set"\na = [[0, 0, 0]]\nradius = 1.0\nnoise = { amp = 0.1 }', "nodes.world.noise.amp",
     "unknown key"),
    ('type = "skeletal_set"\na = [[0, 0, 0]]\nradius = 1.0\ncombine = "avg"', "nodes.world.combine", "one of"),
    ('type = "implicit_heightfield"\nextent = [0, 0, 50, 50]\nresolution = [9, 9]\nR = 10.0\nT = 1.0',
     "nodes.world.T", "R/3"),
    ('type = "erosion"\nchild = { type = "sphere", center = [0, 0, 0], radius = 1.0 }\n'
     'field = { type = "skeletal_set", a = [[0, 0, 0]], radius = 1.0 }\n'
     'resistance = { type = "sphere", center = [0, 0, 0], radius = 1.0 }', "nodes.world", "geology node"),
    ('type = "resistance_strata"\nspacing = 2.0\nR = 3.0', "nodes.world", "spacing / 2"),
    ('type = "implicit_heightfield"\nextent = [0, 0, 50, 50]\nresolution = [9, 9]\n'
     'bumps = { center = [[1, 2]], radius = [0.0], height = [1.0] }', "nodes.world.bumps", "radius"),
    ('type = "resistance_fault"\nchild = { type = "resistance_constant", value = 0.5 }\npoint = [0, 0, 0]\n'
     'normal = [1, 0, 0]\nslip = [0, 0, 1]\nwidth = 0.0', "nodes.world.width", "> 0"),
]


@pytest.mark.parametrize("body,key,msg", BAD)
def test_bad_input_names_key(tmp_path, body, key, msg):
    np.savez(tmp_path / "wrong.npz", centres=np.zeros((2, 3)))
    (tmp_path / "bad.toml").write_text(HEAD + "[nodes.world]\n" + body + "\n")
    with pytest.raises(SceneError) as err:
        load_scene(tmp_path / "bad.toml")
    assert key in str(err.value) and msg in str(err.value)
    assert str(err.value).count("\n") == 0


# -- banded polygonization ------------------------------------------------------------------------
def test_banded_mesh_equals_dense_mesh(scene_dir):
    tree = load_scene(scene_dir / "world.toml").field
    stats = BandStats()
    voxel = 1.25
    mb = polygonize_banded(tree, voxel, stats=stats)
    md = polygonize_dense(tree, voxel)
    assert mb.vertices.shape == md.vertices.shape and len(mb.vertices) > 1000
    np.testing.assert_array_equal(mb.faces, md.faces)
    assert np.abs(mb.vertices - md.vertices).max() < 1e-4 * voxel
    np.testing.assert_allclose(mb.normals, md.normals, atol=1e-5)
    # The band is a fraction of the grid, and columns without primitives are direct.
    assert stats.evaluated + stats.direct < 0.7 * stats.voxels
    assert stats.direct > 0 and stats.evaluated > 0


def test_banded_handles_unions_and_plain_heightfields():
    from arches_render.field import Heightfield, Sphere
    x = np.linspace(0, 1, 17)
    X, Y = np.meshgrid(x, x)
    hf = Heightfield(4 * np.sin(3 * X) + 2 * Y, (0, 0, 40, 40))
    tree = Union(hf, Sphere([20, 20, 6], 4.0))
    stats = BandStats()
    mb = polygonize_banded(tree, 1.0, stats=stats)
    md = polygonize_dense(tree, 1.0)
    np.testing.assert_array_equal(mb.faces, md.faces)
    assert np.abs(mb.vertices - md.vertices).max() < 1e-4
    assert stats.band < 0.7 * stats.voxels


def test_banded_rejects_unbounded():
    from arches_render.field import Plane
    with pytest.raises(ValueError, match="bounded"):
        polygonize_banded(Plane(), 1.0)


def test_banded_clipped_tile_equals_dense(scene_dir):
    """A tree clipped to a tile by a box (as amplify meshes slabs) keeps the equality."""
    from arches_render.field import Box, Intersection
    # (a one-operand union around the root, as amplify writes single-feature trees)
    tree = Intersection(Union(load_scene(scene_dir / "world.toml").field), Box([40, 45, 0], [30, 35, 9], rounding=0.5))
    stats = BandStats()
    mb = polygonize_banded(tree, 1.25, stats=stats)
    md = polygonize_dense(tree, 1.25)
    np.testing.assert_array_equal(mb.faces, md.faces)
    assert np.abs(mb.vertices - md.vertices).max() < 1e-4
    np.testing.assert_allclose(mb.normals, md.normals, atol=1e-5)
    assert stats.direct > 0 and stats.evaluated < stats.voxels
