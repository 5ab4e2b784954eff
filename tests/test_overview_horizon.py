"""An overview's horizon (issue 34): where the far field meets the sky it fades into haze,
never a ruled line; and no tile edge in the frame (checked with the coverage AOV and the
field's box, as every landscape shot is)."""

from __future__ import annotations

import numpy as np

from helpers import REPO, variant
from landscape_helpers import render_shots, shot_report, skyline_report
from robust_helpers import cli_out

#: The most a flat far field's skyline may stand out from the sky above it (luminance,
#: :func:`landscape_helpers.skyline_report`). The Maunga Whau overview below reads 0.18 at
#: 256x144 in default air (0.08 at 640x360, as tiles of 5-30 km do), 0.77 without air.
SKYLINE_CONTRAST = 0.25


def test_a_small_tiles_overview_fades_its_far_field_into_the_sky(tmp_path, capsys):
    # The 0.86 km Maunga Whau DEM: tiles under a kilometre had no [atmosphere], and the
    # far field's plain ended in a sharp line against the sky, its rolling relief unread.
    variant()
    from arches_render.scene import load_scene
    out = tmp_path / "mw.toml"
    rc, _, err = cli_out(capsys, "amplify", REPO / "scenes" / "data" / "real_maunga_whau_10m.npy", "-o", out,
                         "--cell-size", "10", "-q")
    assert rc == 0, err
    desc = load_scene(out)
    desc.cameras = {"overview": desc.cameras["overview"]}
    width, height = 256, 144
    rgb, layers = render_shots(desc, width, height, spp=2)["overview"]
    rep = shot_report(desc, layers, desc.cameras["overview"], width, height) | skyline_report(rgb, layers)
    assert rep["wall_hits"] == 0.0 and rep["below_horizon_misses"] == 0.0 and rep["top_sky"] > 0.5, rep
    # The horizon here is the far field's, flat: it must not stand out.
    assert rep["skyline_columns"] > 0.9 and rep["skyline_flat"] > 0.5 and rep["skyline_far"] > 0.5, rep
    assert rep["skyline_contrast"] < SKYLINE_CONTRAST, rep
