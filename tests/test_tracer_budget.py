"""No ray is left unresolved by the tracer's two step budgets (issue 21, item 1).

Every shipped scene, every gallery scene, and every named camera of the three
in-repo real DEMs amplified with the default preset renders small through the CLI;
the EXR header's ``rays_unresolved_primary`` (camera rays that used up both
budgets) must be 0, and the counts must be there at all. A ray that gives up is a
bug to find, not a pixel to hide: before issue 21 such rays came back as misses
and showed the sky through canyon walls.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from helpers import variant

variant()

from arches_render.cli import main  # noqa: E402
from arches_render.imaging.exr import read_exr  # noqa: E402
from arches_render.scene import load_scene  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHIPPED = sorted(p for p in (REPO / "scenes").glob("*.toml") if "\n[field]" in p.read_text())
GALLERY = sorted((REPO / "scenes" / "gallery").glob("*.toml"))
#: The real DEMs (file, cell size, extra amplify options: Salish Sea reduced, as in
#: the landscape tests, for time).
REAL_DEMS = [("real_nm_canyon_10m.npy", "10", []), ("real_jacksboro_80m.npy", "80", []),
             ("real_salish_sea_2435m.npy", "2435", ["--max-cells", "3000"])]
SIZE = "48x27"


def _unresolved(scene, camera, out):
    args = ["render", str(scene), "-o", str(out), "--resolution", SIZE, "--spp", "1", "-q"]
    if camera:
        args += ["--camera", camera]
    assert main(args) == 0
    header = read_exr(out).header
    assert "rays_unresolved_primary" in header and "rays_exhausted_primary" in header
    return int(header["rays_unresolved_primary"])


@pytest.mark.parametrize("scene", SHIPPED + GALLERY, ids=lambda p: p.stem)
def test_shipped_and_gallery_scenes_leave_no_ray_unresolved(scene, tmp_path):
    assert _unresolved(scene, None, tmp_path / "r.exr") == 0


@pytest.mark.parametrize("dem, cell, extra", REAL_DEMS, ids=lambda v: v if isinstance(v, str) else "")
def test_every_camera_of_the_real_dems_leaves_no_ray_unresolved(dem, cell, extra, tmp_path):
    scene = tmp_path / "dem.toml"
    assert main(["amplify", str(REPO / "scenes" / "data" / dem), "-o", str(scene), "--cell-size", cell,
                 "--seed", "5", "-q", *extra]) == 0
    cameras = list(load_scene(scene).cameras)
    assert len(cameras) >= 1
    left = {cam: _unresolved(scene, cam, tmp_path / f"{cam}.exr") for cam in cameras}
    assert not any(left.values()), f"unresolved camera rays: {left}"
