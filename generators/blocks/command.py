"""``arches-render blocks SCENE -o TILE.npz``: build (or reuse) the block tile of a scene.

The ``blocks`` node ``--node`` (default: the only, or first in name order, node of
type ``blocks`` under ``[nodes]``) gives the tile parameters (structure, tile size,
spacing, orientation, seed, ...); the tile is taken from the cache or built and
cached (:mod:`.tile_cache`), then written to
``TILE.npz``. A scene can use the file directly with ``tile = "TILE.npz"`` in its
``blocks`` node.
"""

from __future__ import annotations

from pathlib import Path

from arches_render.commands import Progress, UsageError


def _blocks_table(path: Path, name: str | None):
    import tomllib

    from arches_render.scene import SceneError
    from arches_render.scene.validate import Table
    try:
        data = tomllib.loads(path.read_text())
    except OSError as exc:
        raise UsageError(f"{path}: cannot read the scene ({exc.strerror or exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(path, "", f"not valid TOML ({exc})") from None
    nodes = data.get("nodes", {})
    if not isinstance(nodes, dict):
        raise SceneError(path, "nodes", "must be a table of node tables")
    found = sorted(k for k, v in nodes.items() if isinstance(v, dict) and v.get("type") == "blocks")
    if name is None:
        if not found:
            raise UsageError(f"{path}: nodes: the scene has no node of type 'blocks'")
        name = found[0]
    elif name not in found:
        raise UsageError(f"--node must name a 'blocks' node of {path} ({', '.join(found) or 'none'}; "
                         f"got {name!r})")
    return name, Table(nodes[name], path, f"nodes.{name}")


def cmd_blocks(args) -> int:
    import time

    from .scene_nodes import tile_params
    from .tile_cache import cache_dir, cached_tile, save_tile

    out = Path(args.output)
    if out.suffix.lower() != ".npz":
        raise UsageError(f"-o/--output must end in .npz (got {out})")
    scene = Path(args.scene)
    name, table = _blocks_table(scene, args.node)
    if table.has("tile"):
        raise UsageError(f"{scene}: nodes.{name}.tile: the node already uses a tile file")
    params = tile_params(table)
    t0 = time.perf_counter()
    bar = Progress("block tile", "stage", args.quiet)
    tile = cached_tile(params, progress=bar)
    bar.close()
    out.parent.mkdir(parents=True, exist_ok=True)
    save_tile(tile, out)
    st = tile.stats
    print(f"wrote {out} ({params.structure}: {tile.n_blocks} blocks from {st['points']} samples and "
          f"{st['discs']} fractures, {tile.nbytes() / 1e6:.3f} MB; {time.perf_counter() - t0:.1f} s; "
          f"cache {cache_dir()})")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("blocks", help="build and cache the block tile of a scene's blocks node")
    p.add_argument("scene", help="scene file (.toml)")
    p.add_argument("-o", "--output", required=True, help="output tile file (.npz)")
    p.add_argument("--node", default=None, help="name of the blocks node under [nodes] (default: first)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_blocks)
