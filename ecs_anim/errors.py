"""User-facing errors: each says what is wrong and where, in one line, with no traceback."""

from __future__ import annotations

from collections.abc import Iterable
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


def compose_yaml(path: str | Path, what: str) -> object:
    """The YAML node tree of a file (``yaml.compose``: nodes keep their line numbers), or None for
    an empty file; an unreadable file or bad YAML is an :class:`InputError` naming ``what``
    (e.g. "scenario") and, for bad YAML, the line."""
    import yaml

    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(path, f"cannot read {what}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(path, f"cannot read {what}: not UTF-8 text") from None
    try:
        return yaml.compose(text)
    except RecursionError:
        raise InputError(path, "not valid YAML: nested too deeply") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = None if mark is None else mark.line + 1
        position = getattr(exc, "position", None)  # a reader error: a character offset
        if line is None and isinstance(position, int):
            line = text.count("\n", 0, position) + 1
        problem = getattr(exc, "problem", None) or getattr(exc, "reason", None) or str(exc)
        raise InputError(path, f"not valid YAML: {' '.join(str(problem).split())}", line) from None


def listed(names: Iterable[object], limit: int = 6) -> str:
    """``names`` joined by commas, cut after ``limit`` with the count of the rest, so that an error
    message stays one short line whatever the input holds (a 5,000-joint file, 10,000 labels).

    >>> listed(["a", "b", "c"], limit=2)
    'a, b (+1 more)'
    """
    items = [str(name) for name in names]
    shown = ", ".join(items[:limit])
    return shown if len(items) <= limit else f"{shown} (+{len(items) - limit} more)"
