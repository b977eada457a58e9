"""The exception root of ``trackgen`` and the located layout error."""
from __future__ import annotations


class TrackError(Exception):
    """Root of every error ``trackgen`` raises on purpose (bad layout, bad output folder)."""


class LayoutError(TrackError, ValueError):
    """A problem at one line of a layout: ``str(err) == f"{path}:{line}: {message}"``.

    ``path`` is the layout as the user named it (``"<python>"``-like for the Python API),
    ``line`` is 1-based (``None`` when the whole file is concerned, e.g. it cannot be read;
    then ``str(err) == f"{path}: {message}"``).
    """

    def __init__(self, path: str, line: int | None, message: str) -> None:
        self.path = str(path)
        self.line = line
        self.message = message
        super().__init__(str(self))

    def __str__(self) -> str:
        if self.line is None:
            return f"{self.path}: {self.message}"
        return f"{self.path}:{self.line}: {self.message}"

    def __reduce__(self):  # picklable despite the custom __init__
        return (type(self), (self.path, self.line, self.message))
