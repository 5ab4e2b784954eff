"""The ``.npz`` file of a skeletal primitive set: array names, their schema, reading and writing.

A scene's ``skeletal_set`` node may name such a file (``file = "..."``); presets write
one per carving process. Arrays, no pickles; written atomically and byte-for-byte
reproducibly (:func:`arches_render.npzfile.write_npz`).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from arches_render.atomic import atomic_write
from arches_render.npzfile import write_npz
from arches_render.scene.array_files import Spec, read_arrays

__all__ = ["NPZ_KEYS", "NPZ_SPECS", "save_npz", "load_npz"]

#: Array names of the ``.npz`` format (``a`` and ``radius`` required).
NPZ_KEYS = ("a", "b", "radius", "energy", "core", "group")
#: What each array of a primitive file must be (:func:`arches_render.scene.array_files.read_arrays`).
NPZ_SPECS = {"a": Spec(("n", 3)), "b": Spec(("n", 3), required=False),
             "radius": Spec(("n",), scalar=True, lo=0.0, lo_open=True),
             "energy": Spec(("n",), scalar=True, required=False),
             "core": Spec(("n",), scalar=True, required=False, lo=0.0),
             "group": Spec(("n",), required=False, lo=0.0)}


def save_npz(path, **arrays) -> None:
    """Write primitive arrays (``NPZ_KEYS``) to ``path`` atomically (no pickles)."""
    unknown = set(arrays) - set(NPZ_KEYS)
    if unknown:
        raise ValueError(f"unknown array(s) {sorted(unknown)}; allowed: {', '.join(NPZ_KEYS)}")
    buf = io.BytesIO()
    write_npz(buf, {k: np.asarray(v) for k, v in arrays.items() if v is not None})
    with atomic_write(Path(path)) as f:
        f.write(buf.getvalue())


def load_npz(path) -> dict:
    """Read the primitive arrays of ``path`` (keys of ``NPZ_KEYS`` present in it), checked against :data:`NPZ_SPECS`."""
    return read_arrays(path, NPZ_SPECS, "primitive arrays")
