"""``arches-render blocks SCENE -o TILE.npz``: build (or reuse) the block tile of a scene.

The ``blocks`` node ``--node`` (default: the only node of type ``blocks`` under
``[nodes]``) gives the tile parameters (structure, tile size, spacing, orientation,
seed, ...); the tile is taken from the cache or built and cached
(:mod:`.tile_cache`), then written to ``TILE.npz``. A scene can use the file
directly with ``tile = "TILE.npz"`` in its ``blocks`` node.
"""

from __future__ import annotations

import time
from pathlib import Path

from arches_render.cache import cache_dir
from arches_render.commands import Progress, UsageError, find_node, output_file, scene_argument, writable_output
from arches_render.scene import read_toml

from .scene_nodes import tile_params
from .tile_cache import cached_tile, save_tile


def register(subparsers) -> None:
    p = subparsers.add_parser("blocks", help="build and cache the block tile of a scene's blocks node")
    scene_argument(p)
    p.add_argument("-o", "--output", required=True, help="output tile file (.npz)")
    p.add_argument("--node", default=None, help="name of the blocks node under [nodes] (when the scene has several)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    out = writable_output(output_file(args.output, ".npz"))
    scene = Path(args.scene)
    name, table = find_node(read_toml(scene), scene, "blocks", args.node)
    if table.has("tile"):
        raise UsageError(f"{scene}: nodes.{name}.tile: the node already uses a tile file")
    params = tile_params(table)
    t0 = time.perf_counter()
    bar = Progress("block tile", "stage", args.quiet)
    tile = cached_tile(params, progress=bar)
    bar.close()
    save_tile(tile, out)
    st = tile.stats
    print(f"wrote {out} ({params.structure}: {tile.n_blocks} blocks from {st['points']} samples and "
          f"{st['discs']} fractures, {tile.nbytes() / 1e6:.3f} MB; {time.perf_counter() - t0:.1f} s; "
          f"cache {cache_dir('blocks')})")
    return 0
