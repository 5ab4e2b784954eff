"""Rays the mesh region skips meet no mesh (arches_render/render/mesh_region.py).

The integrator masks off Mitsuba's query for rays that provably meet no mesh: a box
around the shapes inside the scene, and the far field's skirt (outside the tile less
its frame band, between its lowest and highest vertex). A region too small would drop
real hits (sky through the far field, light through its hills); these tests aim rays at
every kind of triangle and check the render is the same with and without the region.
"""

from __future__ import annotations

import numpy as np

from helpers import variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.render.mesh_region import MeshRegion, scene_mesh_region  # noqa: E402
from arches_render.render.renderer import build_scene, render_layers  # noqa: E402
from arches_render.scene import load_scene  # noqa: E402

SCENE = """
[scene]
name = "region"

[render]
resolution = [48, 27]
spp = 2
max_depth = 3

[cameras.low]
origin = [-150.0, -160.0, 112.0]
target = [200.0, 150.0, 100.0]
fov = 60.0

[[lights]]
type = "sunsky"
elevation = 12.0
azimuth = 40.0

[materials.ground]
type = "diffuse"
color = [0.3, 0.4, 0.2]

[materials.water]
type = "diffuse"
color = [0.1, 0.2, 0.3]

[field]
root = "world"
material = "ground"

[[far_field]]
node = "terrain"
material = "ground"
sea_level = 96.0
water_material = "water"

[nodes.terrain]
type = "implicit_heightfield"
extent = [-200.0, -200.0, 200.0, 200.0]
source = "file"
file = "h.npy"
R = 20.0
T = 10.0

[nodes.hollow]
type = "skeletal_set"
a = [[0.0, 0.0, 90.0]]
radius = [8.0]
energy = [-1.0]

[nodes.world]
type = "sum"
children = ["terrain", "hollow"]
"""

EXTENT = 200.0


def _desc(tmp_path):
    x = np.linspace(-EXTENT, EXTENT, 41)
    X, Y = np.meshgrid(x, x)
    np.save(tmp_path / "h.npy", (100.0 + 6.0 * np.sin(X / 23.0) * np.cos(Y / 31.0) + 0.02 * X).astype(np.float32))
    (tmp_path / "scene.toml").write_text(SCENE)
    return load_scene(tmp_path / "scene.toml")


def _scene(tmp_path):
    """The far field's shapes and a cube standing in for a mesh inside the tile."""
    desc = _desc(tmp_path)
    item = desc.tables["far_field"][0]
    bsdf = mi.load_dict({"type": "diffuse"})
    d = {"type": "scene", "rock": {"type": "cube", "to_world": mi.ScalarTransform4f().translate([50.0, -30.0, 104.0])
                                                          @ mi.ScalarTransform4f().scale([6.0, 4.0, 3.0])}}
    for k, shape in enumerate(item.shapes({"ground": bsdf, "water": bsdf})):
        d[f"{item.name}_{k}"] = shape
    scene = mi.load_dict(d)
    return scene, item, scene_mesh_region(scene, [item])


def _rays(o, d, maxt):
    f = lambda a: [mi.Float(np.ascontiguousarray(c, np.float32)) for c in np.asarray(a).T]  # noqa: E731
    return mi.Ray3f(mi.Point3f(*f(o)), mi.Vector3f(*f(d)), mi.Float(np.asarray(maxt, np.float32)))


def test_rays_the_region_skips_meet_no_mesh(tmp_path):
    """Random rays in and around the tile, at every angle and of every length: Mitsuba
    finds no hit on a ray the region skips, and the region skips many."""
    scene, item, region = _scene(tmp_path)
    assert region.box is not None and region.skirt is not None
    rng = np.random.default_rng(3)
    n = 200_000
    o = np.column_stack([rng.uniform(-1.3, 1.3, (n, 2)) * EXTENT, rng.uniform(70.0, 170.0, n)])
    d = rng.normal(size=(n, 3))
    d[: n // 3, 2] *= 0.05  # a third near the horizontal: the far field's grazing rays
    d /= np.linalg.norm(d, axis=1)[:, None]
    maxt = np.where(rng.random(n) < 0.5, np.inf, rng.uniform(1.0, 600.0, n))
    ray = _rays(o, d, maxt)
    hit = scene.ray_intersect(ray).is_valid()
    may = region.may_meet(ray.o, ray.d, ray.maxt)
    wrong = np.asarray(hit & ~may)
    assert not wrong.any(), (o[wrong][:5], d[wrong][:5], maxt[wrong][:5])
    assert np.asarray(hit).mean() > 0.2
    assert np.asarray(~may).mean() > 0.25  # the region is worth asking


def test_every_triangle_lies_in_the_region(tmp_path):
    """Segments from inside the tile to random points of every mesh (the far field's
    frame band, rings and sea, and the cube) meet the region: its hole holds no
    triangle."""
    scene, item, region = _scene(tmp_path)
    rng = np.random.default_rng(4)
    targets = []
    for _, mesh in item.meshes():
        V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        near = np.abs(V[F].mean(1)[:, :2]).max(1) < 3 * EXTENT  # the triangles a tile's ray meets
        tri = V[F[near][rng.integers(0, near.sum(), 20_000)]]
        w = rng.dirichlet(np.ones(3), len(tri))
        targets.append(np.einsum("nk,nkj->nj", w, tri))
    targets.append(rng.uniform(-1, 1, (2000, 3)) * [6.0, 4.0, 3.0] + [50.0, -30.0, 104.0])  # the cube
    p = np.concatenate(targets)
    o = np.column_stack([rng.uniform(-0.9, 0.9, (len(p), 2)) * EXTENT, rng.uniform(90.0, 130.0, len(p))])
    v = p - o
    dist = np.linalg.norm(v, axis=1)
    may = region.may_meet(*(lambda r: (r.o, r.d, r.maxt))(_rays(o, v / dist[:, None], dist * (1 + 1e-6))))
    missed = ~np.asarray(may)
    assert not missed.any(), p[missed][:5]


def test_a_segment_ending_over_the_tile_skips_the_skirt():
    """A ray that ends over the hole, stays over it, or leaves the slab of the skirt's
    heights before the hole's edge skips it; one that leaves the hole low, or comes
    down into the slab outside it, does not."""
    region = MeshRegion(None, ((-100.0, -100.0, 100.0, 100.0), 0.0, 50.0)).grown()
    o = mi.Point3f([0.0, 0.0, 0.0, 0.0, 0.0, 150.0], [0.0] * 6, [10.0, 10.0, 10.0, 60.0, 60.0, 80.0])
    d = dr.normalize(mi.Vector3f([1.0, 1.0, 1.0, 0.0, 1.0, 0.0], [0.0] * 6, [0.0, 0.0, 1.0, -1.0, -0.5, -1.0]))
    tmax = mi.Float([50.0, np.inf, np.inf, np.inf, np.inf, 20.0])
    assert list(region.may_meet(o, d, tmax)) == [False, True, False, False, True, False]
    assert list(region.may_meet(o, d, tmax + 60.0)) == [True, True, False, False, True, True]


def test_renders_alike_with_and_without_the_region(tmp_path):
    """The picture is the same, bit for bit, whether the integrator asks Mitsuba about every
    ray or only the rays the region may hold."""
    scene = build_scene(_desc(tmp_path))
    integrator = scene.integrator()
    assert integrator.mesh_region is not None
    with_region = np.asarray(render_layers(scene, 2, seed=5)[0])
    integrator.attach_mesh_region(None)
    without = np.asarray(render_layers(scene, 2, seed=5)[0])
    assert np.array_equal(with_region, without)
    assert with_region[..., :3].mean() > 0.01


def test_mesh_mode_renders_alike_with_and_without_the_region(tmp_path):
    """In mesh mode (``implicit_path`` without a field: the field's mesh lies in the region's
    box, the far field in its skirt, both asked in one query) the picture is the same, bit
    for bit, with and without the region."""
    scene = build_scene(_desc(tmp_path), geometry="mesh", voxel=4.0, aovs=True)
    integrator = scene.integrator()
    assert integrator.mesh_region is not None and integrator.mesh_region.box is not None
    with_region = np.asarray(render_layers(scene, 2, seed=5)[0])
    integrator.attach_mesh_region(None)
    without = np.asarray(render_layers(scene, 2, seed=5)[0])
    assert np.array_equal(with_region, without)
    assert with_region[..., :3].mean() > 0.01
