"""Imports point one way: the field core loads no renderer, scene loader, mesher, command or generator.

Each check runs in a fresh interpreter, so that modules imported by other tests of
this session cannot hide an import.
"""

from __future__ import annotations

import json
import subprocess
import sys

from helpers import REPO

# Builds and evaluates a small tree through the public field API, then lists the
# arches_render modules the interpreter has loaded.
FIELD_ONLY = """
import json, sys
import numpy as np
from arches_render import field as F
tree = F.Difference(
    F.Blend(F.Heightfield(np.outer(np.linspace(0, 1, 9), np.ones(9)), (-4, -4, 4, 4)),
            F.Displace(F.Capsule([0, 0, 0], [2, 0, 1], 0.8), 0.1, 1.0, 2, seed=3), radius=0.5),
    F.Transform.translate(F.Sphere([0, 0, 0], 1.0), [1, 1, 0]))
values = F.evaluate(tree, np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 9.0]]))
print(json.dumps({"values": values.tolist(),
                  "modules": sorted(m for m in sys.modules if m.startswith("arches_render"))}))
"""

FORBIDDEN = ("arches_render.render", "arches_render.scene", "arches_render.commands", "arches_render.mesh",
             "arches_render.generators", "arches_render.materials", "arches_render.cli",
             "arches_render.extensions")


def test_field_imports_nothing_above_it():
    proc = subprocess.run([sys.executable, "-c", FIELD_ONLY], cwd=REPO, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    inside, outside = out["values"]
    assert inside > 0 > outside  # the tree was really built and evaluated
    loaded = out["modules"]
    assert "arches_render.field.node" in loaded
    leaked = [m for m in loaded if m.startswith(FORBIDDEN)]
    assert not leaked, f"importing arches_render.field loaded {leaked}"
