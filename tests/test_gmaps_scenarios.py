"""The three evolution scenarios (arch, drilling, cavern), their exports and the CLI.

Each scenario runs with the map's validity check after every event (the event
queue calls :meth:`GMap.check`); these tests then check the topology (Euler
characteristic and genus per volume: the arch ends with genus one), that every
volume stays closed (α2 everywhere; watertight meshes) and free of
self-intersections, that displacements only remove matter, and determinism.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from arches_render.generators.gmaps import scenarios
from arches_render.generators.gmaps.checks import map_mesh, self_intersections, volumes_by_label
from arches_render.generators.gmaps.export import volume_meshes, write_gltf, write_ply_folder

EXPECTED = {
    # label -> genus at the end; events that must have happened
    "arch": ({0: 1, 1: 0}, {"split", "slide", "hole"}),
    "drilling": ({0: 1, 1: 1, 2: 1, 3: 0}, {"hole"}),
    "cavern": ({0: 1, 1: 1, 2: 0}, {"hole"}),
}


@pytest.fixture(scope="module", params=sorted(EXPECTED))
def run(request):
    name = request.param
    vols = []

    def on_step(step, res):
        vols.append(volumes_by_label(res.gmap))
    res = scenarios.run(name, seed=0, on_step=on_step, check=True)
    return name, res, vols


def test_topology_at_the_end(run):
    name, res, _ = run
    genus, kinds = EXPECTED[name]
    res.gmap.check()
    topo = res.gmap.volume_topology()
    assert {t["label"]: t["genus"] for t in topo} == genus
    for t in topo:
        assert t["euler"] == 2 - 2 * t["genus"]
        assert t["V"] - t["E"] + t["F"] == t["euler"]
    assert kinds <= set(res.counts())
    if name == "drilling":
        assert res.counts()["hole"] == 3             # one hole per interface crossed
        (s,) = res.gmap.surface_topology()
        assert s["genus"] == 0                       # shaft ends in the bottom layer: no through hole


def test_volumes_closed_watertight_and_not_self_intersecting(run):
    _, res, _ = run
    g = res.gmap
    ds = g.darts()
    assert np.all(g.alpha[2, ds] != ds)              # every face has its α2 neighbours
    for label, part, mat, mesh in volume_meshes(g, res.materials):
        assert mesh.is_watertight and mesh.is_winding_consistent, (label, part)
        assert mesh.volume > 0
        assert self_intersections(mesh) == [], (label, part)
        assert mat in ("sandstone", "limestone", "basalt")
    assert self_intersections(map_mesh(g)) == []     # and volumes do not cross each other


def test_displacements_only_remove_matter(run):
    name, _, vols = run
    assert len(vols) == scenarios.default_steps(name)
    for before, after in zip(vols, vols[1:]):
        for label in before:
            assert after[label] <= before[label] + 1e-9, (name, label)
    first, last = vols[0], vols[-1]
    assert sum(last.values()) < sum(first.values())


@pytest.mark.parametrize("name", ["arch", "drilling"])
def test_determinism(name):
    a = scenarios.run(name, seed=3, steps=8, check=False)
    b = scenarios.run(name, seed=3, steps=8, check=False)
    c = scenarios.run(name, seed=4, steps=8, check=False)
    for r in (a, b, c):
        r.gmap.compact()
    assert np.array_equal(a.gmap.alpha, b.gmap.alpha) and np.array_equal(a.gmap.attr, b.gmap.attr)
    assert np.array_equal(a.gmap.points, b.gmap.points)
    assert a.gmap.points.shape != c.gmap.points.shape or not np.allclose(a.gmap.points, c.gmap.points)


def test_arch_memory_like_the_paper():
    res = scenarios.run("arch", seed=0, check=False)
    g = res.gmap
    g.compact()
    assert g.dart_bytes() == 20.0
    assert g.nbytes() < 16 * 1024                    # paper §4.1: the arch model < 16 KB


def test_exports(tmp_path):
    res = scenarios.run("arch", seed=0, steps=6, check=False)
    paths = write_ply_folder(res.gmap, tmp_path / "arch", res.materials, {"scenario": "arch"})
    man = json.loads((tmp_path / "arch" / "manifest.json").read_text())
    assert man["scenario"] == "arch" and len(man["volumes"]) == 2
    for v in man["volumes"]:
        m = trimesh.load(tmp_path / "arch" / v["file"])
        assert m.is_watertight and v["watertight"]
    assert paths[-1].name == "manifest.json"
    glb = write_gltf(res.gmap, tmp_path / "arch.glb", res.materials)
    scene = trimesh.load(glb)
    assert len(scene.geometry) == 2
    mats = {g.visual.material.name for g in scene.geometry.values()}
    assert mats == {"sandstone", "limestone"}
    assert not list(tmp_path.glob("**/.*tmp*"))      # atomic writes leave no temporaries


def test_cli_evolve(tmp_path, capsys):
    from arches_render.cli import main
    out = tmp_path / "drill"
    rc = main(["evolve", "drilling", "-o", str(out), "--steps", "5", "--every", "2", "--seed", "1", "-q"])
    assert rc == 0
    man = json.loads((out / "manifest.json").read_text())
    assert man["steps"] == 5 and man["seed"] == 1
    assert (out / "step_0002" / "manifest.json").is_file() and (out / "step_0004" / "manifest.json").is_file()
    assert "wrote" in capsys.readouterr().out
    rc = main(["evolve", "arch", "-o", str(tmp_path / "a.txt"), "-q"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and ".glb" in err[0]
    with pytest.raises(SystemExit) as e:
        main(["evolve", "volcano", "-o", str(tmp_path / "x")])
    assert e.value.code == 2
