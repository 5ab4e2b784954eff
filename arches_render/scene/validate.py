"""Typed access to TOML tables with errors that name the file, key path and range.

A :class:`Table` wraps one TOML table and its key path; its getters check the type
and range of a value and raise :class:`~arches_render.scene.errors.SceneError`
otherwise. :meth:`Table.finish` rejects keys that no getter asked for, so typos in
scene files are reported instead of silently ignored.
"""

from __future__ import annotations

import math

from .errors import SceneError

_MISSING = object()


def _fmt_range(lo, hi, lo_open=False, hi_open=False):
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi}"
    return "a number"


class Table:
    """A validated view of one TOML table (see module docstring)."""

    def __init__(self, data, file, path: str = ""):
        if not isinstance(data, dict):
            raise SceneError(file, path, f"must be a table (got {type(data).__name__})")
        self.data, self.file, self.path = data, file, path
        self.used: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def error(self, name: str, message: str) -> SceneError:
        return SceneError(self.file, self.key(name), message)

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str, default=_MISSING):
        self.used.add(name)
        if name not in self.data:
            if default is _MISSING:
                raise self.error(name, "is required")
            return default
        return self.data[name]

    def number(self, name, default=_MISSING, lo=None, hi=None, lo_open=False, hi_open=False,
               integer=False):
        v = self.raw(name, default)
        if v is default and default is not _MISSING:
            return v
        kind = "an integer" if integer else "a number"
        ok_type = isinstance(v, int) if integer else isinstance(v, (int, float))
        if isinstance(v, bool) or not ok_type or (isinstance(v, float) and not math.isfinite(v)):
            raise self.error(name, f"must be {kind} {_fmt_range(lo, hi, lo_open, hi_open)} (got {v!r})")
        bad = ((lo is not None and (v <= lo if lo_open else v < lo))
               or (hi is not None and (v >= hi if hi_open else v > hi)))
        if bad:
            raise self.error(name, f"must be {kind} {_fmt_range(lo, hi, lo_open, hi_open)} (got {v!r})")
        return int(v) if integer else float(v)

    def integer(self, name, default=_MISSING, lo=None, hi=None):
        return self.number(name, default, lo, hi, integer=True)

    def boolean(self, name, default=_MISSING):
        v = self.raw(name, default)
        if not isinstance(v, bool):
            raise self.error(name, f"must be true or false (got {v!r})")
        return v

    def string(self, name, default=_MISSING, choices=None):
        v = self.raw(name, default)
        if v is default and default is not _MISSING:
            return v
        if not isinstance(v, str):
            raise self.error(name, f"must be a string (got {v!r})")
        if choices is not None and v not in choices:
            raise self.error(name, f"must be one of {', '.join(sorted(choices))} (got {v!r})")
        return v

    def vector(self, name, n=3, default=_MISSING, lo=None, hi=None, nonzero=False):
        v = self.raw(name, default)
        if v is default and default is not _MISSING:
            return v
        desc = f"an array of {n} numbers" + (f" each {_fmt_range(lo, hi)}" if lo is not None or hi is not None else "")
        if (not isinstance(v, list) or len(v) != n
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
            raise self.error(name, f"must be {desc} (got {v!r})")
        if (lo is not None and min(v) < lo) or (hi is not None and max(v) > hi):
            raise self.error(name, f"must be {desc} (got {v!r})")
        if nonzero and not any(v):
            raise self.error(name, f"must be a non-zero vector (got {v!r})")
        return [float(x) for x in v]

    def table(self, name, default=_MISSING) -> "Table | None":
        v = self.raw(name, default)
        if v is None:
            return None
        return Table(v, self.file, self.key(name))

    def tables(self, name) -> list["Table"]:
        """An array of tables (``[[name]]``); empty when absent."""
        v = self.raw(name, [])
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            raise self.error(name, "must be an array of tables ([[...]])")
        return [Table(x, self.file, f"{self.key(name)}[{i}]") for i, x in enumerate(v)]

    def finish(self) -> None:
        """Reject keys nobody asked for (typos)."""
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            allowed = ", ".join(sorted(self.used)) or "none"
            raise self.error(unknown[0], f"unknown key (allowed here: {allowed})")
