"""User-facing errors: each says what is wrong and where, in one line, with no traceback."""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray


def did_you_mean(word: str, choices: Iterable[str], parenthesized: bool = False) -> str:
    """The hint for a misspelt name: ``; did you mean 'x'?`` (or `` (did you mean 'x'?)``) with
    the closest of ``choices``, or "" when none is close (difflib's default cutoff, 0.6)."""
    close = difflib.get_close_matches(word, list(choices), n=1)
    if not close:
        return ""
    return f" (did you mean {close[0]!r}?)" if parenthesized else f"; did you mean {close[0]!r}?"


class EcsAnimError(Exception):
    """Base class of every error caused by user input (files, YAML, command-line values).

    The CLI prints ``str(error)`` on one line and exits non-zero; anything else is a bug.
    """


class UsageError(EcsAnimError, ValueError):
    """A Python API call given a value it cannot take (an unknown preset, a stature out of
    range, a negative duration): one line saying what was expected and what was found. Also a
    ValueError, so code that checks values with ``except ValueError`` keeps working."""


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


#: A plain decimal number as YAML reads it to the same value as ``float()`` (no octal ``012``,
#: ``1_000``, ``.nan``, hex or sexagesimal forms: those lists take the node-by-node path).
#: libyaml's parser where PyYAML was built with it (its wheels are): it composes the same
#: nodes, line numbers included, about ten times faster than PyYAML's own (100,000 triggers:
#: 55 s of CPU).
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

_PLAIN_NUMBER = r"(?>[-+]?(?:(?:0|[1-9][0-9]*)(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?)"
_NUMBER_LIST = re.compile(rf"\[\s*+({_PLAIN_NUMBER}(?:\s*+,\s*+{_PLAIN_NUMBER})*+)\s*+\]")
#: Flow lists of at least this many plain numbers are read in one go (a height grid's rows).
NUMBER_LIST_MIN = 16
_NUMBER_LIST_TAG = "!ecs-anim-number-list"


class NumberList(yaml.SequenceNode):
    """A flow list of plain numbers (``[0.0, 0.12, ...]``) read in one go by :func:`compose_yaml`.

    ``numbers`` (n,) float64 holds the values; ``value``, the list of scalar nodes with their lines
    that generic code (and error messages) walk, is only built when first asked for.
    """

    def __init__(self, numbers: NDArray[np.float64], text: str, start_mark: yaml.Mark,
                 end_mark: yaml.Mark):
        self._items: list[yaml.Node] | None = None
        super().__init__("tag:yaml.org,2002:seq", None, start_mark, end_mark, flow_style=True)
        self.numbers = numbers
        self._text = text  # the numbers as written, with their line breaks

    @property
    def value(self) -> list[yaml.Node]:
        if self._items is None:
            resolver = yaml.resolver.Resolver()
            start = self.start_mark
            self._items = []
            line, counted = start.line, 0
            for token in re.finditer(r"[^,\s]+", self._text):
                line += self._text.count("\n", counted, token.start())
                counted = token.start()
                mark = yaml.Mark(start.name, 0, line, 0, None, 0)  # no buffer: no snippet
                tag = resolver.resolve(yaml.ScalarNode, token.group(), (True, False))
                self._items.append(yaml.ScalarNode(tag, token.group(), mark, mark))
        return self._items

    @value.setter
    def value(self, items: list[yaml.Node] | None) -> None:
        self._items = items


def _packed(text: str) -> tuple[str, list[str]]:
    """``text`` with each flow list of :data:`NUMBER_LIST_MIN` or more plain numbers replaced by a
    one-item placeholder list keeping its line breaks (so every line number stays), and the
    lists' contents in order."""
    contents: list[str] = []

    def pack(match: re.Match[str]) -> str:
        inner = match.group(1)
        if inner.count(",") + 1 < NUMBER_LIST_MIN:
            return match.group()
        contents.append(inner)
        return f"[{_NUMBER_LIST_TAG} {len(contents) - 1}" + "\n" * match.group().count("\n") + "]"

    return _NUMBER_LIST.sub(pack, text), contents


def _unpack(root: yaml.Node, contents: list[str]) -> bool:
    """Replace the placeholders of :func:`_packed` in the tree by :class:`NumberList` nodes (one
    node per placeholder, so aliases stay shared); False unless every placeholder was a list
    node (one in a comment or a quoted text means the packed text is not the file's meaning)."""
    found: dict[int, NumberList] = {}
    seen: set[int] = set()

    def swap(node: yaml.Node) -> yaml.Node:
        if isinstance(node, yaml.SequenceNode) and len(node.value) == 1 \
                and getattr(node.value[0], "tag", None) == _NUMBER_LIST_TAG:
            if id(node) not in found:
                inner = contents[int(node.value[0].value)]
                found[id(node)] = NumberList(np.array(inner.split(","), dtype=np.float64), inner,
                                             node.start_mark, node.end_mark)
            return found[id(node)]
        if id(node) not in seen:
            seen.add(id(node))
            if isinstance(node, yaml.SequenceNode):
                node.value = [swap(item) for item in node.value]
            elif isinstance(node, yaml.MappingNode):
                node.value = [(swap(key), swap(value)) for key, value in node.value]
        return node

    swap(root)
    return len(found) == len(contents)


def compose_yaml(path: str | Path, what: str, number_lists: bool = False) -> Any:
    """The YAML node tree of a file (``yaml.compose``: nodes keep their line numbers), or None for
    an empty file; an unreadable file or bad YAML is an :class:`InputError` naming ``what``
    (e.g. "scenario") and, for bad YAML, the line.

    ``number_lists``: long flow lists of plain numbers come back as :class:`NumberList` nodes,
    read in one go (composing a million scalar nodes one by one takes about 30 s).
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(path, f"cannot read {what}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(path, f"cannot read {what}: not UTF-8 text") from None
    if number_lists:
        packed, contents = _packed(text)
        if contents:
            try:
                root = yaml.compose(packed, Loader=_YAML_LOADER)
                if root is not None and _unpack(root, contents):
                    return root
            except (RecursionError, yaml.YAMLError):
                pass  # reported from the file's own text below
    return _compose_text(path, text)


def _compose_text(path: str | Path, text: str) -> Any:
    try:
        return yaml.compose(text, Loader=_YAML_LOADER)
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


def expanded_size(root: yaml.Node, limit: int) -> int:
    """How many values (nodes) the tree holds once its aliases are expanded, each alias counting
    its whole subtree again (a :class:`NumberList` counts its numbers); counting stops above
    ``limit``. Linear in the distinct nodes (memoised), so a small file of nested aliases that
    expands to billions is measured at once. A node inside itself (a recursive alias) counts once
    there (its reader reports it)."""
    sizes: dict[int, int] = {}

    def size(node: yaml.Node) -> int:
        if id(node) in sizes:
            return sizes[id(node)]
        sizes[id(node)] = 1  # while inside it
        if isinstance(node, NumberList):
            total = 1 + len(node.numbers)
        elif isinstance(node, yaml.SequenceNode):
            total = 1 + sum(min(size(item), limit + 1) for item in node.value)
        elif isinstance(node, yaml.MappingNode):
            total = 1 + sum(min(size(k), limit + 1) + min(size(v), limit + 1) for k, v in node.value)
        else:
            total = 1
        sizes[id(node)] = min(total, limit + 1)
        return sizes[id(node)]

    return size(root)


def listed(names: Iterable[object], limit: int = 6) -> str:
    """``names`` joined by commas, cut after ``limit`` with the count of the rest, so that an error
    message stays one short line whatever the input holds (a 5,000-joint file, 10,000 labels).

    >>> listed(["a", "b", "c"], limit=2)
    'a, b (+1 more)'
    """
    items = [str(name) for name in names]
    shown = ", ".join(items[:limit])
    return shown if len(items) <= limit else f"{shown} (+{len(items) - limit} more)"


def quoted(text: object, limit: int = 40) -> str:
    """``repr(text)``, cut after ``limit`` characters with "...", so that a name taken from a file
    (a 5,000-character joint name) leaves an error message one short line.

    >>> quoted("a" * 50, limit=10)
    "'aaaaaaa...'"
    """
    text = str(text)
    return repr(text if len(text) <= limit else text[: limit - 3] + "...")
