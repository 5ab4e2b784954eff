"""``arches-render amplify`` end to end, karst percolation and hoodoo grammar, determinism."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from helpers import REPO, variant


def _amplify(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "arches_render.cli", "amplify", *map(str, args), "-q"],
                          capture_output=True, text=True, cwd=cwd or REPO, timeout=300)


def _cliff_dem(n=33):
    x = np.linspace(-1, 1, n)
    X, Y = np.meshgrid(x, x)
    t = np.clip((Y + 0.2) / 0.15, 0, 1)
    return (-2.0 + 14.0 * t * t * (3 - 2 * t)).astype(np.float32)


# -- invasion percolation ------------------------------------------------------------------------
def _lattice(rng, spacing=1.0):
    from arches_render.generators.terrain.karst import PercolationLattice
    return PercolationLattice((0, 0, 0), (30, 30, 30), spacing, rng)


def test_invasion_percolation_follows_the_least_resistant_layer():
    from arches_render.generators.terrain.karst import invasion_percolation
    rng = np.random.default_rng(0)
    lat = _lattice(rng)
    P = lat.positions
    band = np.abs(P[:, 2] - 12.0) < 2.0                       # soft layer, 4 of 30 m
    rho = np.where(band, 0.1, 0.6) + 0.05 * rng.random(len(P))
    seed_site = lat.index([[15.0, 15.0, 29.0]])
    order, parent = invasion_percolation(lat, rho, seed_site, rho0=1.0, epsilon=0.1, branching=17,
                                         max_sites=600, rng=np.random.default_rng(1))
    assert len(order) == 600
    # Water has to go down through the hard rock once, then spreads in the soft layer.
    assert band[order].mean() > 0.85 > band.mean() + 0.5
    # Every invaded site was reached from an invaded site in its lower hemisphere.
    nz, ny, nx = lat.shape
    k = order // (ny * nx)
    kp = parent[order[1:]] // (ny * nx)
    assert np.all(parent[order[1:]] >= 0) and np.all(np.isin(parent[order[1:]], order))
    assert np.all(k[1:] <= kp)                                # never upwards
    # The threshold rho_0: only soft sites are carved when rho_0 sits between the layers.
    order2, _ = invasion_percolation(lat, rho, lat.index([[15.0, 15.0, 12.0]]), rho0=0.5, epsilon=0.1,
                                     branching=17, max_sites=100_000, rng=np.random.default_rng(1))
    assert len(order2) > 100 and np.all(rho[order2] < 0.5)


def test_invasion_percolation_drifts_towards_softer_rock():
    from arches_render.generators.terrain.karst import invasion_percolation
    rng = np.random.default_rng(2)
    lat = _lattice(rng)
    P = lat.positions
    rho = 0.3 + 0.4 * (30.0 - P[:, 0]) / 30.0                 # softer towards +x
    order, _ = invasion_percolation(lat, rho, lat.index([[15.0, 15.0, 25.0]]), rho0=1.0, epsilon=0.1,
                                    branching=17, max_sites=400, rng=rng)
    assert P[order, 0].mean() > 18.0


def test_karst_network_is_deterministic_and_underground():
    from arches_render.generators.terrain.karst import karst_network
    h = lambda x, y: np.full_like(np.asarray(x, float), 40.0)  # noqa: E731
    rho = lambda P: np.where(np.abs(P[:, 2] - 20.0) < 4.0, 0.1, 0.8)  # noqa: E731
    args = (h, (0, 0, 60, 60), (0, 40), rho, [[30.0, 30.0, 40.0]], 3.0, 1.5)
    a = karst_network(*args, rho0=0.45, max_sites=300, seed=4)
    b = karst_network(*args, rho0=0.45, max_sites=300, seed=4)
    c = karst_network(*args, rho0=0.45, max_sites=300, seed=5)
    assert len(a) > 50 and np.array_equal(a.center, b.center) and np.array_equal(a.radius, b.radius)
    assert not (len(a) == len(c) and np.array_equal(a.end, c.end))
    # A shaft from the sink goes down to the soft layer (the sink is on hard rock); tunnels stay in it.
    assert a.center[0, 2] > 39.0 and abs(a.end[0, 2] - 20.0) < 4.0 + 3.0
    assert np.all(np.abs(a.end[1:, 2] - 20.0) < 4.0 + 1.0)


# -- hoodoo grammar -------------------------------------------------------------------------------
def test_hoodoo_grammar_follows_the_rules():
    from arches_render.generators.terrain import hoodoos as hd
    feet = np.zeros((200, 3))
    feet[:, 0] = np.arange(200) * 10.0
    hard = hd.derive_hoodoos(feet, 4.0, 1.5, lambda P: np.full(len(P), 0.95), np.random.default_rng(0))
    soft = hd.derive_hoodoos(feet, 4.0, 1.5, lambda P: np.full(len(P), 0.05), np.random.default_rng(0))
    for s in (hard, soft):
        for k in range(200):
            sym = s.symbol[s.hoodoo == k]
            assert sym[0] == hd.BLOCK                    # A -> B -> b ...
            assert np.all(sym[sym == hd.CAP] == hd.CAP) and (sym[-1] == hd.CAP) == (hd.CAP in sym)
            if hd.CAP in sym:                            # a cap (d) ends the derivation
                assert np.all(sym[-3:] == hd.CAP) and np.sum(sym == hd.CAP) == 3
    # Hard rock stacks more blocks and caps more columns; its symbols are wider.
    cap_rate = lambda s: np.mean([hd.CAP in s.symbol[s.hoodoo == k] for k in range(200)])  # noqa: E731
    assert cap_rate(hard) > 0.8 > 0.3 > cap_rate(soft)
    assert np.sum(hard.symbol == hd.BLOCK) > 1.5 * np.sum(soft.symbol == hd.BLOCK)
    assert np.median(hard.width[hard.symbol == hd.BLOCK]) > np.median(soft.width[soft.symbol == hd.BLOCK])
    # Columns grow upwards, each symbol on top of the last.
    z = hard.b[:, 2] - hard.a[:, 2]
    assert np.all(z[hard.symbol != hd.CAP] > 0)


# -- amplify CLI ----------------------------------------------------------------------------------
def test_amplify_cli_end_to_end(tmp_path):
    variant()
    from arches_render.field import evaluate
    from arches_render.scene import load_scene
    dem = tmp_path / "cliff.npy"
    np.save(dem, _cliff_dem())
    out = tmp_path / "scene.toml"
    r = _amplify(dem, "-o", out, "--preset", "sea", "--seed", "3", "--cell-size", "2")
    assert r.returncode == 0, r.stderr
    assert "wrote" in r.stdout and out.is_file()
    desc = load_scene(out)
    assert desc.field is not None and desc.field.count() >= 3
    names = sorted(p.name for p in tmp_path.iterdir())
    assert "scene.heights.npy" in names and "scene.sea_erosion.npz" in names
    assert not any(n.startswith(".") for n in names)  # no temporary files left
    # The camera sees the terrain: the centre of the image ray hits the field's box.
    lo, hi = desc.field.bounds()
    target = np.asarray(desc.camera.target)
    assert np.all(target >= lo - 1e-6) and np.all(target <= hi + 1e-6)
    # Same seed, same tree; another seed, another tree.
    out2 = tmp_path / "again.toml"
    assert _amplify(dem, "-o", out2, "--preset", "sea", "--seed", "3", "--cell-size", "2").returncode == 0
    pts = np.random.default_rng(0).uniform(lo, hi, (20000, 3))
    f1 = evaluate(desc.field, pts)
    np.testing.assert_array_equal(f1, evaluate(load_scene(out2).field, pts))
    out3 = tmp_path / "other.toml"
    assert _amplify(dem, "-o", out3, "--preset", "sea", "--seed", "4", "--cell-size", "2").returncode == 0
    assert not np.array_equal(f1, evaluate(load_scene(out3).field, pts))


@pytest.mark.parametrize("preset", ["river", "karst", "hoodoos", "strata"])
def test_amplify_presets_write_loadable_scenes(tmp_path, preset):
    variant()
    from arches_render.scene import load_scene
    x = np.linspace(-1, 1, 41)
    X, Y = np.meshgrid(x, x)
    H = 30.0 * np.clip(np.abs(X - 0.3 * np.sin(3 * Y)) / 0.3, 0, 1) + 3.0 * (Y + 1)  # a valley
    H -= 6.0 * np.exp(-((X - 0.6) ** 2 + (Y - 0.5) ** 2) / 0.01)                         # a sink
    np.save(tmp_path / "v.npy", H)
    out = tmp_path / f"{preset}.toml"
    r = _amplify(tmp_path / "v.npy", "-o", out, "--preset", preset, "--data-dir", "data")
    assert r.returncode == 0, r.stderr
    desc = load_scene(out)
    assert desc.field.count() >= 3, f"{preset}: no landform generated"
    assert (tmp_path / "data" / f"{preset}.heights.npy").is_file()


@pytest.mark.parametrize("content,message", [
    ("tiny", "at least 2x2"), ("nan", "no valid height"), ("missing", "no such file"),
    ("badext", "unknown DEM format"), ("small", "at least 3x3")])
def test_amplify_bad_dems_exit_2_with_one_line(tmp_path, content, message):
    path = tmp_path / ("dem.txt" if content == "badext" else "dem.npy")
    if content == "tiny":
        np.save(path, np.zeros((1, 1)))
    elif content == "nan":
        np.save(path, np.full((8, 8), np.nan))
    elif content == "small":
        np.save(path, np.zeros((2, 5)))
    elif content == "badext":
        path.write_text("1 2 3")
    r = _amplify(path, "-o", tmp_path / "s.toml")
    assert r.returncode == 2 and message in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "s.toml").exists()


def test_amplify_flat_dem_and_nodata(tmp_path):
    variant()
    from arches_render.scene import load_scene
    np.save(tmp_path / "flat.npy", np.full((16, 16), 5.0))
    r = _amplify(tmp_path / "flat.npy", "-o", tmp_path / "flat.toml", "--preset", "sea")
    assert r.returncode == 0, r.stderr
    assert "flat" in r.stdout and load_scene(tmp_path / "flat.toml").field is not None
    H = _cliff_dem(24).astype(np.float64)
    H[5:8, 5:9] = np.nan
    np.save(tmp_path / "holes.npy", H)
    r = _amplify(tmp_path / "holes.npy", "-o", tmp_path / "holes.toml", "--preset", "strata")
    assert r.returncode == 0 and "filled 12 no-data cells" in r.stdout, r.stdout + r.stderr
    assert load_scene(tmp_path / "holes.toml").field is not None


def test_amplify_bad_arguments(tmp_path):
    np.save(tmp_path / "d.npy", _cliff_dem(8))
    for args, msg in ((["--preset", "lava"], "invalid choice"), (["--cell-size", "-1"], "--cell-size"),
                      (["--seed", "x"], "--seed")):
        r = _amplify(tmp_path / "d.npy", "-o", tmp_path / "s.toml", *args)
        assert r.returncode == 2 and msg in r.stderr
    r = _amplify(tmp_path / "d.npy", "-o", tmp_path / "s.obj")
    assert r.returncode == 2 and ".toml" in r.stderr
