"""Terrain generators (heightmaps now; terrain amplification builds here next)."""
