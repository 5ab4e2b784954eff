"""A field hit never lands under a mesh that lies on the field (arches_render/render/integrator.py).

A far field's frame is a mesh of the DEM's samples over the tile's border band, lifted a
few centimetres over the implicit heightfield it covers. A sphere-traced ray stops up to
its hit tolerance (``eps t``: 10 cm at 500 m) off the field's surface, in front of the
frame, and its hit is then projected onto the surface, under the frame: every shadow and
bounce ray from there met the frame, and a jagged black line ran along the tile's border
in every view from outside the tile (Maunga Whau's overview stood back: issue 34). Within
the tolerance of a mesh, measured along the mesh's normal, the mesh is now the hit.
"""

from __future__ import annotations

import numpy as np

from helpers import variant

variant()

from arches_render.render.renderer import build_scene, render_layers  # noqa: E402
from arches_render.scene import load_scene  # noqa: E402

SCENE = """
[scene]
name = "seam"

[render]
resolution = [160, 90]
spp = 4
max_depth = 3

[cameras.outside]
origin = [0.0, 420.0, 135.0]
target = [0.0, 150.0, 100.0]
fov = 50.0

[[lights]]
type = "sunsky"
elevation = 35.0
azimuth = 102.0

[materials.ground]
type = "diffuse"
color = [0.3, 0.4, 0.2]

[field]
root = "world"
material = "ground"

[[far_field]]
node = "terrain"
material = "ground"

[nodes.terrain]
type = "implicit_heightfield"
extent = [-200.0, -200.0, 200.0, 200.0]
source = "file"
file = "h.npy"
R = 20.0
T = 10.0

# A sum with a skeletal set (a hollow under the middle): the whole tile is sphere-traced.
[nodes.hollow]
type = "skeletal_set"
a = [[0.0, 0.0, 90.0]]
radius = [8.0]
energy = [-1.0]

[nodes.world]
type = "sum"
children = ["terrain", "hollow"]
"""


def test_no_black_line_along_a_tiles_border_seen_from_outside(tmp_path):
    """From outside the tile, looking across its border band at a low angle, no ground
    pixel is black. (Before: 76 of 10,720 were, all on the border band.)"""
    x = np.linspace(-200.0, 200.0, 41)
    X, Y = np.meshgrid(x, x)
    np.save(tmp_path / "h.npy", (100.0 + 6.0 * np.sin(X / 23.0) * np.cos(Y / 31.0) + 0.02 * X).astype(np.float32))
    (tmp_path / "scene.toml").write_text(SCENE)
    desc = load_scene(tmp_path / "scene.toml")
    rgb, layers = render_layers(build_scene(desc, aovs=True), 4, seed=1)
    lum = np.asarray(rgb)[..., :3].mean(-1)
    cover = np.asarray(layers["coverage"][0]).sum(-1)  # field and mesh hits
    ground = cover > 0.99
    assert ground.sum() > 8000
    # Sunlit grass under a sky: the darkest ground pixel is well above black (the border
    # band's pixels were 0 where the frame blocked every ray).
    assert np.all(lum[ground] > 0.1 * np.median(lum[ground])), np.argwhere(ground & (lum < 0.1 * np.median(lum)))[:10]
