"""What the ``gmaps`` generator adds to arches-render (:mod:`arches_render.extensions`).

Kept out of the package's ``__init__`` so that importing one of its modules
(a worker process unpickling a task, a script) does not import the CLI, the
scene loader with it. Benchmarks stay in ``benchmarks.py`` (``BENCHMARKS``), imported
only by ``benchmarks/run.py``.
"""

from __future__ import annotations

__all__ = ["NODE_TYPES", "SCENE_TABLES", "COMMANDS"]


NODE_TYPES: dict = {}
SCENE_TABLES: dict = {}
# Module names, imported by the CLI only: a render does not pay for the commands' imports.
COMMANDS = ("command",)
