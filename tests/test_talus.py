"""Fallen blocks at the feet of cliffs (issue 34): the apron from the DEM, and the
``strata`` preset's opt-in blocks resting on it."""
from __future__ import annotations

import math

import numpy as np

from helpers import variant
from robust_helpers import cli_out

variant()

from arches_render.field import evaluate  # noqa: E402
from arches_render.generators.terrain.amplify import amplify  # noqa: E402
from arches_render.generators.terrain.talus import PEAK, STEEP_DEG, talus_apron  # noqa: E402

CELL = 10.0


def _mesa(n=96, top=80.0):
    """A round mesa ``top`` m tall, 500 m across, its wall steeper than 60 degrees."""
    x = (np.arange(n) - (n - 1) / 2) * CELL
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X, Y)
    return (1000.0 + top / (1.0 + np.exp((r - 250.0) / 8.0))).astype(np.float32)


def _steep(H):
    gy, gx = np.gradient(H.astype(np.float64), CELL)
    return np.hypot(gx, gy) > math.tan(math.radians(STEEP_DEG))


def test_apron_lies_below_the_cliffs_and_thins_out_away_from_them():
    H = _mesa()
    n = H.shape[0]
    ext = (-(n - 1) / 2 * CELL, -(n - 1) / 2 * CELL, (n - 1) / 2 * CELL, (n - 1) / 2 * CELL)
    apron = talus_apron(H, ext, CELL, reach=60.0, block=4.0, border=40.0)
    assert apron is not None
    # The grid spans the box exactly: map it back onto the DEM's samples.
    x0, y0, _, x1, y1, _ = apron.box
    ny, nx = apron.density.shape
    xs = x0 + (np.arange(nx) + 0.5) * (x1 - x0) / nx
    ys = y0 + (np.arange(ny) + 0.5) * (y1 - y0) / ny
    X, Y = np.meshgrid(xs, ys)
    i = np.rint((X - ext[0]) / CELL).astype(int)
    j = np.rint((Y - ext[1]) / CELL).astype(int)
    d = apron.density
    r = np.hypot(X, Y)
    steep = _steep(H)[j, i]
    assert d.max() <= PEAK and d.min() >= 0.0
    assert not np.any(d[steep] > 0)                  # never on the wall
    assert not np.any(d[r < 200.0] > 0)              # nor on the mesa's top
    assert np.all(d[(r > 275.0) & (r < 285.0)] > 0)  # all round its foot (the wall ends at 269 m)
    assert not np.any(d[r > 340.0] > 0)              # and not beyond the reach
    # Thinner farther out: the mean density by ring falls.
    rings = [d[(r > a) & (r < a + 15.0)].mean() for a in (270.0, 290.0, 310.0)]
    assert rings[0] > rings[1] > rings[2]
    flat = np.full((32, 32), 5.0, np.float32)
    assert talus_apron(flat, (0, 0, 310, 310), CELL, 60.0, 4.0, 40.0) is None


def test_strata_fallen_blocks_rest_at_the_foot_of_the_cliffs_unless_refused(tmp_path):
    H = _mesa()
    plain = amplify(H, CELL, "strata", 4, tmp_path / "plain", options={"fallen_blocks": False})
    assert "talus" not in plain.tables and plain.landforms is None
    res = amplify(H, CELL, "strata", 4, tmp_path / "talus")
    n = res.stats["fallen_blocks"]
    assert n > 20 and any(note.startswith(f"fallen blocks: {n} blocks") for note in res.stats["notes"])
    assert res.tables["world"]["children"] == ["talus"]
    # Close shots and the presets' ranking measure the cliffs, not the blocks: the same
    # tree as without them.
    assert res.landforms is not None and res.landforms.kind == "erosion"
    p = np.random.default_rng(0).uniform([-400, -400, 990], [400, 400, 1090], (20000, 3))
    assert np.array_equal(evaluate(res.landforms, p), evaluate(plain.root, p))
    talus = res.root.children[0]
    blocks = talus.children[1]
    c = blocks.tile.centroid[blocks.presence.blocks] + blocks.presence.cells * blocks.tile.size
    r = np.hypot(c[:, 0], c[:, 1])
    # Outside the wall (steep out to r = 269 m), within the reach (half the cliff, at
    # least 2 cells), give or take the density grid's half cell.
    assert np.all(r > 269.0 - 7.1) and np.all(r < 269.0 + 60.0 + 7.1), (r.min(), r.max())
    # Resting on the ground (the host field is about the height above it, negated): the
    # blocks' centres lie within a block or two of it, not up the wall or in the air.
    depth = evaluate(talus.children[0], c)
    assert np.all(np.abs(depth) < 2.0 * res.tables["talus"]["spacing"]), np.abs(depth).max()
    # None hovers over a hollow: every block has three anchors within CONTACT b of the
    # ground or in it (the majority of anchors in the distance range alone let blocks
    # float up to 0.3 b above it).
    from arches_render.generators.terrain.talus import CONTACT
    A = blocks.tile.anchors[blocks.presence.blocks] + (blocks.presence.cells * blocks.tile.size)[:, None, :]
    f = evaluate(talus.children[0], A.reshape(-1, 3)).reshape(A.shape[:2])
    assert np.all((f >= -CONTACT * res.tables["talus"]["spacing"]).sum(-1) >= 3)
    again = amplify(H, CELL, "strata", 4, tmp_path / "again")
    b2 = again.root.children[0].children[1]
    assert np.array_equal(b2.presence.cells, blocks.presence.cells)
    assert np.array_equal(b2.presence.blocks, blocks.presence.blocks)


def test_cli_writes_the_blocks_bare_and_says_so_unless_refused(tmp_path, capsys):
    import tomllib

    from arches_render.scene import load_scene
    np.save(tmp_path / "mesa.npy", _mesa())
    out = tmp_path / "mesa.toml"
    rc, stdout, err = cli_out(capsys, "amplify", tmp_path / "mesa.npy", "-o", out, "--cell-size", "10",
                              "--preset", "strata", "-q")
    assert rc == 0, err
    text = out.read_text()
    assert "# Note: fallen blocks: " in text and "fallen blocks: " in stdout
    doc = tomllib.loads(text)
    assert doc["nodes"]["talus"]["type"] == "blocks" and (tmp_path / doc["nodes"]["talus"]["density"]).exists()
    look = doc["materials"]["landscape"]
    assert {m["layer"] for m in look["masks"]} == {"grass", "sand"}
    assert look["cavity"]["node"] == doc["nodes"]["talus"]["host"]
    blocks = [n for n in load_scene(out).field.walk() if n.kind == "blocks_field"]
    assert len(blocks) == 1 and blocks[0].n_present > 20
    rc, stdout, err = cli_out(capsys, "amplify", tmp_path / "mesa.npy", "-o", out, "--cell-size", "10",
                              "--preset", "strata", "--no-fallen-blocks", "-q")
    assert rc == 0, err
    text = out.read_text()
    assert "--sea-level 0 --no-fallen-blocks" in text and "talus" not in tomllib.loads(text)["nodes"]


def _crossing(field, lo, hi, steps=40):
    """Points where ``field`` changes sign on the segments ``lo -> hi`` (inside at ``lo``), by bisection."""
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        inside = evaluate(field, mid) > 0
        lo, hi = np.where(inside[:, None], mid, lo), np.where(inside[:, None], hi, mid)
    return 0.5 * (lo + hi)


def test_fallen_blocks_carry_the_beds_of_the_cliff_above_them(tmp_path, capsys):
    """On a block's top the material's colour is a bed of the wall above the block, not the
    bed at the block's own height (every block at the foot came out in that one colour); the
    wall itself keeps its beds."""
    import drjit as dr
    import mitsuba as mi

    from arches_render import tomlfile
    from arches_render.tomlfile import toml_text
    from arches_render.materials.masks import PALETTES, strata_index
    from arches_render.render.renderer import load_materials
    from arches_render.scene import load_scene
    np.save(tmp_path / "mesa.npy", _mesa())
    out = tmp_path / "mesa.toml"
    rc, _, err = cli_out(capsys, "amplify", tmp_path / "mesa.npy", "-o", out, "--cell-size", "10",
                         "--preset", "strata", "-q")
    assert rc == 0, err
    doc = tomlfile.load(out)
    mat = doc["materials"]["landscape"]
    # The albedo is then the palette colour itself: no texture, detail or cavity.
    mat["overrides"]["rock.texture"] = ""
    mat["detail"] = False
    mat.pop("cavity", None)
    out.write_text(toml_text(doc))
    desc = load_scene(out)
    bsdf = load_materials(desc)["landscape"]
    strata = mat["strata"]
    palette = np.array(PALETTES[strata["palette"]])
    geology = desc.material_nodes["landscape"]["strata"]
    root = desc.field
    talus = root.children[0]
    block = doc["nodes"]["talus"]["spacing"]

    def albedo(p, n):
        si = dr.zeros(mi.SurfaceInteraction3f, len(p))
        si.p = mi.Point3f(p.T.astype(np.float32))
        si.sh_frame = mi.Frame3f(mi.Vector3f(n.T.astype(np.float32)))
        si.wi, si.t = si.sh_frame.n, mi.Float(1.0)
        return np.array(bsdf.albedo(si)).T.reshape(-1, 3)

    def bed(colours):
        """Palette index of each colour (it must be one of them: atol 1e-5, float32 sums)."""
        d = np.abs(colours[:, None, :] - palette[None]).max(-1)
        assert np.all(d.min(1) < 1e-5), d.min(1).max()
        return d.argmin(1)

    # Block tops: down from 2 blocks above each block's centre to the centre (inside it),
    # kept where the top stands a quarter block above the ground (a bare top, in the gate).
    blocks = talus.children[1]
    c = blocks.tile.centroid[blocks.presence.blocks] + blocks.presence.cells * blocks.tile.size
    top = _crossing(root, c, c + [0.0, 0.0, 2.0 * block])
    top = top[evaluate(talus.children[0], top) < -0.3 * block]
    assert len(top) > 20
    up = np.tile([0.0, 0.0, 1.0], (len(top), 1))
    got = bed(albedo(top, up))
    own = strata_index(evaluate(geology, top), strata["levels"])
    # The beds of the wall above the blocks (foot at 1000 m, top at 1080 m).
    col = np.concatenate([np.c_[top[:, :2], np.full(len(top), z)] for z in np.linspace(1000.0, 1080.0, 33)])
    wall = set(strata_index(evaluate(geology, col), strata["levels"]).tolist())
    assert set(got.tolist()) <= wall
    # Not the block's own bed: at their own heights the blocks show one or two beds, each
    # block mostly the one it rests in; lifted, at least two beds and most blocks another.
    assert len(set(got.tolist())) >= 2 and np.mean(got != own) > 0.5, (np.bincount(got), np.mean(got != own))
    # The wall keeps the bed at its own height (the gate is off the blocks).
    ang = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
    z = np.repeat([1020.0, 1040.0, 1060.0], len(ang))
    a = np.tile(ang, 3)
    d = np.c_[np.cos(a), np.sin(a), np.zeros_like(a)]
    p = _crossing(root, d * 200.0 + np.c_[0 * a, 0 * a, z], d * 300.0 + np.c_[0 * a, 0 * a, z])
    assert np.array_equal(bed(albedo(p, d)), strata_index(evaluate(geology, p), strata["levels"]))
