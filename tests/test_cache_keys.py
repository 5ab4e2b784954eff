"""The code digest in the rock and block tile cache keys: a tile cached by other code is never served.

Two ways it could fail: a module that shapes the tiles is missing from the digest
(an edit of it would serve stale tiles), or the digest does not follow the bytes
of the modules it lists.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from helpers import REPO

PACKAGES = {
    # package: (module whose imports build the tiles, modules that only read or describe them)
    "rocks": ("tile_cache", set()),
    "blocks": ("tile_cache", set()),
}


def _local_imports(folder: Path, module: str) -> set[str]:
    """Modules of the package that ``module`` imports, transitively (relative imports, any depth)."""
    seen, todo = set(), [module]
    while todo:
        name = todo.pop()
        if name in seen or not (folder / f"{name}.py").is_file():
            continue
        seen.add(name)
        for node in ast.walk(ast.parse((folder / f"{name}.py").read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                if node.module:
                    todo.append(node.module.split(".")[0])
                else:
                    todo += [a.name for a in node.names]
    return seen


def _key_and_modules(package):
    if package == "rocks":
        from arches_render.generators.rocks import tile_cache
        from arches_render.generators.rocks.tile_params import TileParams
        return (lambda: tile_cache.cache_key(TileParams())), tile_cache._CODE_MODULES
    from arches_render.generators.blocks import tile_cache
    return (lambda: tile_cache.TileParams().key()), tile_cache._CODE_MODULES


@pytest.mark.parametrize("package", sorted(PACKAGES))
def test_tile_cache_digest_covers_every_module_that_builds_tiles(package):
    folder = REPO / "generators" / package
    builder, exempt = PACKAGES[package]
    _, modules = _key_and_modules(package)
    needed = _local_imports(folder, builder) - exempt
    # tile_cache itself: the rocks key lists the builders it calls, the blocks key its own file too.
    missing = needed - set(modules) - ({"tile_cache"} if package == "rocks" else set())
    assert not missing, f"{package}: modules that build tiles but are not in the cache key's digest: {missing}"


@pytest.mark.parametrize("package", sorted(PACKAGES))
def test_tile_cache_key_changes_with_each_listed_module(package, monkeypatch):
    key, modules = _key_and_modules(package)
    base = key()
    assert key() == base  # deterministic
    real = Path.read_bytes
    for name in modules:
        target = f"{package}/{name}.py"

        def edited(self, target=target):
            data = real(self)
            return data + b"\n# edited\n" if self.as_posix().endswith(target) else data
        monkeypatch.setattr(Path, "read_bytes", edited)
        assert key() != base, f"{package}: editing {name}.py leaves the tile cache key unchanged"
        monkeypatch.setattr(Path, "read_bytes", real)
    assert key() == base
