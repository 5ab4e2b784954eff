"""Topological terrain evolution on 3-G-maps (topological-gmaps-evolution)."""
