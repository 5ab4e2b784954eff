"""Layered terrain (Peytavie et al. 2009, *Arches: a framework for modeling complex terrains*).

Material stacks (:mod:`.material_stacks`), their convolution surface
(:mod:`.convolution_surface`), stabilization by the angle of repose and the
editing tools sculpt, sweep, deposit and erode (:mod:`.operations`): the
``layers`` and ``layers_ratio`` node types (:mod:`.scene_nodes`) and the
``layers`` command.
"""
