"""Terrain amplification (Paris et al. 2019, *Terrain amplification with implicit 3D features*).

A DEM becomes an implicit heightfield; a geology (resistance) tree and erosion
processes (sea, river, karst, hoodoos, strata) add caves, arches and overhangs as
skeletal primitive sets; :mod:`.banded` polygonizes such trees in a band around
the surface (Sec. 7); :mod:`.far_field` continues a heightfield tile to the horizon
(the ``[[far_field]]`` scene table). Entry points: :func:`.amplify.amplify` and the presets of :mod:`.presets`; the
``amplify`` command; node types in :mod:`.scene_nodes`.
"""
