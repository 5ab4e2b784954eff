"""No camera ray is left unresolved by the tracer's two step budgets (issue 21, item 1).

Every gallery scene and every named camera of two in-repo real DEMs amplified
with the default preset renders small, and the ``unresolved`` AOV of camera rays
(rays that used up both budgets) must be 0 everywhere; the shipped scenes get the
same check in their field-vs-mesh test (``test_render.py``), the third real DEM
(the Salish Sea) in its landscape test (``test_terrain_landscape.py``), which
amplifies and renders it anyway. One
CLI render checks that the counts reach the EXR header. A ray that gives up is a
bug to find, not a pixel to hide: before issue 21 such rays came back as misses
and showed the sky through canyon walls.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers import variant

variant()

from arches_render.cli import main  # noqa: E402
from arches_render.imaging.exr import read_exr  # noqa: E402
from arches_render.render.jobs import set_camera  # noqa: E402
from arches_render.render.renderer import build_scene, render_layers  # noqa: E402
from arches_render.scene import load_scene  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
GALLERY = sorted((REPO / "scenes" / "gallery").glob("*.toml"))
#: The real DEMs (file, cell size, extra amplify options).
REAL_DEMS = [("real_nm_canyon_10m.npy", "10", []), ("real_jacksboro_80m.npy", "80", [])]
W, H = 40, 24


def _unresolved_per_camera(scene_file):
    """``{camera: unresolved camera rays}`` of a 1 spp render through every named camera."""
    desc = load_scene(scene_file)
    scene = build_scene(desc, "field", W, H, aovs=True)
    out = {}
    for name, cam in desc.cameras.items():
        set_camera(scene, cam.origin, cam.target, cam.up, cam.fov)
        _, layers = render_layers(scene, 1, seed=2)
        arr, letters = layers["unresolved"]
        out[name] = int(arr[..., letters.index("primary")].sum())
    return out


@pytest.mark.parametrize("scene", GALLERY, ids=lambda p: p.stem)
def test_gallery_scenes_leave_no_camera_ray_unresolved(scene):
    left = _unresolved_per_camera(scene)
    assert not any(left.values()), f"unresolved camera rays: {left}"


@pytest.mark.parametrize("dem, cell, extra", REAL_DEMS, ids=[d[0].split(".")[0] for d in REAL_DEMS])
def test_every_camera_of_the_real_dems_leaves_no_camera_ray_unresolved(dem, cell, extra, tmp_path):
    scene = tmp_path / "dem.toml"
    assert main(["amplify", str(REPO / "scenes" / "data" / dem), "-o", str(scene), "--cell-size", cell,
                 "--seed", "5", "-q", *extra]) == 0
    left = _unresolved_per_camera(scene)
    assert len(left) >= 1
    assert not any(left.values()), f"unresolved camera rays: {left}"
    if dem.startswith("real_nm"):
        # The counts reach the EXR header (the canyon close shot).
        out = tmp_path / "u.exr"
        assert main(["render", str(scene), "--camera", next(iter(left)), "-o", str(out),
                     "--resolution", f"{W}x{H}", "--spp", "2", "-q"]) == 0
        img = read_exr(out)
        arr, letters = img.layers["exhausted"], img.layer_channels["exhausted"]
        expect = int(round(float(arr[..., letters.index("primary")].astype(np.float64).sum()) * 2))
        assert int(img.header["rays_exhausted_primary"]) == expect
        assert img.header["rays_unresolved_primary"] == "0"
