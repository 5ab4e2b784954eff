"""The strata preset's erosion field (Paris et al. 2019, Sec. 6: ``f - f_D (1 - rho)``):
a recess along the soft beds, not a pocket at every sphere of ``f_D`` (issue 34: a
caldera's walls read polka-dotted, rows of round holes at the spheres' centres)."""

from __future__ import annotations

import tomllib

import numpy as np
from scipy.spatial import cKDTree

from arches_render.generators.terrain.falloff import g
from helpers import variant
from robust_helpers import cli_out
from synthetic_dems import caldera


def test_the_strata_erosion_field_is_as_deep_between_its_spheres_as_at_them(tmp_path, capsys):
    variant()
    np.save(tmp_path / "caldera.npy", caldera())
    out = tmp_path / "c.toml"
    rc, _, err = cli_out(capsys, "amplify", tmp_path / "caldera.npy", "-o", out, "--cell-size", "150",
                         "--seed", "5", "--preset", "strata", "--no-fallen-blocks", "-q")
    assert rc == 0, err
    doc = tomllib.loads(out.read_text())
    node, T = doc["nodes"]["strata_field"], float(doc["nodes"]["terrain"]["T"])
    with np.load(tmp_path / node["file"], allow_pickle=False) as z:
        a, R, e = z["a"], z["radius"], z["energy"]
    assert len(a) > 50 and np.all(R == R[0])

    def field(P):  # f_D as the scene's node combines its spheres
        parts = e[None] * g(np.linalg.norm(P[:, None] - a[None], axis=-1), R[None])
        return parts.sum(axis=1) if node.get("combine", "sum") == "sum" else parts.max(axis=1)

    # Midway between neighbouring spheres (closer than 0.9 R) the field carves as deep as
    # at their centres: as a maximum it fell to 0.51-0.75 of it there.
    i, j = cKDTree(a).query_pairs(0.9 * R[0], output_type="ndarray").T
    assert len(i) > len(a) / 2
    centres, middles = field(a), field(0.5 * (a[i] + a[j]))
    assert np.median(middles) >= 0.9 * np.median(centres), (np.median(middles), np.median(centres))
    # As deep as one sphere of the paper's 2T carved (the typical centre).
    assert abs(np.median(centres) - 2.0 * T) <= 1e-6 * T
