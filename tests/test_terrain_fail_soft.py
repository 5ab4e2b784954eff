"""Every preset fails soft (issue 22): DEMs where a process finds nothing to carve.

Synthetic DEMs of the kinds real users brought (a low sandy coast with its shelf, a
plateau with escarpments and sinkholes at 200 m cells, a flat plain, no-data
patches) go through ``arches-render amplify`` in this process: exit 0, a one-line
``nothing to carve`` where a process made nothing (printed and in the scene's
header), a scene that ``arches-render info`` reads, and landform cameras where
another preset can make landforms. Each DEM is small (96^2 to 128^2).
"""

from __future__ import annotations

import numpy as np
import pytest


def _grid(n):
    x = np.linspace(-1, 1, n)
    return np.meshgrid(x, x)


def low_coast(n=128):
    """An estuary's shelf 20 m deep rising to dunes 6 m high: half the tile under the sea, no cliff."""
    X, Y = _grid(n)
    return (np.where(Y > 0, 6.0 * Y, 20.0 * Y) + 0.5 * np.sin(5 * X + 2 * Y)).astype(np.float32)


def bluff_coast(n=128):
    """The same shelf with an 8 m bluff at the shore: on a 4 km tile its sea band is thinner than a voxel."""
    X, Y = _grid(n)
    return (np.where(Y > 0, 8.0 * np.clip(Y / 0.012, 0, 1) + 6.0 * Y, 20.0 * Y)
            + 0.5 * np.sin(5 * X + 2 * Y)).astype(np.float32)


def alps(n=96):
    """A plateau 2,700 m above its lowlands, escarpments over one or two 200 m cells, four sinkholes."""
    X, Y = _grid(n)
    edge = 0.45 + 0.08 * np.sin(3 * Y) + 0.05 * np.cos(5 * X)
    r = np.maximum(np.abs(X), np.abs(Y) * 0.8)
    H = 500.0 + 2700.0 * np.clip((edge - r) / 0.05, 0, 1)
    H += 60.0 * np.sin(7 * X + 1) * np.cos(6 * Y) + 40.0 * (X + Y)
    for cx, cy in [(-0.2, -0.15), (0.15, 0.2), (0.2, -0.2), (-0.15, 0.25)]:
        H -= 250.0 * np.exp(-((X - cx) ** 2 + (Y - cy) ** 2) / (2 * 0.05 ** 2))
    return H.astype(np.float32)


def _amplify(capsys, dem, out, *args):
    from arches_render.cli import main
    rc = main(["amplify", str(dem), "-o", str(out), "-q", *map(str, args)])
    text = capsys.readouterr()
    return rc, text.out, text.err


def _info(capsys, scene):
    from arches_render.cli import main
    rc = main(["info", str(scene)])
    text = capsys.readouterr()
    assert rc == 0, text.err
    return text.out


def _header(path):
    return [line[2:] for line in path.read_text().splitlines() if line.startswith("# ")]


def _cameras(path):
    import tomllib
    return list(tomllib.loads(path.read_text())["cameras"])


def _nothing_lines(out):
    return [line for line in out.splitlines() if "nothing to carve" in line]


def test_low_sandy_coast_says_nothing_to_carve_and_writes_a_landscape(tmp_path, capsys):
    np.save(tmp_path / "coast.npy", low_coast())
    out = tmp_path / "coast.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "coast.npy", out, "--cell-size", 20)
    assert rc == 0, err
    assert "Traceback" not in err
    said = _nothing_lines(stdout)
    # The sea finds no cliff; the river finds no valley: one line each, then the terrain alone.
    assert len(said) == 2 and "no coastal cliff" in said[0] and "trying river" in said[0], stdout
    assert "terrain alone" in said[1], stdout
    head = _header(out)
    assert sum("nothing to carve" in line for line in head) == 2, head
    assert _cameras(out) == ["overview"]
    _info(capsys, out)
    assert (tmp_path / "coast.water.ply").exists()  # the sea is still there


def test_thin_sea_band_on_a_large_low_coast_no_longer_crashes(tmp_path, capsys):
    # 4 km tile, 8 m bluff, fine precision: the sea band (~8 m) was thinner than the band
    # mesh's voxel (~10 m) and ended in "the field has no surface inside its bounds".
    np.save(tmp_path / "bluff.npy", bluff_coast())
    out = tmp_path / "bluff.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "bluff.npy", out, "--cell-size", 30, "--precision", 0.05)
    assert rc == 0, err
    assert "preset sea" in stdout, stdout
    assert any(c.startswith("sea_cave_") for c in _cameras(out)), stdout
    _info(capsys, out)


def test_alpine_plateau_at_200_m_gets_landform_cameras(tmp_path, capsys):
    np.save(tmp_path / "alps.npy", alps())
    out = tmp_path / "alps.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "alps.npy", out, "--cell-size", 200)
    assert rc == 0, err
    cams = _cameras(out)
    assert "overview" in cams and len(cams) >= 2, stdout
    _info(capsys, out)


def test_a_preset_that_makes_nothing_hands_over_to_the_next(tmp_path, capsys, monkeypatch):
    # The Alpine DEM: karst chosen for its closed depressions, then 0 tunnels.
    from arches_render.generators.terrain import presets
    spec = presets.PRESETS["karst"]
    monkeypatch.setitem(presets.PRESETS, "karst", presets.Preset(
        spec.description, spec.geology, lambda run: run.timer.step("sinks"), spec.steps))
    np.save(tmp_path / "alps.npy", alps())
    out = tmp_path / "alps.toml"
    # The whole tile (--no-refine): its DEM's choice is karst (a refined crop's is strata).
    rc, stdout, err = _amplify(capsys, tmp_path / "alps.npy", out, "--cell-size", 200, "--no-refine")
    assert rc == 0, err
    said = _nothing_lines(stdout)
    # auto ran every applicable preset: the ranking says karst made nothing, and why,
    # and puts it last (issue 34: presets ranked by what they make).
    ranked = [line for line in stdout.splitlines() if "auto ranked the presets" in line]
    assert len(ranked) == 1 and "karst nothing (no tunnel percolated from the sinks)" in ranked[0], stdout
    assert "Order: by volume (karst, the DEM's choice, makes under 3 landforms)" in ranked[0], stdout
    kept = next(line.split()[3] for line in stdout.splitlines() if line.startswith("arches-render amplify: preset "))
    assert kept in ("strata", "hoodoos", "river"), stdout
    cams = _cameras(out)
    assert len(cams) >= 2 and cams[-1] == "overview", cams
    head = _header(out)
    assert ranked[0].split(": ", 2)[2] in head, head
    assert [line for line in head if line.startswith("nothing to carve")] == [line.split(": ", 2)[2] for line in said]
    assert any(line.startswith(f"Preset {kept}: ") for line in head), head
    # Only the kept attempt's data are published (the others' were in work folders, removed).
    published = sorted(p.name for p in tmp_path.iterdir() if p.suffix in (".npy", ".npz", ".ply"))
    text = out.read_text()
    assert all(name in text or name == "alps.npy" for name in published), (published, text[:2000])
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # work folders removed


def test_preset_candidates_put_cliff_landforms_after_the_choice():
    from arches_render.generators.terrain.fallback import preset_candidates
    names = [name for name, _ in preset_candidates(alps().astype(np.float64), 200.0)]
    assert names[0] == "karst" and names[1] == "strata" and "sea" not in names, names
    coast = [name for name, _ in preset_candidates(low_coast().astype(np.float64), 20.0)]
    assert coast[0] == "sea" and "karst" not in coast and "strata" not in coast, coast


@pytest.mark.parametrize("preset", ["auto", "sea", "river", "karst", "hoodoos", "strata"])
def test_flat_plain_says_nothing_to_carve_once(tmp_path, capsys, preset):
    np.save(tmp_path / "plain.npy", np.full((96, 96), 120.0, np.float32))
    out = tmp_path / "plain.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "plain.npy", out, "--cell-size", 10, "--preset", preset)
    assert rc == 0, err
    said = _nothing_lines(stdout)
    assert len(said) == 1 and "flat DEM" in said[0], stdout
    assert any("nothing to carve: flat DEM" in line for line in _header(out))
    assert _cameras(out) == ["overview"]
    _info(capsys, out)


def test_a_chosen_preset_that_finds_nothing_says_how_to_get_more(tmp_path, capsys):
    x = np.linspace(0.0, 30.0, 96)
    np.save(tmp_path / "tilted.npy", np.tile(x, (96, 1)).astype(np.float32))  # a 3 % slope
    out = tmp_path / "tilted.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "tilted.npy", out, "--cell-size", 10, "--preset", "strata")
    assert rc == 0, err
    said = _nothing_lines(stdout)
    assert len(said) == 1 and "no escarpment" in said[0] and "--preset auto" in said[0], stdout
    assert "preset strata" in stdout and "auto ranked" not in stdout  # the user's preset runs alone
    _info(capsys, out)


@pytest.mark.parametrize("preset", ["auto", "sea", "river", "karst", "hoodoos", "strata"])
def test_tiny_dem_every_preset_exits_0(tmp_path, capsys, preset):
    np.save(tmp_path / "tiny.npy", np.array([[0, 5, 0, 2], [5, 20, 5, 1], [0, 5, 0, 3]], np.float32))
    out = tmp_path / "tiny.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "tiny.npy", out, "--cell-size", 10, "--preset", preset)
    assert rc == 0, err
    _info(capsys, out)


def test_no_data_patches_are_filled_and_amplified(tmp_path, capsys):
    H = alps()
    H[10:24, 30:50] = np.nan  # a void on the plateau's rim
    H[60:66, 5:70] = np.nan  # a stripe across the escarpment
    np.save(tmp_path / "voids.npy", H)
    out = tmp_path / "voids.toml"
    rc, stdout, err = _amplify(capsys, tmp_path / "voids.npy", out, "--cell-size", 200)
    assert rc == 0, err
    assert "filled 670 no-data cells" in stdout, stdout
    assert any(line.startswith("DEM: filled 670 no-data cells") for line in _header(out))
    assert len(_cameras(out)) >= 2, stdout
    _info(capsys, out)
