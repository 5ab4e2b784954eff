"""A render process imports only what its scene uses.

Every render (a CLI call, a turntable frame, a Dask worker) is a fresh process, so
import time is paid per render: scipy.special, scipy.ndimage, numba, tifffile and
imageio took 0.7 s of the 2.5 s that a 5,000-rock scene took from start to its
first sample (``rocks_instances_5000_setup_s``). They are imported where they are
used; their replacements here must give the same bits.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from helpers import REPO

SCENE = """
[render]
resolution = [64, 36]
[camera]
origin = [-11.0, -13.0, 7.0]
target = [0.0, 0.0, 0.0]
[[lights]]
type = "sunsky"
elevation = 35.0
[materials.ground]
type = "triplanar"
preset = "terrain"
[field]
root = "ground"
material = "ground"
[nodes.ground]
type = "heightfield"
source = "fbm"
extent = [-14.0, -14.0, 14.0, 14.0]
resolution = [96, 96]
amplitude = 0.8
wavelength = 9.0
seed = 3
"""

CHILD = """
import json, sys
from arches_render.backend import set_variant
set_variant()
from arches_render.scene import load_scene
from arches_render.render.renderer import build_scene
build_scene(load_scene(sys.argv[1]), width=64, height=36)
print(json.dumps(sorted(sys.modules)))
"""

#: Imported on use only: none of them serves a heightfield scene with textures.
HEAVY = ("numba", "scipy.special", "scipy.ndimage", "scipy.spatial", "scipy.stats", "tifffile", "imageio")


def test_a_textured_heightfield_scene_builds_without_heavy_imports(tmp_path):
    scene = tmp_path / "ground.toml"
    scene.write_text(SCENE)
    env = dict(os.environ, ARCHES_RENDER_CACHE=str(tmp_path / "cache"))
    runs = []
    for _ in range(2):  # the first fills the cache (texture tables), the second reads it
        proc = subprocess.run([sys.executable, "-c", CHILD, str(scene)], cwd=REPO, env=env, capture_output=True,
                              text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        runs.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    assert "arches_render.materials.textures" in runs[1]  # the textures were really loaded
    assert list((tmp_path / "cache" / "textures").glob("histogram-*.npz"))
    loaded = sorted({h for h in HEAVY for m in runs[1] if m == h or m.startswith(h + ".")})
    assert not loaded, f"building the scene imported {loaded}"


def test_normal_quantile_and_cdf_match_scipy():
    special = pytest.importorskip("scipy.special")
    from arches_render.materials.textures import normal_cdf, normal_quantile
    u = np.concatenate([np.linspace(1e-6, 1 - 1e-6, 20001), [1e-12, 0.5, 1 - 1e-12]])
    # AS 241 and Cephes' ndtri are two rational approximations, each accurate to ~1e-16:
    # measured 1.8e-15 apart at most (1.0e-15 relative), far below the float32 tables.
    assert np.allclose(normal_quantile(u), special.ndtri(u), rtol=1e-14, atol=1e-14)
    x = np.linspace(-9.0, 9.0, 20001)
    # libm's erfc and Cephes' ndtr differ by up to 1.5e-14 relative in the far tail
    # (Phi(-9) ~ 1e-19): far below float32's 6e-8, in which the tables are stored.
    assert np.allclose(normal_cdf(x), special.ndtr(x), rtol=5e-14, atol=0.0)


def test_histogram_tables_are_the_same_bits_from_the_cache(tmp_path, monkeypatch):
    from arches_render.materials import textures as T
    monkeypatch.setenv("ARCHES_RENDER_CACHE", str(tmp_path))
    arr = T._read(T.texture_path("strata.png"), True, False)
    gauss, lut = T.gaussianize(arr)
    tables, sigma = T.filter_tables(gauss, lut)
    built = T.histogram_tables(arr)

    def refuse(_):
        raise AssertionError("rebuilt although the entry was on disk")

    monkeypatch.setattr(T, "gaussianize", refuse)
    loaded = T.histogram_tables(arr)
    for a, b, c in zip((gauss, tables, sigma), built, loaded):
        assert a.dtype == b.dtype == c.dtype and np.array_equal(a, b) and np.array_equal(a, c)
    # Other texels, another entry.
    with pytest.raises(AssertionError, match="rebuilt"):
        T.histogram_tables(arr[::-1].copy())


def test_window_filters_are_scipys():
    ndimage = pytest.importorskip("scipy.ndimage")
    from arches_render.field.heightfield import _window_max
    from arches_render.field.window_filters import window_max, window_min
    rng = np.random.default_rng(4)
    for shape in [(1,), (9,), (1, 1), (1, 7), (5, 3), (40, 33), (129, 64), (3, 5, 7), (6, 1, 4)]:
        a = rng.normal(size=shape)
        for size in (1, 3, 5, 9, 19, 67, 259):
            assert np.array_equal(window_max(a, size), ndimage.maximum_filter(a, size=size, mode="nearest"))
            assert np.array_equal(window_min(a, size), ndimage.minimum_filter(a, size=size, mode="nearest"))
        if a.ndim == 2:
            for w in (0, 2, 8, 128):  # the heightfield's windows: 2 w + 3 samples
                assert np.array_equal(_window_max(a, w), ndimage.maximum_filter(a, size=2 * w + 3, mode="nearest"))
    with pytest.raises(ValueError, match="odd"):
        window_max(np.zeros(4), 4)


CLI_RENDER = """
import json, sys
from arches_render.cli import build_parser
args = build_parser(sys.argv[1:]).parse_args(sys.argv[1:])
print(json.dumps({"command": args.command, "modules": sorted(sys.modules)}))
"""


def test_a_render_command_registers_only_render():
    """``arches-render render`` imports no generator's subcommand (``amplify``: numba, trimesh
    and scipy) nor the turntable's scipy.interpolate; ``--help`` and unknown names see them all."""
    proc = subprocess.run([sys.executable, "-c", CLI_RENDER, "render", "scene.toml", "--spp", "4"], cwd=REPO,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["command"] == "render"
    loaded = set(out["modules"])
    assert "arches_render.commands.render" in loaded
    others = {"arches_render.generators.terrain.command", "arches_render.generators.terrain.amplify",
              "numba", "trimesh", "scipy.interpolate", "scipy.ndimage", "scipy.special"}
    assert not others & loaded, sorted(others & loaded)
    from arches_render.cli import build_parser
    import argparse
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert {"render", "turntable", "amplify", "rocks"} <= set(sub.choices)
