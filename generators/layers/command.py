"""``arches-render layers SCENE -o STACKS.npz``: build a scene's layered terrain and save its stacks.

The ``layers`` node of the scene (see :mod:`.scene_nodes`)
is built from its source and its list of operations is applied in order (with a
progress bar over the operations); the edited material stacks are written
atomically to an ``.npz`` file, which a scene can load back with
``source = "stacks"``.
"""

from __future__ import annotations

from pathlib import Path

from arches_render.commands import Progress, UsageError


def cmd_layers(args) -> int:
    import sys

    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    from arches_render.scene.errors import SceneError
    from arches_render.scene.nodes import NodeBuilder
    from arches_render.scene.validate import Table

    scene = Path(args.scene)
    out = Path(args.output)
    if out.suffix.lower() != ".npz":
        raise UsageError(f"-o/--output must end in .npz (got {out})")
    try:
        with open(scene, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise SceneError(scene, "", "no such scene file") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(scene, "", f"not valid TOML: {exc}") from None
    except OSError as exc:
        raise SceneError(scene, "", f"cannot read: {exc.strerror}") from None
    nodes = data.get("nodes", {})
    if not isinstance(nodes, dict):
        raise SceneError(scene, "nodes", "must be a table of named node tables")
    names = sorted(n for n, t in nodes.items() if isinstance(t, dict) and t.get("type") == "layers")
    if not names:
        raise SceneError(scene, "nodes", "has no node of type layers")
    if args.node is None:
        if len(names) > 1:
            raise UsageError(f"{scene} has several layers nodes ({', '.join(names)}): choose one with --node")
        name = names[0]
    elif args.node not in names:
        raise UsageError(f"--node must name a layers node of {scene} ({', '.join(names)}; got {args.node!r})")
    else:
        name = args.node

    from arches_render.backend import set_variant
    set_variant()
    from .scene_nodes import build_stacks

    builder = NodeBuilder(nodes, scene, scene.parent)
    bar = Progress(f"layers {name}", "op", args.quiet)
    builder.layers_progress = bar
    table = Table(nodes[name], scene, f"nodes.{name}")
    stacks, _ = build_stacks(table, builder)
    table.used.add("type")
    table.finish()
    bar.close()
    out.parent.mkdir(parents=True, exist_ok=True)
    stacks.save(out)
    print(f"wrote {out} ({stacks.nx}x{stacks.ny} stacks, {len(stacks.material)} layers, "
          f"{stacks.nbytes()} bytes, effective {stacks.nx}x{stacks.ny}x{stacks.n_levels} voxels)")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("layers", help="build a scene's layered terrain and save its material stacks")
    p.add_argument("scene", help="scene file (.toml) with a node of type layers")
    p.add_argument("-o", "--output", required=True, help="output .npz of the edited stacks")
    p.add_argument("--node", default=None, help="name of the layers node (when the scene has several)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_layers)
