"""Registration of our Python Mitsuba plugins, once per variant, where rendering starts.

``implicit_path`` (:mod:`arches_render.render.integrator`) and ``triplanar``
(:mod:`arches_render.materials.triplanar`) are Python classes bound to the
active variant; Mitsuba keeps a plugin registry per variant, so they are
registered for each variant the process renders with. Scene assembly
(:func:`arches_render.render.renderer.build_scene`, ``load_materials``) calls
:func:`ensure_registered`; selecting a variant (:mod:`arches_render.backend`)
registers nothing, so building or evaluating a field never loads the renderer.
"""

from __future__ import annotations

from ..backend import variant
from ..materials import triplanar
from . import integrator

__all__ = ["ensure_registered"]

_REGISTERED: set[str] = set()


def ensure_registered() -> str:
    """Register ``implicit_path`` and ``triplanar`` for the active variant (once).

    Selects the default variant first when none is active.

    Returns
    -------
    str
        The active variant.
    """
    name = variant()
    if name not in _REGISTERED:
        integrator.register()
        triplanar.register()
        _REGISTERED.add(name)
    return name
