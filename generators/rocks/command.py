"""``arches-render rocks SCENE -o TILES.npz``: build (or reuse) the rock tiles of a scene's pile.

The tiles of ``[[rock_piles]]`` entry ``--pile`` (default 0) are taken from the
tile cache or built and cached (see :mod:`.tile_cache`), then written to ``TILES.npz``
(:class:`~arches_render.generators.rocks.rock_store.RockStore` arrays). A later
render of the scene reuses the cache.
"""

from __future__ import annotations

import time

from arches_render.atomic import atomic_path
from arches_render.commands import Progress, UsageError, bounded_int, output_file, scene_argument, writable_output
from arches_render.scene import load_scene

from .tile_cache import cache_key, load_or_build


def register(subparsers) -> None:
    p = subparsers.add_parser("rocks", help="build and cache the rock tiles of a scene's [[rock_piles]]")
    scene_argument(p)
    p.add_argument("-o", "--output", required=True, help="output tile file (.npz)")
    p.add_argument("--pile", type=bounded_int("--pile", 0, 1023), default=0,
                   help="index of the [[rock_piles]] entry (default 0)")
    p.add_argument("--workers", type=bounded_int("--workers", 1, 64), default=None,
                   help="build processes (default: CPU count)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    out = writable_output(output_file(args.output, ".npz"))
    desc = load_scene(args.scene)
    piles = desc.rock_piles
    if not piles:
        raise UsageError(f"{args.scene}: rock_piles: the scene has no [[rock_piles]] entry")
    if args.pile >= len(piles):
        raise UsageError(f"--pile must be in [0, {len(piles) - 1}] for {args.scene} (got {args.pile})")
    pile = piles[args.pile]
    t0 = time.perf_counter()
    bar = Progress("rock tiles", "region", args.quiet)
    store, source = load_or_build(pile.params, progress=bar, workers=args.workers)
    bar.close()
    elapsed = time.perf_counter() - t0
    with atomic_path(out) as tmp:
        with open(tmp, "wb") as f:
            store.save(f)
    what = {"built": "built", "disk": "from cache", "memory": "from cache"}[source]
    print(f"wrote {out} ({len(store)} stones, {int(store.meta['triangles'])} triangles, "
          f"{pile.params.tiling}, {what} in {elapsed:.1f} s; cache key {cache_key(pile.params)})")
    return 0
