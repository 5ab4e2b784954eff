"""Register the Python Mitsuba plugins of arches-render for the active variant."""

from __future__ import annotations


def register_all() -> None:
    """Register ``implicit_path`` (integrator) and ``triplanar`` (BSDF)."""
    from .render import integrator
    integrator.register()
    from .materials import triplanar
    triplanar.register()
