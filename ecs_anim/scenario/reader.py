"""Reading a scenario's YAML tree: typed values with ``file:line: path.to.key: message`` errors, and
the size limits that keep a small file from taking hours to load."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Protocol

import yaml
from yaml import Node

from ecs_anim.core.errors import (
    EcsAnimError,
    InputError,
    compose_yaml,
    did_you_mean,
    expanded_size,
    quoted,
)

#: Sizes of a scenario once its YAML aliases are expanded (an alias counts each time it is used),
#: so that a small file cannot take hours to load or to run (docs/scenarios.md).
MAX_YAML_VALUES = 5_000_000


MAX_GRID_CELLS = 4_000_000  # heights over all the height grids of the ground


MAX_GROUND_PARTS = 1_000  # grounds, combined ones and their parts included


class YamlReader:
    """Typed access to a composed YAML tree with ``file:line: path: message`` errors."""

    def __init__(self, path: str):
        self.path = path
        self._constructor = yaml.constructor.SafeConstructor()
        self.ground_parts = 0  # read so far, against MAX_GROUND_PARTS
        self.grid_cells = 0  # against MAX_GRID_CELLS

    def fail(self, node: Node | None, where: str, message: str) -> InputError:
        line = None if node is None else node.start_mark.line + 1
        return InputError(self.path, f"{where}: {message}" if where else message, line)

    def mapping(self, node: Node, where: str, allowed: dict[str, bool]) -> dict[str, Node]:
        """Keys -> value nodes; ``allowed`` maps each key to whether it is required."""
        if not isinstance(node, yaml.MappingNode):
            raise self.fail(node, where, f"expected a mapping, found {self._kind(node)}")
        out: dict[str, Node] = {}
        for key_node, value in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise self.fail(key_node, where or "top level",
                                f"a key must be a name, found {self._kind(key_node)}")
            key = str(key_node.value)
            here = f"{where}.{key}" if where else key
            if key not in allowed:
                hint = did_you_mean(key, list(allowed))
                raise self.fail(key_node, here, f"unknown key{hint} (expected one of "
                                               f"{', '.join(allowed)})")
            if key in out:
                raise self.fail(key_node, here, "given twice")
            out[key] = value
        for key, required in allowed.items():
            if required and key not in out:
                raise self.fail(node, where or "top level", f"missing required key {key!r}")
        return out

    @staticmethod
    def _kind(node: Node) -> str:
        if isinstance(node, yaml.MappingNode):
            return "a mapping"
        if isinstance(node, yaml.SequenceNode):
            return "a list"
        return repr(node.value)

    def scalar(self, node: Node, where: str) -> Any:
        if not isinstance(node, yaml.ScalarNode):
            raise self.fail(node, where, f"expected a single value, found {self._kind(node)}")
        try:  # the node's tag was resolved when composed: construct it as yaml.safe_load would
            return self._constructor.construct_object(node, deep=True)
        except yaml.YAMLError as exc:
            raise self.fail(node, where, f"not plain YAML data ({getattr(exc, 'problem', exc)})") from None

    def number(self, node: Node, where: str, lo: float = -math.inf, hi: float = math.inf,
               unit: str = "") -> float:
        value = self.scalar(node, where)
        if isinstance(value, str):
            try:  # YAML 1.1 reads 1e6 (an exponent without a decimal point) as text
                value = float(value)
            except ValueError:
                pass
        if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 1e300:
            value = math.inf  # beyond any float: refused below, not an OverflowError
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            found = self.scalar(node, where)
            shown = "a number too large" if isinstance(found, int) and not isinstance(found, bool) \
                else repr(found)
            raise self.fail(node, where, f"expected a number{' in ' + unit if unit else ''}, "
                                         f"found {shown}")
        if not lo <= value <= hi:
            raise self.fail(node, where, f"expected a number between {lo:g} and {hi:g}"
                                         f"{' ' + unit if unit else ''}, found {value!r}")
        return float(value)

    def integer(self, node: Node, where: str, lo: int, hi: int) -> int:
        value = self.scalar(node, where)
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise self.fail(node, where, f"expected a whole number from {lo} to {hi}, found {value!r}")
        return value

    def string(self, node: Node, where: str, empty: bool = False) -> str:
        """A text; ``empty`` allows ``''``."""
        value = self.scalar(node, where)
        if not isinstance(value, str) or not (value or empty):
            raise self.fail(node, where, f"expected a name, found {value!r}")
        return value

    def boolean(self, node: Node, where: str) -> bool:
        value = self.scalar(node, where)
        if not isinstance(value, bool):
            raise self.fail(node, where, f"expected true or false, found {value!r}")
        return value

    def sequence(self, node: Node, where: str, most: int | None = None, what: str = "items") -> list[Node]:
        """The items of a list; ``most`` bounds their number (an alias counted each time it is
        used)."""
        if not isinstance(node, yaml.SequenceNode):
            raise self.fail(node, where, f"expected a list, found {self._kind(node)}")
        if most is not None and len(node.value) > most:
            raise self.fail(node, where, f"at most {most:,} {what}, found {len(node.value):,}")
        return list(node.value)

    def vector(self, node: Node, where: str, size: int, unit: str,
               bound: float = math.inf) -> tuple[float, ...]:
        items = self.sequence(node, where)
        if len(items) != size:
            raise self.fail(node, where, f"expected a list of {size} numbers ({unit}), found "
                                         f"{len(items)}")
        return tuple(self.number(v, f"{where}[{i}]", -bound, bound, unit=unit)
                     for i, v in enumerate(items))

    def vector3(self, node: Node, where: str, unit: str,
                bound: float = math.inf) -> tuple[float, float, float]:
        """:meth:`vector` of three numbers (a point or a direction)."""
        x, y, z = self.vector(node, where, 3, unit, bound)
        return (x, y, z)

    def vector2(self, node: Node, where: str, unit: str,
                bound: float = math.inf) -> tuple[float, float]:
        """:meth:`vector` of two numbers (a horizontal place or size)."""
        x, y = self.vector(node, where, 2, unit, bound)
        return (x, y)

    def too_far(self, node: Node, where: str, away_m: float, what: str, reference: str) -> None:
        """Refuse ``what`` lying ``away_m`` from ``reference`` beyond :data:`MAX_TARGET_DISTANCE_M`
        (metres given as millimetres, most likely)."""
        if away_m > MAX_TARGET_DISTANCE_M:
            guess = "was it given in mm?" if away_m / 1000.0 <= MAX_TARGET_DISTANCE_M else "is the unit right?"
            raise self.fail(node, where, f"{what} is {away_m:,.0f} m from {reference} (at most "
                            f"{MAX_TARGET_DISTANCE_M:g} m); {where.rsplit('.', 1)[-1]} is in metres "
                            f"({guess})")


class Fails(Protocol):
    """What :func:`read_motion` reports through: a :class:`YamlReader`, or a clip's own reader."""

    def fail(self, node: Node | None, where: str, message: str) -> EcsAnimError: ...


def read_tree(path: Path, what: str, label: str) -> Node:
    """The file's YAML tree (long number lists read in one go), refused when empty or when it holds
    more than :data:`MAX_YAML_VALUES` values with its aliases expanded."""
    root: Node | None = compose_yaml(path, what, number_lists=True)
    if root is None:
        raise InputError(path, f"{label} is empty", 1)
    try:
        expanded = expanded_size(root, MAX_YAML_VALUES)
    except RecursionError:
        raise InputError(path, "not valid YAML: nested too deeply") from None
    if expanded > MAX_YAML_VALUES:
        raise InputError(path, f"{label} holds more than {MAX_YAML_VALUES:,} values once its aliases "
                               "(*name) are expanded, each counted every time it is used "
                               "(docs/scenarios.md, Sizes)", 1)
    return root


def refuse_clip(path: Path) -> None:
    """A motion clip given where a scenario is expected (``ecs-anim run walk.bvh``) is said to be
    one, by its extension or its first bytes, with how to play it."""
    try:
        with open(path, "rb") as f:
            head = f.read(16)
    except OSError:
        return  # compose_yaml says why it cannot be read
    suffix = path.suffix.lower()
    where = "name it in a scenario's motions: (docs/scenarios.md)"
    # The path leads the message already: the example names the file alone, so the line stays short.
    name = quoted(path.name)
    if suffix == ".bvh" or head.lstrip(b"\xef\xbb\xbf \t\r\n").upper().startswith(b"HIERARCHY"):
        what, how = "a BVH clip", f"import it (ecs-anim import {name} -o motions/) or {where}"
    elif suffix == ".c3d" or (len(head) > 1 and head[0] < 0x20 and head[1] == 0x50):
        what, how = "a C3D capture", f"import it (ecs-anim import {name} -o motions/) or {where}"
    elif suffix == ".fbx" or head.startswith(b"Kaydara FBX Binary") or head.startswith(b"; FBX"):
        what, how = "an FBX scene", f"import it (ecs-anim import {name} -o motions/) or {where}"
    elif suffix == ".nmo":
        what, how = "an .nmo motion", where
    elif head.startswith(b"PK\x03\x04"):
        what, how = "a zip archive (an .nmo motion?)", where
    else:
        return
    raise InputError(path, f"a scenario YAML was expected, not {what}; to play it, {how}")


#: How far a world target may lie from its character's start, and a table from the nearest
#: character; also the largest area corner or radius. Beyond, the metres were likely millimetres.
MAX_TARGET_DISTANCE_M = 100.0
