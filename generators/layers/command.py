"""``arches-render layers SCENE -o STACKS.npz``: build a scene's layered terrain and save its stacks.

The ``layers`` node ``--node`` (default: the only node of type ``layers``; see
:mod:`.scene_nodes`) is built from its source and its list of operations is
applied in order (with a progress bar over the operations); the edited material
stacks are written atomically to an ``.npz`` file, which a scene can load back
with ``source = "stacks"``.
"""

from __future__ import annotations

from pathlib import Path

from arches_render.commands import Progress, find_node, output_file, scene_argument, writable_output
from arches_render.scene import read_toml
from arches_render.scene.nodes import NodeBuilder

from .scene_nodes import build_stacks


def register(subparsers) -> None:
    p = subparsers.add_parser("layers", help="build a scene's layered terrain and save its material stacks")
    scene_argument(p, "scene file (.toml) with a node of type layers")
    p.add_argument("-o", "--output", required=True, help="output .npz of the edited stacks")
    p.add_argument("--node", default=None, help="name of the layers node (when the scene has several)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    out = writable_output(output_file(args.output, ".npz"))
    scene = Path(args.scene)
    data = read_toml(scene)
    name, table = find_node(data, scene, "layers", args.node)
    bar = Progress(f"layers {name}", "op", args.quiet)
    stacks, _ = build_stacks(table, NodeBuilder(data["nodes"], scene, scene.parent, progress=bar))
    table.finish()
    bar.close()
    stacks.save(out)
    print(f"wrote {out} ({stacks.nx}x{stacks.ny} stacks, {len(stacks.material)} layers, "
          f"{stacks.nbytes()} bytes, effective {stacks.nx}x{stacks.ny}x{stacks.n_levels} voxels)")
    return 0
