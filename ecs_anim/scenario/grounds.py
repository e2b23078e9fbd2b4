"""A scenario's ``ground:``: planes, slopes, stairs, bumps, height grids and their combinations."""

from __future__ import annotations

import numpy as np
import yaml
from yaml import Node

from ecs_anim.core.errors import (
    NumberList,
    did_you_mean,
    listed,
)
from ecs_anim.core.ground import Bumps, Combined, Ground, HeightGrid, Plane, Slope, Stairs
from ecs_anim.scenario.reader import (
    MAX_GRID_CELLS,
    MAX_GROUND_PARTS,
    YamlReader,
)

#: Highest (and, negated, lowest) height of a grid ground (m), as for a plane's level ``z_m``.
MAX_GROUND_HEIGHT_M = 1e3


def read_ground(r: YamlReader, node: Node, where: str, inside: tuple[int, ...] = ()) -> Ground:
    if id(node) in inside:  # a YAML alias back to an enclosing ground
        raise r.fail(node, where, "a ground cannot contain itself")
    r.ground_parts += 1
    if r.ground_parts > MAX_GROUND_PARTS:
        raise r.fail(node, where, f"a ground has at most {MAX_GROUND_PARTS:,} parts (combined grounds "
                                  "included, an alias counted each time it is used)")
    if not isinstance(node, yaml.MappingNode):
        raise r.fail(node, where, "expected a mapping with 'type:' (plane, slope, stairs, bumps, "
                                  "grid, combined)")
    type_node = next((v for k, v in node.value if k.value == "type"), None)
    if type_node is None:
        raise r.fail(node, where, "missing required key 'type' (plane, slope, stairs, bumps, grid, "
                                  "combined)")
    kind = r.string(type_node, f"{where}.type")
    if kind not in GROUND_KEYS:
        hint = did_you_mean(kind, list(GROUND_KEYS))
        raise r.fail(type_node, f"{where}.type", f"unknown ground {kind!r}{hint} (expected one of "
                                                 f"{', '.join(GROUND_KEYS)})")
    keys = r.mapping(node, where, GROUND_KEYS[kind])

    def num(key: str, default: float, lo: float = -1e3, hi: float = 1e3, unit: str = "") -> float:
        return r.number(keys[key], f"{where}.{key}", lo, hi, unit) if key in keys else default

    if kind == "plane":
        return Plane(num("z_m", 0.0, unit="m"))
    if kind == "slope":
        return Slope(num("grade_x", 0.0, -2, 2), num("grade_y", 0.0, -2, 2), num("z_m", 0.0, unit="m"))
    if kind == "stairs":
        steps = r.integer(keys["steps"], f"{where}.steps", 0, 10000) if "steps" in keys else 8
        return Stairs(num("rise_m", 0.15, -1, 1, "m"), num("run_m", 0.3, 0.05, 10, "m"), steps,
                      num("start_m", 1.0, unit="m"), num("heading_deg", 0.0, -360, 360, "degrees"),
                      num("z_m", 0.0, unit="m"))
    if kind == "bumps":
        return Bumps(num("amplitude_m", 0.05, 0, 5, "m"), num("wavelength_x_m", 2.0, 0.05, 1e3, "m"),
                     num("wavelength_y_m", 2.0, 0.05, 1e3, "m"), num("z_m", 0.0, unit="m"))
    if kind == "grid":
        heights = _grid_heights(r, keys["heights_m"], f"{where}.heights_m")
        origin = r.vector2(keys["origin_m"], f"{where}.origin_m", "m") if "origin_m" in keys else (0.0, 0.0)
        return HeightGrid(heights, r.number(keys["cell_m"], f"{where}.cell_m", 1e-3, 1e3, "m"),
                          origin[0], origin[1])
    parts = r.sequence(keys["parts"], f"{where}.parts")
    if not parts:
        raise r.fail(keys["parts"], f"{where}.parts", "expected at least one ground")
    return Combined(tuple(read_ground(r, p, f"{where}.parts[{i}]", inside + (id(node),))
                          for i, p in enumerate(parts)))


def _grid_heights(r: YamlReader, node: Node, where: str) -> np.ndarray:
    """A grid's ``heights_m``, rows along y -> (ny, nx) metres. Sizes are checked before any value
    is read (at most :data:`MAX_GRID_CELLS` over the whole ground); a row written as a flow list
    of numbers (a :class:`NumberList`) is checked in one go, any other row value by value."""
    rows = r.sequence(node, where)
    widths = [len(row.numbers) if isinstance(row, NumberList) else len(r.sequence(row, f"{where}[{i}]"))
              for i, row in enumerate(rows)]
    r.grid_cells += sum(widths)
    if r.grid_cells > MAX_GRID_CELLS:
        raise r.fail(node, where, f"at most {MAX_GRID_CELLS:,} heights in the ground's grids, found "
                                  f"{r.grid_cells:,} (an alias counted each time it is used)")
    if len(rows) < 2 or len(set(widths)) != 1 or widths[0] < 2:
        raise r.fail(node, where, "expected a rectangular grid of at least 2 x 2 heights (rows along "
                                  f"y), found {len(rows)} rows of lengths {listed(widths)}")
    values = []
    for i, row in enumerate(rows):
        if isinstance(row, NumberList):
            bad = ~(np.abs(row.numbers) <= MAX_GROUND_HEIGHT_M)  # NaN included
            if not bad.any():
                values.append(row.numbers)
                continue
            j = int(np.argmax(bad))  # the first bad height, read again for its message and line
            r.number(row.value[j], f"{where}[{i}][{j}]", -MAX_GROUND_HEIGHT_M, MAX_GROUND_HEIGHT_M, "m")
        values.append(np.array([r.number(v, f"{where}[{i}][{j}]", -MAX_GROUND_HEIGHT_M,
                                         MAX_GROUND_HEIGHT_M, "m") for j, v in enumerate(row.value)]))
    return np.stack(values)


GROUND_KEYS: dict[str, dict[str, bool]] = {
    "plane": {"type": True, "z_m": False},
    "slope": {"type": True, "grade_x": False, "grade_y": False, "z_m": False},
    "stairs": {"type": True, "rise_m": False, "run_m": False, "steps": False, "start_m": False,
               "heading_deg": False, "z_m": False},
    "bumps": {"type": True, "amplitude_m": False, "wavelength_x_m": False,
              "wavelength_y_m": False, "z_m": False},
    "grid": {"type": True, "cell_m": True, "origin_m": False, "heights_m": True},
    "combined": {"type": True, "parts": True},
}
