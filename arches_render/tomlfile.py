"""Reading TOML: the one place of the Python 3.10 fallback to ``tomli``.

``tomllib`` is in the standard library from Python 3.11; ``pyproject.toml`` allows
3.10 and installs ``tomli`` (the same parser) there. Scene files go through
:func:`arches_render.scene.read_toml`, which turns these errors into one-line
scene errors; material presets read their files here directly.
"""

from __future__ import annotations

import sys

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["TOMLDecodeError", "load", "loads"]

TOMLDecodeError = tomllib.TOMLDecodeError


def load(path) -> dict:
    """Parse the TOML file ``path``.

    Raises
    ------
    OSError
        When the file cannot be read.
    TOMLDecodeError
        When it is not valid TOML.
    """
    with open(path, "rb") as f:
        return tomllib.load(f)


def loads(text: str) -> dict:
    """Parse TOML text (raises :data:`TOMLDecodeError`)."""
    return tomllib.loads(text)
