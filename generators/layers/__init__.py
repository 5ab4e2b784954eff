"""Layered terrain: material stacks, convolution surface, stabilization and editing tools (arches-layered-terrain-2009)."""
