"""Generators: the algorithms that build terrain, rock piles, blocks and topology.

One sub-package per paper (``terrain/``, ``rocks/``, ``blocks/``, ``layers/``,
``gmaps/``); each builds nodes of :mod:`arches_render.field`, primitive arrays or
meshes, and never evaluates geometry with code of its own.
"""
