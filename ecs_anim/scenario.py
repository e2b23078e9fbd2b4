"""Scenario files (YAML): who plays what, on which ground, for how long.

Every field is validated at load time; an error reads ``file:line: path.to.key: what was
expected, what was found`` and suggests the closest key on a typo. Nothing is checked in the
tick. The schema is documented in ``docs/scenarios.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import yaml
from yaml import Node

from .body_points import BodyPoint
from .components import MotionPlayer, Placement, QueuedClip
from .constraints import Activation, ConstraintSpec
from .errors import (
    EcsAnimError,
    InputError,
    NumberList,
    compose_yaml,
    did_you_mean,
    expanded_size,
    listed,
    quoted,
)
from .events import Action, Condition, Trigger, constraints_named, switched_off
from .files import MAX_NAME_LENGTH, NAME_PATTERN
from .ground import Bumps, Combined, Ground, HeightGrid, Plane, Slope, Stairs
from .morphology import LENGTH_KEYS, PRESET_SPECS, Morphology, with_lengths_m
from .motion import NormalizedMotion, load_nmo
from .simulation import MAX_COORDINATE_M, MAX_DURATION_S, Simulation
from .store import MAX_QUEUE, MAX_WAYPOINTS

#: How far a desired centre of mass may lie from the character's position (over its feet).
MAX_COM_OFFSET_M = 1.0
#: How far a world target may lie from its character's start, and a table from the nearest
#: character; also the largest area corner or radius. Beyond, the metres were likely millimetres.
MAX_TARGET_DISTANCE_M = 100.0
#: Sizes of a scenario once its YAML aliases are expanded (an alias counts each time it is used),
#: so that a small file cannot take hours to load or to run (docs/scenarios.md).
MAX_YAML_VALUES = 5_000_000
MAX_GRID_CELLS = 4_000_000  # heights over all the height grids of the ground
MAX_GROUND_PARTS = 1_000  # grounds, combined ones and their parts included
MAX_CHARACTERS = 100_000
MAX_CONSTRAINTS = 100_000  # over all characters
MAX_TABLES = 1_000
#: Highest (and, negated, lowest) height of a grid ground (m), as for a plane's level ``z_m``.
MAX_GROUND_HEIGHT_M = 1e3


@dataclass
class ConstraintEntry:
    """A scenario constraint, as :meth:`Simulation.add_constraint` takes it; the target
    character is a name until the simulation is built."""

    name: str
    point: str
    priority: float
    activation: Activation
    target_in_world: tuple[float, float, float] | None = None
    target_character: str | None = None
    target_point: str | None = None
    options: dict[str, Any] = field(default_factory=dict)
    #: ``activation.motion``: the activation runs in this clip's own time while it plays.
    clock_motion: str | None = None
    #: A moving world target: keyframe times (s) and points (m), interpolated linearly.
    target_keyframes: tuple[tuple[float, ...], tuple[tuple[float, float, float], ...]] | None = None

    def aims_at_itself(self) -> bool:
        """Whether the target is the constrained point itself (on its own body)."""
        from .body_points import body_point

        if self.target_point is None:
            return False
        o = self.options
        own = body_point(self.point, o.get("fraction"), o.get("offset_m", (0.0, 0.0, 0.0)),
                         segment=o.get("kind") == "orientation")
        aim = body_point(self.target_point, o.get("target_fraction"),
                         o.get("target_offset_m", (0.0, 0.0, 0.0)), as_target=True)
        return (own.segment, own.fraction, tuple(own.offset_m)) == \
            (aim.segment, aim.fraction, tuple(aim.offset_m))

    def to_spec(self) -> ConstraintSpec:
        """The constraint stored with a motion (its target a point of the same body)."""
        o = self.options
        params: dict[str, Any] = {"target_point": self.target_point,
                                  "target_fraction": o.get("target_fraction"),
                                  "target_offset_m": list(o.get("target_offset_m", (0.0, 0.0, 0.0)))}
        for key in ("distance_m", "axis"):
            if key in o:
                params[key] = list(o[key]) if key == "axis" else o[key]
        if "area" in o:
            params["area"] = asdict(o["area"])
        return ConstraintSpec(self.name, o["kind"], self.point, self.activation,
                              tuple(o.get("chain") or ()), self.priority,
                              o.get("fraction"),
                              tuple(o.get("offset_m", (0.0, 0.0, 0.0))), params)


@dataclass(frozen=True)
class SteeringSpec:
    """A character's locomotion set and steering from the scenario (docs/steering.md):
    ``locomotion`` gait -> motion name (``walk`` always, ``idle`` and ``run`` if given),
    ``path_m`` waypoints (x, y) metres walked in order (empty: none), ``speed_m_s`` the speed
    asked for (None: the walk's own)."""

    locomotion: dict[str, str]
    path_m: tuple[tuple[float, float], ...] = ()
    speed_m_s: float | None = None


@dataclass
class CharacterSpec:
    name: str
    morphology: Morphology
    player: MotionPlayer
    placement: Placement
    team: str = ""
    constraints: list[ConstraintEntry] = field(default_factory=list)
    com_control: bool = True
    com_target_xy: tuple[float, float] | None = None
    steering: SteeringSpec | None = None


@dataclass(frozen=True)
class Table:
    """A table drawn in the scene (a prop: nothing collides with it): its top's centre
    ``centre_m`` (x, y) and size ``size_m`` (along its heading, across), metres; the top's
    height above the ground, metres; heading, radians anticlockwise from +x."""

    centre_m: tuple[float, float]
    size_m: tuple[float, float]
    height_m: float
    heading_rad: float = 0.0


@dataclass
class Scenario:
    """A scenario file as :func:`load_scenario` read it (docs/scenarios.md): ``duration_s`` and
    ``fps`` (Hz), ``motions`` by name, the ``ground``, the ``characters`` to spawn
    (:func:`build_simulation`), viewer hints and props."""

    path: str
    duration_s: float
    fps: float
    motions: dict[str, NormalizedMotion]
    ground: Ground
    characters: list[CharacterSpec] = field(default_factory=list)
    camera: dict[str, Any] = field(default_factory=dict)  # viewer hints (docs/scenarios.md)
    tables: list[Table] = field(default_factory=list)  # props, drawn only
    #: The scenario file and every motion file it read: no output may overwrite one.
    input_files: tuple[str, ...] = ()
    #: Reactions (ecs_anim.events), naming characters and constraints by scenario index.
    triggers: list[Trigger] = field(default_factory=list)
    #: The constraints triggers name: (character index, constraint name) by placeholder id.
    trigger_constraints: list[tuple[int, str]] = field(default_factory=list)


class _Reader:
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


def _ground(r: _Reader, node: Node, where: str, inside: tuple[int, ...] = ()) -> Ground:
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
    return Combined(tuple(_ground(r, p, f"{where}.parts[{i}]", inside + (id(node),))
                          for i, p in enumerate(parts)))


def _grid_heights(r: _Reader, node: Node, where: str) -> np.ndarray:
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


def _morphology(r: _Reader, node: Node, where: str) -> Morphology:
    if isinstance(node, yaml.ScalarNode):
        name = r.string(node, where)
        if name not in PRESET_SPECS:
            hint = did_you_mean(name, list(PRESET_SPECS))
            raise r.fail(node, where, f"unknown morphology preset {name!r}{hint} (presets: "
                                      f"{', '.join(PRESET_SPECS)}, or a mapping with stature_m / "
                                      "lengths_m)")
        return Morphology.preset(name)
    keys = r.mapping(node, where, {"stature_m": False, "sex": False, "proportions": False,
                                   "leg_scale": False, "mass_kg": False, "lengths_m": False,
                                   "preset": False})
    if "preset" in keys:
        extra = [k for k in keys if k not in ("preset", "lengths_m")]
        if extra:
            raise r.fail(keys[extra[0]], f"{where}.{extra[0]}", "cannot be combined with 'preset' "
                         "(a preset fixes stature, sex and proportions; adjust it with lengths_m)")
        base = _morphology(r, keys["preset"], f"{where}.preset")
    else:
        sex = r.string(keys["sex"], f"{where}.sex") if "sex" in keys else "male"
        if sex not in ("male", "female"):
            raise r.fail(keys["sex"], f"{where}.sex", f"expected 'male' or 'female', found {sex!r}")
        proportions = r.string(keys["proportions"], f"{where}.proportions") if "proportions" in keys else "adult"
        if proportions not in ("adult", "child"):
            raise r.fail(keys["proportions"], f"{where}.proportions",
                         f"expected 'adult' or 'child', found {proportions!r}")
        base = Morphology.from_stature(
            r.number(keys["stature_m"], f"{where}.stature_m", 0.3, 3.0, "m") if "stature_m" in keys else 1.75,
            sex=sex, proportions=proportions,
            leg_scale=r.number(keys["leg_scale"], f"{where}.leg_scale", 0.5, 1.5) if "leg_scale" in keys else 1.0,
            mass_kg=r.number(keys["mass_kg"], f"{where}.mass_kg", 5, 400, "kg") if "mass_kg" in keys else None,
            name=where)
    if "lengths_m" not in keys:
        return base
    seg_nodes = r.mapping(keys["lengths_m"], f"{where}.lengths_m", {k: False for k in LENGTH_KEYS})
    given = {seg: r.number(v, f"{where}.lengths_m.{seg}", 0.001, 2.0, "m")
             for seg, v in seg_nodes.items()}
    try:
        return with_lengths_m(base, given)
    except ValueError as exc:
        raise r.fail(keys["lengths_m"], f"{where}.lengths_m", str(exc)) from None


def _load_motion(r: _Reader, node: Node, where: str, base_dir: Path,
                 read: dict[Path, NormalizedMotion]) -> NormalizedMotion:
    """The motion a file holds; ``read`` (resolved path -> motion) keeps each file read once,
    however many names it is given (or an alias repeats)."""
    rel = r.string(node, where)
    path = (base_dir / rel) if not Path(rel).is_absolute() else Path(rel)
    if path.is_dir():
        raise r.fail(node, where, f"{rel!r} is a folder, not a motion file (looked at {path})")
    if not path.is_file():
        raise r.fail(node, where, f"motion file {rel!r} not found (looked at {path})")
    if path.resolve() not in read:
        read[path.resolve()] = _read_motion(r, node, where, path, rel)
    return read[path.resolve()]


class _Fails(Protocol):
    """What :func:`_read_motion` reports through: a :class:`_Reader`, or a clip's own reader."""

    def fail(self, node: Node | None, where: str, message: str) -> EcsAnimError: ...


def _read_motion(r: _Fails, node: Node | None, where: str, path: Path,
                 rel: str) -> NormalizedMotion:
    from .c3d_import import import_c3d
    from .importing import import_bvh

    try:
        if path.suffix.lower() == ".nmo":
            return load_nmo(path)
        if path.suffix.lower() == ".bvh":
            return import_bvh(path)
        if path.suffix.lower() == ".c3d":
            return import_c3d(path)
    except EcsAnimError as exc:
        raise r.fail(node, where, f"cannot load motion: {exc}") from None
    raise r.fail(node, where, f"expected a .bvh, .c3d or .nmo file, found {rel!r}")


def _fill_absent(r: _Reader, motions: dict[str, NormalizedMotion], name: str, node: Node) -> None:
    """``motions.NAME.absent_from: OTHER``: the body parts NAME's capture lacks (a lower-body
    C3D's trunk, head and arms) are played from motion OTHER, looped, instead of a neutral
    pose."""
    from .c3d_import import fill_absent_from

    where = f"motions.{name}.absent_from"
    other = r.string(node, where)
    if other == name or other not in motions:
        hint = did_you_mean(other, [m for m in motions if m != name])
        raise r.fail(node, where, f"no other motion named {other!r}{hint}")
    if not motions[name].info.get("absent"):
        raise r.fail(node, where, f"{name!r} has every body part: nothing to take from {other!r}")
    motions[name] = fill_absent_from(motions[name], motions[other], other)


CHARACTER_KEYS = {"name": True, "morphology": True, "motion": False, "position_m": False,
                  "heading_deg": False, "speed": False, "loop": False, "start_s": False,
                  "then": False, "team": False, "constraints": False, "com_control": False,
                  "com_target_m": False, "locomotion": False, "path_m": False,
                  "speed_m_s": False}
STEERING_KEYS = ("locomotion", "path_m", "speed_m_s")


def _travels(motion: NormalizedMotion) -> bool:
    """Whether a motion's root goes somewhere over the clip (a walk, not an idle)."""
    root = motion.poses.root_position[:, :2]
    return bool(np.linalg.norm(root[-1] - root[0]) > 1e-3 * max(motion.n_frames, 1))


def _steering(r: _Reader, keys: dict[str, Node], where: str, motions: dict[str, NormalizedMotion],
              start_m: tuple[float, float]) -> SteeringSpec | None:
    """A character's ``locomotion``, ``path_m`` and ``speed_m_s`` (None: none of them)."""
    if not any(k in keys for k in STEERING_KEYS):
        return None
    if "locomotion" not in keys:
        given = next(k for k in STEERING_KEYS if k in keys)
        raise r.fail(keys[given], f"{where}.{given}", "a steered character needs a locomotion "
                     "set: locomotion: {idle: MOTION, walk: MOTION} (run: optional)")
    lwhere = f"{where}.locomotion"
    lk = r.mapping(keys["locomotion"], lwhere, {"idle": False, "walk": True, "run": False})
    locomotion: dict[str, str] = {}
    for gait, node in lk.items():
        name = r.string(node, f"{lwhere}.{gait}")
        if name not in motions:
            raise r.fail(node, f"{lwhere}.{gait}", f"unknown motion {name!r}"
                         f"{did_you_mean(name, list(motions))} (motions: {', '.join(motions)})")
        if gait != "idle" and not _travels(motions[name]):
            raise r.fail(node, f"{lwhere}.{gait}", f"motion {name!r} does not travel (its root "
                         f"ends where it starts): a {gait} must go somewhere")
        locomotion[gait] = name
    path: list[tuple[float, float]] = []
    if "path_m" in keys:
        pwhere = f"{where}.path_m"
        points = r.sequence(keys["path_m"], pwhere, MAX_WAYPOINTS - 1, "waypoints")
        if not points:
            raise r.fail(keys["path_m"], pwhere, "a path needs at least 1 waypoint [x, y] (m)")
        for j, point in enumerate(points):
            xy = r.vector2(point, f"{pwhere}[{j}]", "m", MAX_COORDINATE_M)
            r.too_far(point, f"{pwhere}[{j}]", math.dist(xy, start_m), "the waypoint",
                      "the character's position_m")
            path.append(xy)
        if "idle" not in locomotion:
            raise r.fail(keys["locomotion"], lwhere, "a character given path_m stops on its "
                         "idle motion at the end: add idle: MOTION")
    speed = (r.number(keys["speed_m_s"], f"{where}.speed_m_s", 0.0, 20.0, "m/s")
             if "speed_m_s" in keys else None)
    return SteeringSpec(locomotion, tuple(path), speed)


def apply_steering(sim: Simulation, entity: int, spec: SteeringSpec, heading_rad: float) -> None:
    """Give a spawned character its scenario steering: its locomotion set, then its path, or
    its speed along ``heading_rad`` (without ``speed_m_s`` nor a path it stands on its idle
    motion, or walks on at its own speed if it has none)."""
    loco = spec.locomotion
    sim.set_locomotion(entity, loco["walk"], loco.get("idle"), loco.get("run"))
    if spec.path_m:
        sim.follow_path(entity, spec.path_m, spec.speed_m_s)
    elif spec.speed_m_s is not None or "idle" not in loco:
        sim.steer(entity, heading_rad, spec.speed_m_s)


def _constraint(r: _Reader, node: Node, where: str, in_motion: bool = False,
                origin_m: tuple[float, ...] | None = None,
                motion_names: tuple[str, ...] = ()) -> tuple[ConstraintEntry, Node | None]:
    """One constraint entry; returns it and the node naming a target character (checked once
    every character is known). Everything else is checked here, against a scratch table, so a
    mistake is reported with its line. A target ``point:`` without ``character:`` is on the
    constrained character itself; ``in_motion`` (constraints stored with a motion) allows only
    those. A ``world_m`` target lies within :data:`MAX_TARGET_DISTANCE_M` of ``origin_m``
    (x, y, z), the character's start on the ground."""
    from .body_points import GROUPS, body_point
    from .constraint_table import KIND_NAMES, Area, ConstraintTable, Target

    keys = r.mapping(node, where, {"name": True, "kind": False, "point": True, "fraction": False,
                                   "offset_m": False, "chain": False, "priority": False,
                                   "target": True, "activation": False, "distance_m": False,
                                   "area": False, "axis": False})
    name = r.string(keys["name"], f"{where}.name")
    kind = r.string(keys["kind"], f"{where}.kind") if "kind" in keys else "position"
    if kind not in KIND_NAMES:
        hint = did_you_mean(kind, list(KIND_NAMES))
        raise r.fail(keys["kind"], f"{where}.kind", f"unknown kind {kind!r}{hint} "
                                                    f"(kinds: {', '.join(KIND_NAMES)})")

    def point_of(pkeys: dict[str, Node], pwhere: str, point_key: str,
                 as_target: bool = False) -> tuple[str, float | None, tuple[float, float, float]]:
        point = r.string(pkeys[point_key], f"{pwhere}.{point_key}")
        fraction = r.number(pkeys["fraction"], f"{pwhere}.fraction", 0.0, 1.0) if "fraction" in pkeys else None
        offset = r.vector3(pkeys["offset_m"], f"{pwhere}.offset_m", "m", 10.0) if "offset_m" in pkeys else (0.0, 0.0, 0.0)
        try:
            body_point(point, fraction, offset, as_target)
        except ValueError as exc:
            raise r.fail(pkeys[point_key], f"{pwhere}.{point_key}", str(exc)) from None
        return point, fraction, offset

    point, fraction, offset = point_of(keys, where, "point")
    priority = r.number(keys["priority"], f"{where}.priority", -1e6, 1e6) if "priority" in keys else 0.0
    if "activation" in keys:
        ak = r.mapping(keys["activation"], f"{where}.activation",
                       {"start_s": False, "stop_s": False, "ease_in_s": False, "ease_out_s": False,
                        "motion": False, "by_trigger": False})
        clock_motion, by_trigger = _activation_clock(r, ak, f"{where}.activation", in_motion,
                                                     motion_names)
        values = {k: r.number(v, f"{where}.activation.{k}", 0.0, 1e6, "s") for k, v in ak.items()
                  if k not in ("motion", "by_trigger")}
        try:
            activation = Activation(values.get("start_s", 0.0), values.get("stop_s", 1e6),
                                    values.get("ease_in_s", 0.0), values.get("ease_out_s", 0.0))
            if by_trigger:
                activation = switched_off(activation.ease_in_s, activation.ease_out_s)
        except ValueError as exc:
            raise r.fail(keys["activation"], f"{where}.activation", str(exc)) from None
    else:
        activation, clock_motion = Activation(0.0, 1e6), None
    options: dict[str, Any] = {"kind": kind, "fraction": fraction, "offset_m": offset}
    if "chain" in keys:
        chain = []
        for j, gn in enumerate(r.sequence(keys["chain"], f"{where}.chain")):
            group = r.string(gn, f"{where}.chain[{j}]")
            if group not in GROUPS:
                hint = did_you_mean(group, list(GROUPS))
                raise r.fail(gn, f"{where}.chain[{j}]", f"unknown group {group!r}{hint} "
                                                       f"(groups: {', '.join(GROUPS)})")
            chain.append(group)
        options["chain"] = tuple(chain)
    if "distance_m" in keys:
        if kind != "distance":
            raise r.fail(keys["distance_m"], f"{where}.distance_m", f"only a distance constraint "
                         f"takes distance_m (this one is kind {kind!r})")
        options["distance_m"] = r.number(keys["distance_m"], f"{where}.distance_m", 0.0, 100.0, "m")
    if "axis" in keys:
        options["axis"] = r.vector3(keys["axis"], f"{where}.axis", "", 1e3)
    if "area" in keys:
        ak = r.mapping(keys["area"], f"{where}.area", {"shape": True, "low_m": False, "high_m": False,
                                                       "radius_m": False, "normal": False,
                                                       "inside": False})
        aw = f"{where}.area"
        try:
            options["area"] = Area(
                r.string(ak["shape"], f"{aw}.shape"),
                r.vector3(ak["low_m"], f"{aw}.low_m", "m", MAX_TARGET_DISTANCE_M) if "low_m" in ak else (0.0, 0.0, 0.0),
                r.vector3(ak["high_m"], f"{aw}.high_m", "m", MAX_TARGET_DISTANCE_M) if "high_m" in ak else (0.0, 0.0, 0.0),
                r.number(ak["radius_m"], f"{aw}.radius_m", 0.0, MAX_TARGET_DISTANCE_M, "m") if "radius_m" in ak else 0.0,
                r.vector3(ak["normal"], f"{aw}.normal", "", 1e3) if "normal" in ak else (0.0, 0.0, 1.0),
                r.boolean(ak["inside"], f"{aw}.inside") if "inside" in ak else True)
        except ValueError as exc:
            raise r.fail(keys["area"], aw, str(exc)) from None
    tk = r.mapping(keys["target"], f"{where}.target",
                   {"world_m": False, "direction": False, "character": False, "point": False,
                    "joint": False, "fraction": False, "offset_m": False})
    given: list[str] = [k for k in ("world_m", "direction", "character") if k in tk]
    if not given and ("point" in tk or "joint" in tk):
        given = ["self"]
    if in_motion and given != ["self"]:
        raise r.fail(keys["target"], f"{where}.target", "a motion's constraint aims at a point of "
                     "the same body: give point: (and fraction:, offset_m:) only")
    if len(given) != 1:
        raise r.fail(keys["target"], f"{where}.target", "give one of world_m: [x, y, z], "
                     "direction: [x, y, z] (orientation), point: POINT (this character) or "
                     "character: NAME with point: POINT")
    target_world, other, target_point, who = None, None, None, None
    if given[0] in ("world_m", "direction"):
        for extra in ("point", "joint", "fraction", "offset_m"):
            if extra in tk:
                raise r.fail(tk[extra], f"{where}.target.{extra}", "only with character:")
        if (given[0] == "direction") != (kind == "orientation"):
            raise r.fail(tk[given[0]], f"{where}.target.{given[0]}",
                         "an orientation aims along direction: [x, y, z] or looks at a character's "
                         "point" if kind == "orientation" else "direction: is for orientation constraints")
        keyframes = None
        if given[0] == "world_m" and isinstance(tk["world_m"], yaml.SequenceNode) and \
                tk["world_m"].value and isinstance(tk["world_m"].value[0], yaml.MappingNode):
            keyframes = _keyframes(r, tk["world_m"], f"{where}.target.world_m")
            target_world = keyframes[1][0]
        else:
            target_world = r.vector3(tk[given[0]], f"{where}.target.{given[0]}", "m", 1e5)
        for far in (keyframes[1] if keyframes else ()):
            if origin_m is not None:
                r.too_far(tk["world_m"], f"{where}.target.world_m", math.dist(far, origin_m),
                          "a keyframe", "the character's start (position_m, on the ground)")
        if given[0] == "world_m" and origin_m is not None:
            r.too_far(tk["world_m"], f"{where}.target.world_m",
                      math.dist(target_world, origin_m), "the target",
                      "the character's start (position_m, on the ground)")
    else:
        if ("point" in tk) == ("joint" in tk):
            raise r.fail(keys["target"], f"{where}.target", "character: needs point: (a joint or "
                                                            "a segment of that character)")
        key = "point" if "point" in tk else "joint"
        target_point, t_fraction, t_offset = point_of(tk, f"{where}.target", key, as_target=True)
        options["target_fraction"], options["target_offset_m"] = t_fraction, t_offset
        if "character" in tk:
            other, who = r.string(tk["character"], f"{where}.target.character"), tk["character"]
    # Everything but the target character's existence, checked now (with this line).
    target = Target(row=0, point=body_point(target_point, options.get("target_fraction"),
                                            options.get("target_offset_m", (0.0, 0.0, 0.0)), True)) \
        if target_point else Target(world_m=target_world)
    checks = {k: v for k, v in options.items() if k in ("chain", "distance_m", "area", "axis")}
    try:
        ConstraintTable().add(name, 0, kind, body_point(point, fraction, offset,
                                                        segment=kind == "orientation"), target, priority,
                              activation, **checks)
    except ValueError as exc:
        raise r.fail(node, where, str(exc)) from None
    entry = ConstraintEntry(name, point, priority, activation, target_world, other, target_point,
                            options, clock_motion)
    if given[0] == "world_m":
        entry.target_keyframes = keyframes
    return entry, who


def _com_target(r: _Reader, keys: dict[str, Node], where: str,
                position: tuple[float, ...]) -> tuple[float, float] | None:
    """A character's desired centre of mass (x, y), which must lie over its feet: within
    :data:`MAX_COM_OFFSET_M` of its position."""
    if "com_target_m" not in keys:
        return None
    xy = r.vector2(keys["com_target_m"], f"{where}.com_target_m", "m", 1e5)
    away = math.hypot(xy[0] - position[0], xy[1] - position[1])
    if away > MAX_COM_OFFSET_M:
        raise r.fail(keys["com_target_m"], f"{where}.com_target_m", f"{away:.2f} m from the "
                     f"character's position_m: the centre of mass must stay over its feet (within "
                     f"{MAX_COM_OFFSET_M:g} m)")
    return (xy[0], xy[1])


def _compose(path: Path, what: str, label: str) -> Node:
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


def _refuse_clip(path: Path) -> None:
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
    elif suffix == ".nmo":
        what, how = "an .nmo motion", where
    elif head.startswith(b"PK\x03\x04"):
        what, how = "a zip archive (an .nmo motion?)", where
    else:
        return
    raise InputError(path, f"a scenario YAML was expected, not {what}; to play it, {how}")


def _motion_name(r: _Reader, n: Node, w: str, motions: dict[str, NormalizedMotion]) -> str:
    """The name of one of ``motions`` at node ``n`` (``w`` its place in the file), or a
    ``file:line:`` error with "did you mean"."""
    c = r.string(n, w)
    if c not in motions:
        hint = did_you_mean(c, list(motions))
        raise r.fail(n, w, f"unknown motion {c!r}{hint} (motions: {', '.join(motions)})")
    return c


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario; motions are loaded (BVH imported) here, once."""
    path = Path(path)
    r = _Reader(str(path))
    _refuse_clip(path)
    root = _compose(path, "scenario", "the scenario")
    top = r.mapping(root, "", {"duration_s": True, "fps": False, "motions": True,
                               "ground": False, "characters": True, "description": False,
                               "camera": False, "tables": False, "triggers": False})
    fps = r.number(top["fps"], "fps", 1.0, 1000.0, "Hz") if "fps" in top else 30.0
    duration = r.number(top["duration_s"], "duration_s", 1.0 / fps, MAX_DURATION_S, "s")
    motion_nodes = top["motions"]
    if not isinstance(motion_nodes, yaml.MappingNode) or not motion_nodes.value:
        raise r.fail(motion_nodes, "motions", "expected a mapping name: file (.bvh, .c3d or .nmo)")
    motions: dict[str, NormalizedMotion] = {}
    fills: list[tuple[str, Node]] = []
    read: dict[Path, NormalizedMotion] = {}
    for key_node, value in motion_nodes.value:
        if not isinstance(key_node, yaml.ScalarNode) or not NAME_PATTERN.fullmatch(str(key_node.value)):
            raise r.fail(key_node, "motions", "motion names must be plain names (letters, digits, "
                                              "_ . -)")
        name = str(key_node.value)
        if name in motions:
            raise r.fail(key_node, f"motions.{name}", "given twice")
        if isinstance(value, yaml.MappingNode):  # {file: ..., absent_from: OTHER}
            mk = r.mapping(value, f"motions.{name}", {"file": True, "absent_from": False})
            motions[name] = _load_motion(r, mk["file"], f"motions.{name}.file", path.parent,
                                         read)
            if "absent_from" in mk:
                fills.append((name, mk["absent_from"]))
        else:
            motions[name] = _load_motion(r, value, f"motions.{name}", path.parent, read)
    for name, node in fills:
        _fill_absent(r, motions, name, node)
    ground = _ground(r, top["ground"], "ground") if "ground" in top else Plane()
    characters: list[CharacterSpec] = []
    names: set[str] = set()
    pending_targets: list[tuple[str | None, Node, str]] = []
    n_constraints = 0
    for i, node in enumerate(r.sequence(top["characters"], "characters", MAX_CHARACTERS, "characters")):
        where = f"characters[{i}]"
        keys = r.mapping(node, where, CHARACTER_KEYS)
        name = r.string(keys["name"], f"{where}.name")
        if not NAME_PATTERN.fullmatch(name):
            raise r.fail(keys["name"], f"{where}.name", f"{name!r}: a character name names its "
                         "exported files, so it must be letters, digits, _ . - (not starting with .)")
        if len(name) > MAX_NAME_LENGTH:
            raise r.fail(keys["name"], f"{where}.name", f"a character name has at most "
                         f"{MAX_NAME_LENGTH} characters (it names files), got {len(name)}")
        if name in names:
            raise r.fail(keys["name"], f"{where}.name", f"another character is already named {name!r}")
        names.add(name)

        clip = partial(_motion_name, r, motions=motions)

        queue = _queued_clips(r, keys["then"], f"{where}.then", clip, MAX_QUEUE) if "then" in keys else ()
        position = r.vector2(keys["position_m"], f"{where}.position_m", "m", 1e5) \
            if "position_m" in keys else (0.0, 0.0)
        steering = _steering(r, keys, where, motions, position)
        if "motion" in keys:
            first_clip = clip(keys["motion"], f"{where}.motion")
        elif steering is not None:  # a locomotion set starts standing (or walking, without idle)
            first_clip = steering.locomotion.get("idle", steering.locomotion["walk"])
        else:
            raise r.fail(node, where, "missing required key 'motion' (or a locomotion set: "
                         "locomotion)")
        player = MotionPlayer(
            first_clip,
            speed=r.number(keys["speed"], f"{where}.speed", 0.0, 10.0) if "speed" in keys else 1.0,
            loop=r.boolean(keys["loop"], f"{where}.loop") if "loop" in keys else True,
            start_s=r.number(keys["start_s"], f"{where}.start_s", 0.0, MAX_DURATION_S, "s") if "start_s" in keys else 0.0,
            queue=queue)
        heading = r.number(keys["heading_deg"], f"{where}.heading_deg", -360, 360, "degrees") \
            if "heading_deg" in keys else 0.0
        constraints: list[ConstraintEntry] = []
        own = r.sequence(keys["constraints"], f"{where}.constraints") if "constraints" in keys else []
        n_constraints += len(own)
        if n_constraints > MAX_CONSTRAINTS:
            raise r.fail(keys["constraints"], f"{where}.constraints", f"at most {MAX_CONSTRAINTS:,} "
                         f"constraints over all characters, found {n_constraints:,} by here (an "
                         "alias counted each time it is used)")
        for j, cn in enumerate(own):
            on_ground = (*position, float(ground.height(np.array(position, dtype=float))))
            entry, who = _constraint(r, cn, f"{where}.constraints[{j}]", origin_m=on_ground,
                                     motion_names=tuple(motions))
            if any(c.name == entry.name for c in constraints):
                raise r.fail(cn, f"{where}.constraints[{j}].name",
                             f"{entry.name!r} is used twice on {name!r}")
            if entry.target_character in (None, name) and entry.aims_at_itself():
                raise r.fail(cn, f"{where}.constraints[{j}].target", "the target is the "
                             "constrained point itself")
            constraints.append(entry)
            if who is not None:
                pending_targets.append((entry.target_character, who, f"{where}.constraints[{j}]"))
            elif entry.target_point is not None:
                entry.target_character = name  # a point of this character itself
        characters.append(CharacterSpec(
            name, _morphology(r, keys["morphology"], f"{where}.morphology"), player,
            Placement((position[0], position[1]), math.radians(heading)),
            r.string(keys["team"], f"{where}.team", empty=True) if "team" in keys else "", constraints,
            r.boolean(keys["com_control"], f"{where}.com_control") if "com_control" in keys else True,
            _com_target(r, keys, where, position), steering))
    if not characters:
        raise r.fail(top["characters"], "characters", "expected at least one character")
    for other, node, cwhere in pending_targets:
        if other not in names:
            hint = did_you_mean(str(other), sorted(names))
            raise r.fail(node, f"{cwhere}.target.character", f"no character named {other!r}{hint}")
    camera: dict[str, Any] = {}
    if "camera" in top:
        ck = r.mapping(top["camera"], "camera", {"yaw_deg": False, "pitch_deg": False,
                                                 "distance_m": False, "target_m": False})
        if "yaw_deg" in ck:
            camera["yaw_deg"] = r.number(ck["yaw_deg"], "camera.yaw_deg", -360, 360, "degrees")
        if "pitch_deg" in ck:
            camera["pitch_deg"] = r.number(ck["pitch_deg"], "camera.pitch_deg", -89, 89, "degrees")
        if "distance_m" in ck:
            camera["distance_m"] = r.number(ck["distance_m"], "camera.distance_m", 0.1, 1e4, "m")
        if "target_m" in ck:
            camera["target_m"] = r.vector3(ck["target_m"], "camera.target_m", "m", 1e5)
    starts = np.array([c.placement.position_m for c in characters])
    tables = [_table(r, node, f"tables[{i}]", starts) for i, node in
              enumerate(r.sequence(top["tables"], "tables", MAX_TABLES, "tables") if "tables" in top else [])]
    refs: list[tuple[int, str]] = []
    triggers = _scenario_triggers(r, top, characters, motions, refs)
    return Scenario(str(path), duration, fps, motions, ground, characters, camera, tables,
                    (str(path),) + tuple(str(p) for p in read), triggers, refs)


def _queued_clips(r: _Reader, node: Node, where: str, clip: Callable[[Node, str], str],
                  most: int) -> tuple[QueuedClip, ...]:
    """A ``then:`` list of clips to play next (at most ``most``); ``clip`` reads a motion name."""
    queued = r.sequence(node, where)
    if len(queued) > most:
        raise r.fail(node, where, f"at most {most} clips can be queued")
    queue = []
    for j, q in enumerate(queued):
        qw = f"{where}[{j}]"
        qk = r.mapping(q, qw, {"motion": True, "crossfade_s": False, "loop": False})
        queue.append(QueuedClip(
            clip(qk["motion"], f"{qw}.motion"),
            r.number(qk["crossfade_s"], f"{qw}.crossfade_s", 0.0, 10.0, "s") if "crossfade_s" in qk else 0.3,
            r.boolean(qk["loop"], f"{qw}.loop") if "loop" in qk else False))
    return tuple(queue)


def _table(r: _Reader, node: Node, where: str, starts: np.ndarray) -> Table:
    """A table; ``starts`` (n_characters, 2) the characters' positions, m: the table stands
    within :data:`MAX_TARGET_DISTANCE_M` of one."""
    keys = r.mapping(node, where, {"centre_m": True, "size_m": True, "height_m": True,
                                   "heading_deg": False})
    size = r.vector2(keys["size_m"], f"{where}.size_m", "m", MAX_TARGET_DISTANCE_M)
    if min(size) <= 0:
        raise r.fail(keys["size_m"], f"{where}.size_m", "a table's length and width must be > 0")
    centre = r.vector2(keys["centre_m"], f"{where}.centre_m", "m", 1e5)
    r.too_far(keys["centre_m"], f"{where}.centre_m",
              float(np.min(np.linalg.norm(starts - np.array(centre), axis=-1))), "the table",
              "the nearest character's position_m")
    return Table(centre,
                 size,
                 r.number(keys["height_m"], f"{where}.height_m", 0.1, 3.0, "m"),
                 math.radians(r.number(keys["heading_deg"], f"{where}.heading_deg", -360, 360, "degrees"))
                 if "heading_deg" in keys else 0.0)


def load_motion_constraints(path: str | Path) -> list[ConstraintSpec]:
    """Constraints to store with a motion (``ecs-anim import --constraints FILE.yaml``): a
    ``constraints:`` list in the scenario syntax, each aiming at a point of the same body, with
    activation times in the motion's own time (docs/scenarios.md)."""
    path = Path(path)
    r = _Reader(str(path))
    root = _compose(path, "constraints", "the constraints file")
    top = r.mapping(root, "", {"constraints": True})
    specs, names = [], set()
    for j, node in enumerate(r.sequence(top["constraints"], "constraints")):
        entry, _ = _constraint(r, node, f"constraints[{j}]", in_motion=True)
        if entry.name in names:
            raise r.fail(node, f"constraints[{j}].name", f"{entry.name!r} is used twice")
        if entry.aims_at_itself():
            raise r.fail(node, f"constraints[{j}].target", "the target is the constrained point itself")
        names.add(entry.name)
        specs.append(entry.to_spec())
    return specs


def build_simulation(scenario: Scenario, window: bool = False,
                     rotations: bool = False) -> Simulation:
    """A :class:`~ecs_anim.simulation.Simulation` with the scenario's characters spawned."""
    sim = Simulation(scenario.motions, scenario.ground, scenario.fps, window=window,
                     rotations=rotations)
    sim.tables = tuple(scenario.tables)
    entities = {c.name: sim.spawn(c.name, c.morphology, c.player, c.placement, c.team,
                                  c.com_control, c.com_target_xy)
                for c in scenario.characters}
    added: dict[tuple[int, str], int] = {}
    for i, c in enumerate(scenario.characters):
        for k in c.constraints:
            clock = -1 if k.clock_motion is None else sim.bank.index(k.clock_motion)
            uid = sim.add_constraint(entities[c.name], k.name, k.point, k.priority, k.activation,
                                     k.target_in_world,
                                     None if k.target_character is None else entities[k.target_character],
                                     k.target_point, **k.options, clock=clock)
            added[i, k.name] = uid
            if k.target_keyframes is not None:
                sim.add_target_track(uid, *k.target_keyframes)
    for c in scenario.characters:
        if c.steering is not None:
            apply_steering(sim, entities[c.name], c.steering, c.placement.heading_rad)
    order = [entities[c.name] for c in scenario.characters]
    uids = {placeholder: added[ref] for placeholder, ref in enumerate(scenario.trigger_constraints)
            if ref in added}
    for trigger in scenario.triggers:
        missing = [scenario.trigger_constraints[u] for x in (trigger.when, *trigger.then)
                   for u in constraints_named(x) if u not in uids]
        if missing:
            who, name = missing[0]
            raise EcsAnimError(f"trigger {trigger.name!r} names constraint "
                               f"{scenario.characters[who].name}.{name}, which is not in the scenario")
        sim.add_trigger(_bind_trigger(trigger, order, uids))
    return sim


# --- triggers, keyframed targets (ecs_anim.events) ----------------------------------------------
# Triggers are read after every character: they name characters, their points, clips and
# constraints ("character.constraint"). At load a trigger holds scenario indices in place of
# entity ids and constraint ids (the character's index in ``characters``; a constraint's index
# in ``Scenario.trigger_constraints``, which holds (character index, constraint name));
# build_simulation maps them to the simulation's (:func:`_bind_trigger`).

#: At most this many triggers in a scenario.
MAX_TRIGGERS = 100_000

WHEN_KEYS = {"clip_started": ("character.motion or character",),
             "clip_ended": ("character.motion or character",),
             "near": ("character.point", "to", "within_m", "fraction", "to_fraction"),
             "reached": ("character.constraint", "within_m"),
             "contact_began": ("character", "foot"),
             "at_s": ("seconds",),
             "removed": ("character",)}
ACTION_KEYS = {"play": ("crossfade_s", "loop", "from_s", "then"),
               "switch_on": ("for_s",),
               "switch_off": (),
               "move_target": ("world_m",),
               "set_body": ("morphology", "blend_s"),
               "remove": (),
               "arm": ()}


def _split_ref(r: _Reader, node: Node, where: str, characters: list[CharacterSpec],
               what: str, optional: bool = False) -> tuple[int, str | None]:
    """``character.thing`` (``character`` alone with ``optional``) -> (character index, thing or
    None). The thing follows the last dot (character names may hold dots)."""
    text = r.string(node, where)
    names = [c.name for c in characters]
    who, thing = (text, None) if text in names or "." not in text else text.rsplit(".", 1)
    if who not in names:
        hint = did_you_mean(who, names)
        raise r.fail(node, where, f"no character named {who!r}{hint} (expected "
                                  f"{'character' if what == '' else 'character.' + what})")
    if thing is None and not optional:
        raise r.fail(node, where, f"expected character.{what}, found {text!r}")
    return names.index(who), thing


def _constraint_ref(r: _Reader, node: Node, where: str, characters: list[CharacterSpec],
                    refs: list[tuple[int, str]]) -> int:
    """``character.constraint`` -> its placeholder id at load: its index in ``refs`` (character
    index, constraint name), added there if new."""
    who, name = _split_ref(r, node, where, characters, "constraint")
    own = [k.name for k in characters[who].constraints]
    if name not in own:
        hint = did_you_mean(str(name), own)
        raise r.fail(node, where, f"{characters[who].name!r} has no constraint {name!r}{hint} "
                     f"(it has: {listed(own) or 'none'})")
    if (who, str(name)) not in refs:
        refs.append((who, str(name)))
    return refs.index((who, str(name)))


def _clip_ref(r: _Reader, node: Node, where: str, characters: list[CharacterSpec],
              motions: dict[str, NormalizedMotion], optional: bool) -> tuple[int, str | None]:
    who, clip = _split_ref(r, node, where, characters, "motion", optional)
    if clip is not None and clip not in motions:
        hint = did_you_mean(clip, list(motions))
        raise r.fail(node, where, f"unknown motion {clip!r}{hint} (motions: {', '.join(motions)})")
    return who, clip


def _point_ref(r: _Reader, node: Node, where: str, characters: list[CharacterSpec],
               fraction: float | None) -> tuple[int, BodyPoint]:
    from .body_points import body_point

    who, point = _split_ref(r, node, where, characters, "point")
    try:
        return who, body_point(str(point), fraction, as_target=True)
    except ValueError as exc:
        raise r.fail(node, where, str(exc)) from None


def _kind_of(r: _Reader, node: Node, where: str, kinds: dict[str, Any], what: str) -> str:
    """The kind of a trigger's condition or action: its mapping's first key, one of ``kinds``."""
    if not isinstance(node, yaml.MappingNode) or not node.value:
        raise r.fail(node, where, f"expected a mapping with one of {', '.join(kinds)}")
    kind = str(node.value[0][0].value)
    if kind not in kinds:
        hint = did_you_mean(kind, list(kinds))
        raise r.fail(node.value[0][0], f"{where}.{kind}", f"unknown {what}{hint} (expected one "
                     f"of {', '.join(kinds)})")
    return kind


def _when(r: _Reader, node: Node, where: str, characters: list[CharacterSpec],
          motions: dict[str, NormalizedMotion], refs: list[tuple[int, str]]) -> Condition:
    from .events import AtTime, ClipEnded, ClipStarted, ContactBegan, Near, Reached, Removed

    kind = _kind_of(r, node, where, WHEN_KEYS, "condition")
    allowed = {kind: True} | {k: False for k in WHEN_KEYS[kind][1:]}
    if kind == "near":
        allowed |= {"to": True, "within_m": True}
    keys = r.mapping(node, where, allowed)
    w = f"{where}.{kind}"
    if kind in ("clip_started", "clip_ended"):
        who, clip = _clip_ref(r, keys[kind], w, characters, motions, optional=True)
        return (ClipStarted if kind == "clip_started" else ClipEnded)(who, clip)
    if kind == "near":
        frac = {k: r.number(keys[k], f"{where}.{k}", 0.0, 1.0) for k in ("fraction", "to_fraction")
                if k in keys}
        who, point = _point_ref(r, keys["near"], w, characters, frac.get("fraction"))
        other, other_point = _point_ref(r, keys["to"], f"{where}.to", characters,
                                        frac.get("to_fraction"))
        return Near(who, point, other, other_point,
                    r.number(keys["within_m"], f"{where}.within_m", 0.0, MAX_TARGET_DISTANCE_M, "m"))
    if kind == "reached":
        return Reached(_constraint_ref(r, keys["reached"], w, characters, refs),
                       r.number(keys["within_m"], f"{where}.within_m", 0.0, 10.0, "m")
                       if "within_m" in keys else 0.001)
    if kind == "contact_began":
        who, _ = _split_ref(r, keys[kind], w, characters, "", optional=True)
        foot = r.string(keys["foot"], f"{where}.foot") if "foot" in keys else None
        if foot not in (None, "left", "right"):
            raise r.fail(keys["foot"], f"{where}.foot", f"expected left or right, found {foot!r}")
        return ContactBegan(who, foot)
    if kind == "at_s":
        return AtTime(r.number(keys[kind], w, 0.0, MAX_DURATION_S, "s"))
    who, _ = _split_ref(r, keys[kind], w, characters, "", optional=True)
    return Removed(who)


def _action(r: _Reader, node: Node, where: str, characters: list[CharacterSpec],
            motions: dict[str, NormalizedMotion], queued: Any, refs: list[tuple[int, str]],
            trigger_names: list[str]) -> Action:
    from .events import Arm, MoveTarget, Play, Remove, SetBody, SwitchOff, SwitchOn

    kind = _kind_of(r, node, where, ACTION_KEYS, "action")
    allowed = {kind: True} | {k: False for k in ACTION_KEYS[kind]}
    if kind == "move_target":
        allowed["world_m"] = True
    if kind == "set_body":
        allowed["morphology"] = True
    keys = r.mapping(node, where, allowed)
    w = f"{where}.{kind}"
    if kind == "play":
        who, clip = _clip_ref(r, keys[kind], w, characters, motions, optional=False)
        return Play(who, str(clip),
                    r.number(keys["crossfade_s"], f"{where}.crossfade_s", 0.0, 10.0, "s")
                    if "crossfade_s" in keys else 0.3,
                    r.boolean(keys["loop"], f"{where}.loop") if "loop" in keys else False,
                    r.number(keys["from_s"], f"{where}.from_s", 0.0, MAX_DURATION_S, "s")
                    if "from_s" in keys else 0.0,
                    queued(keys["then"], f"{where}.then") if "then" in keys else ())
    if kind in ("switch_on", "switch_off", "move_target"):
        uid = _constraint_ref(r, keys[kind], w, characters, refs)
        if kind == "switch_off":
            return SwitchOff(uid)
        if kind == "switch_on":
            return SwitchOn(uid, r.number(keys["for_s"], f"{where}.for_s", 1e-3, MAX_DURATION_S, "s")
                            if "for_s" in keys else None)
        return MoveTarget(uid, r.vector3(keys["world_m"], f"{where}.world_m", "m", 1e5))
    if kind == "arm":
        other = r.string(keys[kind], w)
        if other not in trigger_names:
            hint = did_you_mean(other, trigger_names)
            raise r.fail(keys[kind], w, f"no trigger named {other!r}{hint}")
        return Arm(other)
    who, _ = _split_ref(r, keys[kind], w, characters, "", optional=True)
    if kind == "remove":
        return Remove(who)
    return SetBody(who, _morphology(r, keys["morphology"], f"{where}.morphology"),
                   r.number(keys["blend_s"], f"{where}.blend_s", 0.0, 600.0, "s")
                   if "blend_s" in keys else 0.0)


def _triggers(r: _Reader, node: Node, characters: list[CharacterSpec],
              motions: dict[str, NormalizedMotion], queued: Any,
              refs: list[tuple[int, str]]) -> list[Trigger]:
    """The scenario's ``triggers:`` (docs/scenarios.md, Triggers); a cycle of triggers that
    would fire each other forever in one tick is refused here, at the first one's line."""
    from .events import Trigger, find_cycle

    triggers: list[Trigger] = []
    nodes = r.sequence(node, "triggers", MAX_TRIGGERS, "triggers")
    names: list[str] = []  # every trigger's, first (an arm: action may name a later one)
    for i, tn in enumerate(nodes):
        keys = r.mapping(tn, f"triggers[{i}]", {"name": False, "when": True, "then": True,
                                                 "delay_s": False, "repeat": False, "armed": False})
        name = r.string(keys["name"], f"triggers[{i}].name") if "name" in keys else f"triggers[{i}]"
        if name in names:
            raise r.fail(keys.get("name", tn), f"triggers[{i}].name",
                         f"another trigger is named {name!r}")
        names.append(name)
    for i, tn in enumerate(nodes):
        where = f"triggers[{i}]"
        keys = r.mapping(tn, where, {"name": False, "when": True, "then": True, "delay_s": False,
                                     "repeat": False, "armed": False})
        name = names[i]
        actions = r.sequence(keys["then"], f"{where}.then")
        if not actions:
            raise r.fail(keys["then"], f"{where}.then", "expected at least one action")
        triggers.append(Trigger(
            name, _when(r, keys["when"], f"{where}.when", characters, motions, refs),
            tuple(_action(r, a, f"{where}.then[{j}]", characters, motions, queued, refs, names)
                  for j, a in enumerate(actions)),
            r.number(keys["delay_s"], f"{where}.delay_s", 0.0, MAX_DURATION_S, "s")
            if "delay_s" in keys else 0.0,
            r.boolean(keys["repeat"], f"{where}.repeat") if "repeat" in keys else False,
            r.boolean(keys["armed"], f"{where}.armed") if "armed" in keys else True))
    cycle = find_cycle(triggers)
    if cycle:
        path = " -> ".join(repr(triggers[i].name) for i in cycle + cycle[:1])
        raise r.fail(nodes[cycle[0]], f"triggers[{cycle[0]}]", f"triggers {path} would fire each "
                     "other forever in one tick (each repeats without delay): give one of them "
                     "delay_s, or drop its repeat")
    return triggers


def _keyframes(r: _Reader, node: Node, where: str) -> tuple[tuple[float, ...], tuple[tuple[float, float, float], ...]]:
    """A moving ``world_m`` target: a list of ``{t_s, at_m}``, times increasing."""
    frames = r.sequence(node, where)
    if not frames:
        raise r.fail(node, where, "expected at least one keyframe {t_s: S, at_m: [x, y, z]}")
    times: list[float] = []
    points: list[tuple[float, float, float]] = []
    for j, fn in enumerate(frames):
        fk = r.mapping(fn, f"{where}[{j}]", {"t_s": True, "at_m": True})
        t = r.number(fk["t_s"], f"{where}[{j}].t_s", 0.0, MAX_DURATION_S, "s")
        if times and t <= times[-1]:
            raise r.fail(fk["t_s"], f"{where}[{j}].t_s", f"keyframe times must increase: {t:g} s "
                         f"after {times[-1]:g} s")
        times.append(t)
        points.append(r.vector3(fk["at_m"], f"{where}[{j}].at_m", "m", 1e5))
    return tuple(times), tuple(points)


def _activation_clock(r: _Reader, keys: dict[str, Node], where: str, in_motion: bool,
                      motion_names: tuple[str, ...]) -> tuple[str | None, bool]:
    """An activation's ``motion:`` (its times in that clip's own time, while the character plays
    it) and ``by_trigger:`` (off until a trigger's switch_on); at most one of them."""
    if "motion" in keys and "by_trigger" in keys:
        raise r.fail(keys["by_trigger"], f"{where}.by_trigger", "give motion: or by_trigger:, not both")
    if in_motion and ("motion" in keys or "by_trigger" in keys):
        key = "motion" if "motion" in keys else "by_trigger"
        raise r.fail(keys[key], f"{where}.{key}", "a motion's own constraint runs in its clip's time "
                     "already")
    clock = None
    if "motion" in keys:
        clock = r.string(keys["motion"], f"{where}.motion")
        if clock not in motion_names:
            hint = did_you_mean(clock, list(motion_names))
            raise r.fail(keys["motion"], f"{where}.motion", f"unknown motion {clock!r}{hint} "
                         f"(motions: {', '.join(motion_names)})")
    by_trigger = r.boolean(keys["by_trigger"], f"{where}.by_trigger") if "by_trigger" in keys else False
    if by_trigger and ("start_s" in keys or "stop_s" in keys):
        key = "start_s" if "start_s" in keys else "stop_s"
        raise r.fail(keys[key], f"{where}.{key}", "a constraint switched on by a trigger takes only "
                     "ease_in_s and ease_out_s (the trigger's switch_on gives for_s)")
    return clock, by_trigger


def _scenario_triggers(r: _Reader, top: dict[str, Node], characters: list[CharacterSpec],
                       motions: dict[str, NormalizedMotion],
                       refs: list[tuple[int, str]]) -> list[Trigger]:
    """The ``triggers:`` of a scenario (none if absent); ``refs`` gets the constraints they name."""
    if "triggers" not in top:
        return []

    clip = partial(_motion_name, r, motions=motions)

    def queued(n: Node, w: str) -> tuple[QueuedClip, ...]:
        return _queued_clips(r, n, w, clip, MAX_QUEUE - 1)

    return _triggers(r, top["triggers"], characters, motions, queued, refs)


def _bind_trigger(trigger: Trigger, entities: list[int], uids: dict[int, int]) -> Trigger:
    """A trigger read at load with the simulation's entity ids and constraint ids."""
    def bind(item: Any) -> Any:
        changes: dict[str, int] = {}
        for key in ("entity", "other"):
            if hasattr(item, key):
                changes[key] = entities[getattr(item, key)]
        if hasattr(item, "uid"):
            changes["uid"] = uids[item.uid]
        return replace(item, **changes)

    return replace(trigger, when=bind(trigger.when), then=tuple(bind(a) for a in trigger.then))
