"""Writing ``.npz`` files that are the same bits for the same arrays.

``numpy.savez`` stamps every member of the zip archive with the time of writing,
so the same tile, stack or primitive set written twice differs in its bytes: a
rerun after a kill could not be compared bit for bit with an uninterrupted run,
and the cache's checksum would differ between two processes that built the same
entry. :func:`write_npz` writes the same archive layout as ``numpy.savez`` (one
``NAME.npy`` member per array, readable by ``numpy.load``) with a fixed member
timestamp and permissions, and never pickles.
"""

from __future__ import annotations

import zipfile

import numpy as np

__all__ = ["write_npz"]

# The earliest time a zip archive can store: a constant, like SOURCE_DATE_EPOCH builds.
_EPOCH = (1980, 1, 1, 0, 0, 0)


def write_npz(file, arrays: dict, compress: bool = False) -> None:
    """Write ``arrays`` as an ``.npz`` archive whose bytes depend on the arrays only.

    Parameters
    ----------
    file : str, os.PathLike or binary file object
        Destination (a temporary file of :mod:`arches_render.atomic` for outputs).
    arrays : dict
        ``{name: array_like}`` in the order to store them; object arrays are refused.
    compress : bool
        Deflate the members (``numpy.savez_compressed``); default stored.

    Raises
    ------
    ValueError
        An array holds Python objects (it would need a pickle).
    """
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with zipfile.ZipFile(file, mode="w", compression=method, allowZip64=True) as z:
        for name, value in arrays.items():
            arr = np.asanyarray(value)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_EPOCH)
            info.compress_type = method
            info.external_attr = 0o644 << 16
            with z.open(info, "w", force_zip64=True) as f:
                np.lib.format.write_array(f, arr, allow_pickle=False)
