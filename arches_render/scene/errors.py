"""User-facing errors: one line naming the file, the key path and the allowed values."""

from __future__ import annotations


class SceneError(ValueError):
    """Invalid scene input. ``str(err)`` is the one line the CLI prints."""

    def __init__(self, file, key: str, message: str):
        self.file = str(file) if file is not None else "<scene>"
        self.key = key
        self.message = message
        where = f"{self.file}: {key}" if key else self.file
        super().__init__(f"{where}: {message}")

    def __reduce__(self):
        # Pickled with its own arguments, not the formatted line: a render process or a
        # Dask worker sends it back to the CLI, which prints it as raised.
        return type(self), (self.file, self.key, self.message)
