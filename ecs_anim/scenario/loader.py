"""Scenario files (YAML): who plays what, on which ground, for how long.

Every field is validated at load time; an error reads ``file:line: path.to.key: what was
expected, what was found`` and suggests the closest key on a typo. Nothing is checked in the
tick. The schema is documented in ``docs/scenarios.md``.
"""

from __future__ import annotations

import math
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from yaml import Node

from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.errors import (
    did_you_mean,
)
from ecs_anim.core.files import MAX_NAME_LENGTH, NAME_PATTERN
from ecs_anim.core.ground import Plane
from ecs_anim.motion.clip import NormalizedMotion
from ecs_anim.motion.constraints import Activation, ConstraintSpec
from ecs_anim.runtime.actions import switched_off
from ecs_anim.runtime.simulation import MAX_COORDINATE_M, MAX_DURATION_S
from ecs_anim.runtime.store import MAX_QUEUE, MAX_WAYPOINTS
from ecs_anim.scenario.bodies import read_morphology
from ecs_anim.scenario.grounds import read_ground
from ecs_anim.scenario.motions import fill_absent, load_motion, motion_name, queued_clips
from ecs_anim.scenario.reader import MAX_TARGET_DISTANCE_M, YamlReader, read_tree, refuse_clip
from ecs_anim.scenario.spec import CharacterSpec, ConstraintEntry, Scenario, SteeringSpec, Table
from ecs_anim.scenario.triggers import scenario_triggers

#: How far a desired centre of mass may lie from the character's position (over its feet).
MAX_COM_OFFSET_M = 1.0
MAX_CHARACTERS = 100_000
MAX_CONSTRAINTS = 100_000  # over all characters
MAX_TABLES = 1_000


CHARACTER_KEYS = {"name": True, "morphology": True, "motion": False, "position_m": False,
                  "heading_deg": False, "speed": False, "loop": False, "start_s": False,
                  "then": False, "team": False, "constraints": False, "com_control": False,
                  "com_target_m": False, "locomotion": False, "path_m": False,
                  "speed_m_s": False, "avoid": False}
STEERING_KEYS = ("locomotion", "path_m", "speed_m_s", "avoid")


def _travels(motion: NormalizedMotion) -> bool:
    """Whether a motion's root goes somewhere over the clip (a walk, not an idle)."""
    root = motion.poses.root_position[:, :2]
    return bool(np.linalg.norm(root[-1] - root[0]) > 1e-3 * max(motion.n_frames, 1))


def _steering(r: YamlReader, keys: dict[str, Node], where: str, motions: dict[str, NormalizedMotion],
              start_m: tuple[float, float]) -> SteeringSpec | None:
    """A character's ``locomotion``, ``path_m``, ``speed_m_s`` and ``avoid`` (None: none of
    them)."""
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
    avoid = r.boolean(keys["avoid"], f"{where}.avoid") if "avoid" in keys else True
    return SteeringSpec(locomotion, tuple(path), speed, avoid)


def _constraint(r: YamlReader, node: Node, where: str, in_motion: bool = False,
                origin_m: tuple[float, ...] | None = None,
                motion_names: tuple[str, ...] = ()) -> tuple[ConstraintEntry, Node | None]:
    """One constraint entry; returns it and the node naming a target character (checked once
    every character is known). Everything else is checked here, against a scratch table, so a
    mistake is reported with its line. A target ``point:`` without ``character:`` is on the
    constrained character itself; ``in_motion`` (constraints stored with a motion) allows only
    those. A ``world_m`` target lies within :data:`MAX_TARGET_DISTANCE_M` of ``origin_m``
    (x, y, z), the character's start on the ground."""
    from ecs_anim.core.body_points import GROUPS, body_point
    from ecs_anim.motion.constraint_table import KIND_NAMES, Area, ConstraintTable, Target

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


def _com_target(r: YamlReader, keys: dict[str, Node], where: str,
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


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario; motions are loaded (BVH imported) here, once."""
    path = Path(path)
    r = YamlReader(str(path))
    refuse_clip(path)
    root = read_tree(path, "scenario", "the scenario")
    top = r.mapping(root, "", {"duration_s": True, "fps": False, "motions": True,
                               "ground": False, "characters": True, "description": False,
                               "camera": False, "tables": False, "triggers": False,
                               "solver": False})
    fps = r.number(top["fps"], "fps", 1.0, 1000.0, "Hz") if "fps" in top else 30.0
    duration = r.number(top["duration_s"], "duration_s", 1.0 / fps, MAX_DURATION_S, "s")
    motion_nodes = top["motions"]
    if not isinstance(motion_nodes, yaml.MappingNode) or not motion_nodes.value:
        raise r.fail(motion_nodes, "motions", "expected a mapping name: file (.bvh, .c3d, .fbx, .trc, .amc or .nmo)")
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
            motions[name] = load_motion(r, mk["file"], f"motions.{name}.file", path.parent,
                                         read)
            if "absent_from" in mk:
                fills.append((name, mk["absent_from"]))
        else:
            motions[name] = load_motion(r, value, f"motions.{name}", path.parent, read)
    for name, node in fills:
        fill_absent(r, motions, name, node)
    ground = read_ground(r, top["ground"], "ground") if "ground" in top else Plane()
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

        clip = partial(motion_name, r, motions=motions)

        queue = queued_clips(r, keys["then"], f"{where}.then", clip, MAX_QUEUE) if "then" in keys else ()
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
            name, read_morphology(r, keys["morphology"], f"{where}.morphology"), player,
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
    solver: dict[str, Any] = {}
    if "solver" in top:
        sk = r.mapping(top["solver"], "solver", {"max_joint_speed_m_s": False})
        if "max_joint_speed_m_s" in sk:  # null: no bound
            node = sk["max_joint_speed_m_s"]
            solver["max_joint_speed_m_s"] = None if r.scalar(node, "solver.max_joint_speed_m_s") \
                is None else r.number(node, "solver.max_joint_speed_m_s", 0.01, 1000.0, "m/s")
    starts = np.array([c.placement.position_m for c in characters])
    tables = [_table(r, node, f"tables[{i}]", starts) for i, node in
              enumerate(r.sequence(top["tables"], "tables", MAX_TABLES, "tables") if "tables" in top else [])]
    refs: list[tuple[int, str]] = []
    triggers = scenario_triggers(r, top, characters, motions, refs)
    return Scenario(str(path), duration, fps, motions, ground, characters, camera, tables,
                    (str(path),) + tuple(str(p) for p in read), triggers, refs, solver)


def _table(r: YamlReader, node: Node, where: str, starts: np.ndarray) -> Table:
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
    r = YamlReader(str(path))
    root = read_tree(path, "constraints", "the constraints file")
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


# --- triggers, keyframed targets (ecs_anim.runtime.events) ----------------------------------------------
# Triggers are read after every character: they name characters, their points, clips and
# constraints ("character.constraint"). At load a trigger holds scenario indices in place of
# entity ids and constraint ids (the character's index in ``characters``; a constraint's index
# in ``Scenario.trigger_constraints``, which holds (character index, constraint name));
# build_simulation maps them to the simulation's (:func:`bind_trigger`).


def _keyframes(r: YamlReader, node: Node, where: str) -> tuple[tuple[float, ...], tuple[tuple[float, float, float], ...]]:
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


def _activation_clock(r: YamlReader, keys: dict[str, Node], where: str, in_motion: bool,
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


