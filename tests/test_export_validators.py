"""Exports that other tools accept: Khronos's glTF validator and OpenUSD's validators.

``bash setup.sh test`` installs the glTF validator (npm ``gltf-validator``) into
``.venv/node``; OpenUSD's validators come with ``usd-core`` (``UsdValidation``, what
``usdchecker`` runs). Each check is also shown failing on a file broken on purpose,
so a validator that passes everything would fail these tests.
"""

from __future__ import annotations

import json
import shutil
import struct
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
VALIDATOR = Path(sys.prefix) / "node" / "node_modules"
# Validate a .glb (its external resources beside it) and print the report's issue summary.
NODE_SCRIPT = r"""
const fs = require("fs"), path = require("path");
const validator = require("gltf-validator");
const file = process.argv[1];
const external = (uri) => new Promise((ok, fail) => {
  try { ok(new Uint8Array(fs.readFileSync(path.join(path.dirname(file), decodeURIComponent(uri))))); }
  catch (e) { fail(e.toString()); }
});
validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {externalResourceFunction: external})
  .then((r) => console.log(JSON.stringify(r.issues)))
  .catch((e) => { console.error(String(e)); process.exit(3); });
"""


def _gltf_issues(path: Path) -> dict:
    assert (VALIDATOR / "gltf-validator").is_dir(), "bash setup.sh test installs gltf-validator into .venv/node"
    node = shutil.which("node")
    assert node, "bash setup.sh test installs nodejs"
    out = subprocess.run([node, "-e", NODE_SCRIPT, str(path)], capture_output=True, text=True, timeout=300,
                         env={"NODE_PATH": str(VALIDATOR), "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def _mesh(args):
    out = subprocess.run([sys.executable, "-m", "arches_render.cli", "mesh", *map(str, args), "-q"],
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    return out


def test_textured_glb_passes_khronos_gltf_validator(tmp_path):
    glb = tmp_path / "default.glb"
    _mesh([REPO / "scenes" / "default.toml", "-o", glb, "--voxel", "4", "--uv", "--bake", "--texture-size", "256"])
    issues = _gltf_issues(glb)
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"][:5]

    # Broken on purpose: an index past the vertex count makes the validator fail.
    data = bytearray(glb.read_bytes())
    json_len = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + json_len])
    count = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["count"]
    doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["count"] = count // 2
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    broken = data[:12] + struct.pack("<I", len(text)) + data[16:20] + text + data[20 + json_len:]
    struct.pack_into("<I", broken, 8, len(broken))
    bad = tmp_path / "broken.glb"
    bad.write_bytes(bytes(broken))
    assert _gltf_issues(bad)["numErrors"] > 0


def _usd_errors(path: Path) -> list:
    from pxr import Usd, UsdValidation
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    return [e for e in context.Validate(Usd.Stage.Open(str(path)))
            if e.GetType() == UsdValidation.ValidationErrorType.Error]


def test_textured_usd_stage_passes_openusd_validators(tmp_path):
    stage = tmp_path / "default.usda"
    _mesh([REPO / "scenes" / "default.toml", "-o", stage, "--voxel", "4", "--uv", "--bake", "--texture-size", "128"])
    errors = _usd_errors(stage)
    assert not errors, [e.GetMessage() for e in errors[:5]]

    # Broken on purpose: the texture coordinate reader's name as a token (UsdPreviewSurface
    # before 2.5, what this exporter wrote until the validators said otherwise).
    text = stage.read_text()
    assert 'string inputs:varname = "st"' in text
    bad = tmp_path / "broken.usda"
    bad.write_text(text.replace('string inputs:varname = "st"', 'token inputs:varname = "st"'))
    for png in tmp_path.glob("default_*.png"):
        shutil.copy(png, tmp_path / png.name.replace("default_", "broken_"))
    assert any("varname" in e.GetMessage() for e in _usd_errors(bad))


def test_textured_export_is_one_atlas_over_chunk_pieces(tmp_path):
    """The export charts the mesh in pieces (one atlas): every triangle of the whole
    polygonization is there, and the UVs lie in [0, 1]."""
    import trimesh
    out = tmp_path / "default.glb"
    _mesh([REPO / "scenes" / "default.toml", "-o", out, "--voxel", "4", "--uv", "--texture-size", "256"])
    plain = tmp_path / "plain.ply"
    _mesh([REPO / "scenes" / "default.toml", "-o", plain, "--voxel", "4"])
    textured = trimesh.load(out, force="mesh", process=False)
    whole = trimesh.load(plain, process=False)
    assert len(textured.faces) == len(whole.faces)
    uv = textured.visual.uv
    assert uv.min() >= 0.0 and uv.max() <= 1.0
    assert abs(textured.area - whole.area) < 1e-3 * whole.area
