"""Rock piles (Peytavie et al. 2009, *Procedural generation of rock piles using aperiodic tiling*).

Aperiodic corner-cube rock tiles (:mod:`.aperiodic_tiles`) and the periodic rock
tile of Arches (:mod:`.periodic_tile`), cached on disk (:mod:`.tile_cache`) and
instanced on a support object as the ``[[rock_piles]]`` scene table
(:mod:`.scene_piles`); the ``rocks`` command builds and caches the tiles.
"""

__all__ = ["NODE_TYPES", "SCENE_TABLES", "COMMANDS", "BENCHMARKS"]

from . import benchmarks, command
from .scene_piles import parse_rock_pile

NODE_TYPES: dict = {}
SCENE_TABLES = {"rock_piles": parse_rock_pile}
COMMANDS = (command,)
BENCHMARKS = benchmarks.BENCHMARKS
