"""Rock piles (Peytavie et al. 2009, *Procedural generation of rock piles using aperiodic tiling*).

Aperiodic corner-cube rock tiles (:mod:`.aperiodic_tiles`) and the periodic rock
tile of Arches (:mod:`.periodic_tile`), cached on disk (:mod:`.tile_cache`) and
instanced on a support object as the ``[[rock_piles]]`` scene table
(:mod:`.scene_piles`); the ``rocks`` command builds and caches the tiles.
"""
