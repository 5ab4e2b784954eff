"""Generators: the algorithms that build terrain, rock piles, blocks and topology.

One sub-package per paper; each builds nodes of :mod:`arches_render.field`,
primitive arrays or meshes, and never evaluates geometry with code of its own.
Each declares its scene node types, scene tables, commands and benchmarks in its
``extension.py`` for the registry (:mod:`arches_render.extensions`).

==========================================  ===========  ====================================
paper (``shared/papers/``)                  package      entry module (read first)
==========================================  ===========  ====================================
Paris et al. 2019, *Terrain amplification   ``terrain``  ``amplify`` (pipeline), ``presets``,
with implicit 3D features*                               ``implicit_heightfield``,
(terrain-amplification-2019)                             ``skeletal_set``, ``banded`` (Sec. 7)
Peytavie et al. 2009, *Procedural           ``rocks``    ``aperiodic_tiles`` (corner cubes),
generation of rock piles using aperiodic                 ``scene_piles`` (``[[rock_piles]]``)
tiling* (rock-piles-aperiodic-2009)
Paris et al. 2020, *Modeling rocky scenery  ``blocks``   ``tile_cache`` (tile pipeline),
using implicit blocks*                                   ``block_field``, ``replication``
(implicit-blocks-2020)
Peytavie et al. 2009, *Arches: a framework  ``layers``   ``material_stacks``,
for modeling complex terrains*                           ``convolution_surface``, ``operations``
(arches-layered-terrain-2009; the periodic               (the rocks package holds the
rock tile is in ``rocks``)                               periodic tile: ``periodic_tile``)
Bezin et al., *Topological operations for   ``gmaps``    ``gmap`` (kernel), ``operations``,
geomorphological evolution*                              ``scenarios``
(topological-gmaps-evolution)
==========================================  ===========  ====================================
"""
