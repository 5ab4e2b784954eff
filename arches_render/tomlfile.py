"""Reading and writing TOML: the one place of the Python 3.10 fallback to ``tomli``, and
the writer of generated scene files (:func:`toml_text`).

``tomllib`` is in the standard library from Python 3.11; ``pyproject.toml`` allows
3.10 and installs ``tomli`` (the same parser) there. Scene files go through
:func:`arches_render.scene.read_toml`, which turns these errors into one-line
scene errors; material presets read their files here directly.
"""

from __future__ import annotations

import json
import math
import re
import sys

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["TOMLDecodeError", "load", "loads", "toml_text"]

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


_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k):
    return k if _BARE.match(k) else json.dumps(k)


def _value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if not math.isfinite(v):
            raise ValueError(f"cannot write a non-finite number ({v}) to a scene file")
        return repr(v)  # shortest exact form: the file rebuilds the very tree that was made
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a valid TOML basic string
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to a scene file")


def toml_text(doc, header=""):
    """TOML text of a scene document.

    Parameters
    ----------
    doc : dict
        Top-level keys map to tables (dicts of scalars, arrays and inline tables),
        arrays of tables (lists of dicts: ``[[lights]]``), or, for ``nodes`` and
        ``materials`` and ``cameras``, dicts of named tables (``[nodes.NAME]``).
    header : str
        Comment lines put first (without the ``#``).

    Returns
    -------
    str
    """
    out = [f"# {line}".rstrip() for line in header.splitlines()]
    for name, body in doc.items():
        if isinstance(body, list):
            for item in body:
                out += ["", f"[[{_key(name)}]]"] + [f"{_key(k)} = {_value(v)}" for k, v in item.items()]
        elif name in ("nodes", "materials", "cameras"):
            for sub, table in body.items():
                out += ["", f"[{_key(name)}.{_key(sub)}]"] + [f"{_key(k)} = {_value(v)}" for k, v in table.items()]
        else:
            out += ["", f"[{_key(name)}]"] + [f"{_key(k)} = {_value(v)}" for k, v in body.items()]
    return "\n".join(out).lstrip("\n") + "\n"
