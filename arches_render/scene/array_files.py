"""Array files (``.npz``) that scenes name: checked against a schema before their data is read.

Primitive arrays (``capsule_set``, ``skeletal_set``), block tiles and material
stacks come from ``.npz`` files beside a scene, written by this tool or by another
program. :func:`read_arrays` reads one against a schema of :class:`Spec`:

1. the archive is opened and every member's ``.npy`` header (shape, dtype) is
   read *without* its data: unknown members, missing required ones, object or
   structured dtypes (pickles are never loaded), wrong ranks or inconsistent sizes
   are refused before a byte of data is decoded;
2. the decoded size of the whole file is compared with the memory the machine has
   (:func:`arches_render.resources.check_memory`), so a small compressed file that
   expands to more than the machine holds (or arrays far larger than the scene
   could use) is refused with the estimate instead of being decoded;
3. the data is read (``allow_pickle=False``) and checked: finite numbers, ranges
   (e.g. radii ``> 0``), integers where indices are expected.

Every failure is an :class:`ArrayFileError` (a ``ValueError``) with one line naming
the array and what is allowed; loaders add the scene file and key.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..resources import ResourceError, check_memory

__all__ = ["ArrayFileError", "Spec", "read_arrays"]

_KINDS = {"number": "fiu", "integer": "iu", "string": "U", "bool": "b"}


class ArrayFileError(ValueError):
    """An ``.npz`` file that does not match its schema (``str`` is the one-line reason)."""


@dataclass(frozen=True)
class Spec:
    """What one array of an ``.npz`` file must be.

    Attributes
    ----------
    shape : tuple
        One entry per axis: an ``int`` (that length), a ``str`` (a length shared by
        every array using the same name, e.g. ``"n"``) or ``None`` (any length).
    kind : {'number', 'integer', 'string', 'bool'}
        Allowed dtypes: numbers (floats or integers), integers only, unicode
        strings, booleans.
    required : bool
        Whether the file must hold the array.
    scalar : bool
        Also accept a 0-d array (one value for every element).
    lo, hi : float, optional
        Allowed range of the values (numbers and integers).
    lo_open, hi_open : bool
        Exclusive bounds.
    """

    shape: tuple
    kind: str = "number"
    required: bool = True
    scalar: bool = False
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False

    def describe(self) -> str:
        dims = ", ".join("any" if d is None else str(d) for d in self.shape)
        rng = ""
        if self.lo is not None and self.hi is not None:
            rng = f" in {'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"
        elif self.lo is not None:
            rng = f" {'>' if self.lo_open else '>='} {self.lo:g}"
        elif self.hi is not None:
            rng = f" {'<' if self.hi_open else '<='} {self.hi:g}"
        one = "one value or " if self.scalar else ""
        return f"{one}a ({dims}) array of {self.kind}s{rng}"


def _header(f):
    """Shape and dtype of the ``.npy`` stream ``f`` (its data is not read)."""
    version = np.lib.format.read_magic(f)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
    elif version == (2, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
    else:
        raise ArrayFileError(f"npy format {version[0]}.{version[1]} is not supported (only 1.0 and 2.0)")
    return shape, dtype


def _headers(z: zipfile.ZipFile) -> dict:
    out = {}
    for info in z.infolist():
        name = info.filename
        if not name.endswith(".npy"):
            raise ArrayFileError(f"member {name!r} is not an array (.npy)")
        with z.open(info) as f:
            try:
                out[name[:-4]] = _header(f)
            except ArrayFileError:
                raise
            except Exception as exc:
                raise ArrayFileError(f"array {name[:-4]!r} has no valid .npy header ({_first_line(exc)})") from None
    return out


def _first_line(exc) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _check_header(name, spec: Spec, shape, dtype, dims: dict):
    if dtype.hasobject or dtype.fields is not None or dtype.subdtype is not None:
        raise ArrayFileError(f"array {name!r} has dtype {dtype} (Python objects or records); "
                             f"it must be {spec.describe()}")
    if dtype.kind not in _KINDS[spec.kind]:
        raise ArrayFileError(f"array {name!r} has dtype {dtype}; it must be {spec.describe()}")
    if spec.scalar and shape == ():
        return
    if len(shape) != len(spec.shape):
        raise ArrayFileError(f"array {name!r} has shape {shape}; it must be {spec.describe()}")
    for axis, (got, want) in enumerate(zip(shape, spec.shape)):
        if isinstance(want, int) and got != want:
            raise ArrayFileError(f"array {name!r} has shape {shape}; it must be {spec.describe()}")
        if isinstance(want, str):
            if want in dims and dims[want][0] != got:
                other, _ = dims[want][1]
                raise ArrayFileError(f"array {name!r} has {got} rows but {other!r} has {dims[want][0]}: "
                                     f"they must match ({want})")
            dims.setdefault(want, (got, (name, axis)))


def _check_values(name, spec: Spec, arr: np.ndarray):
    if spec.kind not in ("number", "integer") or arr.size == 0:
        return
    if arr.dtype.kind == "f":
        bad = ~np.isfinite(arr)
        if bad.any():
            i = np.unravel_index(int(np.argmax(bad)), arr.shape) if arr.ndim else ()
            raise ArrayFileError(f"array {name!r} holds {int(bad.sum())} NaN or infinite values "
                                 f"(first at index {[int(k) for k in i]}); it must be {spec.describe()}")
    lo_bad = (arr <= spec.lo if spec.lo_open else arr < spec.lo) if spec.lo is not None else None
    hi_bad = (arr >= spec.hi if spec.hi_open else arr > spec.hi) if spec.hi is not None else None
    for bad in (lo_bad, hi_bad):
        if bad is not None and np.any(bad):
            flat = int(np.argmax(bad))
            i = [int(k) for k in np.unravel_index(flat, arr.shape)] if arr.ndim else []
            raise ArrayFileError(f"array {name!r} is out of range at index {i} "
                                 f"(value {arr.reshape(-1)[flat].item()!r}); it must be {spec.describe()}")


def read_arrays(path, specs: dict, what: str = "arrays") -> dict:
    """The arrays of ``.npz`` file ``path``, checked against ``specs``.

    Parameters
    ----------
    path : str, Path or binary file object
        The file (already resolved by :func:`arches_render.scene.paths.scene_file`),
        or an open file (a cache entry's payload).
    specs : dict
        ``{name: Spec}``; members not named are refused.
    what : str
        What the file holds, for the memory message (``'capsule arrays'``).

    Returns
    -------
    dict
        ``{name: numpy.ndarray}`` of the arrays present.

    Raises
    ------
    ArrayFileError
        Not an ``.npz`` archive, unknown or missing arrays, wrong dtype, shape or
        values, or more data than the machine's memory.
    """
    label = Path(getattr(path, "name", None) or str(path)).name
    try:
        z = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
        raise ArrayFileError(f"not an .npz archive ({_first_line(exc)})") from None
    with z:
        heads = _headers(z)
        missing = [k for k, s in specs.items() if s.required and k not in heads]
        if missing:
            raise ArrayFileError(f"missing array {missing[0]!r} (has: {', '.join(heads) or 'none'}; "
                                 f"required: {', '.join(k for k, s in specs.items() if s.required)})")
        unknown = sorted(set(heads) - set(specs))
        if unknown:
            raise ArrayFileError(f"unknown array {unknown[0]!r} (allowed: {', '.join(specs)})")
        dims: dict = {}
        nbytes = 0
        for name, (shape, dtype) in heads.items():
            _check_header(name, specs[name], shape, dtype, dims)
            nbytes += int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
        try:
            check_memory(nbytes, f"decoding the {what} of {label}")
        except ResourceError as exc:
            raise ArrayFileError(str(exc)) from None
        out = {}
        for name in heads:
            try:
                with z.open(name + ".npy") as f:
                    arr = np.lib.format.read_array(f, allow_pickle=False)
            except Exception as exc:  # truncated data, bad CRC, short read: all mean a damaged file
                raise ArrayFileError(f"array {name!r} cannot be read: the file is damaged or "
                                     f"truncated ({_first_line(exc)})") from None
            _check_values(name, specs[name], arr)
            out[name] = arr
    return out
