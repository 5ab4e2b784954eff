"""Rock piles: aperiodic corner-cube rock tiles and the periodic rock tile (rock-piles-aperiodic-2009, arches-layered-terrain-2009)."""
