"""Tiny scenes shared by the production tests (turntables, AOVs, API, export)."""

from __future__ import annotations

from pathlib import Path

# Camera 10 m above a flat field (a wide box with its top at z = 0), looking
# straight down; a mesh ball sits on the field. Every pixel sees a surface.
FLAT = """
[scene]
name = "flat"
[render]
resolution = [32, 18]
spp = 4
max_depth = 3
[camera]
origin = [0.0, 0.0, 10.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = 60.0
[[lights]]
type = "sunsky"
elevation = 50.0
azimuth = 30.0
[materials.ground]
type = "triplanar"
preset = "terrain"
[materials.paint]
type = "diffuse"
color = [0.2, 0.4, 0.6]
[[meshes]]
shape = "sphere"
translate = [0.0, 0.0, 1.0]
material = "paint"
[field]
root = "world"
material = "ground"
[nodes.world]
type = "union"
children = ["slab", "ball"]
[nodes.slab]
type = "box"
center = [0.0, 0.0, -1.0]
size = [40.0, 40.0, 2.0]
[nodes.ball]
type = "sphere"
center = [3.0, 1.0, 0.5]
radius = 1.0
"""

# A small rock on a pedestal for turntables: cheap, and it changes with the view.
ROCK = """
[scene]
name = "rock"
[render]
resolution = [32, 18]
spp = 2
max_depth = 2
[camera]
origin = [0.0, -6.0, 2.5]
target = [0.0, 0.0, 0.6]
fov = 45.0
[[lights]]
type = "directional"
elevation = 40.0
azimuth = 20.0
irradiance = 3.0
[[lights]]
type = "constant"
radiance = 0.3
[materials.stone]
type = "triplanar"
preset = "basalt"
[field]
root = "rock"
material = "stone"
[nodes.rock]
type = "blend"
radius = 0.3
children = [{ type = "box", center = [0.0, 0.0, 0.25], size = [3.0, 3.0, 0.5] },
            { type = "capsule", a = [-0.6, 0.0, 0.8], b = [0.7, 0.3, 1.1], radius = 0.5 }]
"""


def write_scene(folder: Path, text: str, name: str) -> Path:
    path = Path(folder) / f"{name}.toml"
    path.write_text(text)
    return path


def assert_edits_compile_nothing(look, edits: dict, prev):
    """Apply lookdev ``edits`` one by one: each must change the image and compile no kernel.
    Returns the last image."""
    import numpy as np
    for key, value in edits.items():
        look.set(key, value)
        img = look.render()
        assert look.compiled == 0, f"{key}: {look.compiled} kernels compiled"
        assert not np.array_equal(img, prev), f"{key} changed nothing"
        prev = img
    return prev
