"""Implicit blocks (Paris et al. 2020, *Modeling rocky scenery using implicit blocks*).

A periodic tile of fractured convex blocks (:mod:`.tile_cache`: Poisson samples,
fracture discs of a structure type, clusters, hull planes) replicated over a host
field (:mod:`.replication`, :mod:`.block_field`): the ``blocks`` node type
(:mod:`.scene_nodes`) and the ``blocks`` command.
"""
