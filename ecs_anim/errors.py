"""User-facing errors: each says what is wrong and where, in one line, with no traceback."""

from __future__ import annotations

from pathlib import Path


class EcsAnimError(Exception):
    """Base class of every error caused by user input (files, YAML, command-line values).

    The CLI prints ``str(error)`` on one line and exits non-zero; anything else is a bug.
    """


class InputError(EcsAnimError):
    """A malformed input file: ``path:line: message`` (line omitted when unknown)."""

    def __init__(self, path: str | Path | None, message: str, line: int | None = None):
        self.path = None if path is None else str(path)
        self.line = line
        self.message = message
        where = self.path or "<input>"
        if line is not None:
            where += f":{line}"
        super().__init__(f"{where}: {message}")


class MappingError(EcsAnimError):
    """A source skeleton whose joints could not be matched to the canonical body parts."""
