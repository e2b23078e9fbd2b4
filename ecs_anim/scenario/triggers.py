"""A scenario's ``triggers:``: when something happens (a clip starts, a contact begins, a point
comes within reach), what to do (play, switch a constraint on, change a body)."""

from __future__ import annotations

from dataclasses import replace
from functools import partial
from typing import Any

import yaml
from yaml import Node

from ecs_anim.components import QueuedClip
from ecs_anim.core.body_points import BodyPoint
from ecs_anim.core.errors import (
    did_you_mean,
    listed,
)
from ecs_anim.motion.clip import NormalizedMotion
from ecs_anim.runtime.simulation import MAX_DURATION_S
from ecs_anim.runtime.store import MAX_QUEUE
from ecs_anim.runtime.triggers import Action, Condition, Trigger
from ecs_anim.scenario.bodies import read_morphology
from ecs_anim.scenario.motions import motion_name, queued_clips
from ecs_anim.scenario.reader import MAX_TARGET_DISTANCE_M, YamlReader
from ecs_anim.scenario.spec import CharacterSpec

#: At most this many triggers in a scenario.
MAX_TRIGGERS = 100_000


WHEN_KEYS = {"clip_started": ("character.motion or character",),
             "clip_ended": ("character.motion or character",),
             "near": ("character.point", "to", "within_m", "fraction", "to_fraction"),
             "reached": ("character.constraint", "within_m"),
             "contact_began": ("character", "foot"),
             "arrived": ("character",),
             "at_s": ("seconds",),
             "removed": ("character",)}


ACTION_KEYS = {"play": ("crossfade_s", "loop", "from_s", "then"),
               "switch_on": ("for_s",),
               "switch_off": (),
               "move_target": ("world_m",),
               "set_body": ("morphology", "blend_s"),
               "remove": (),
               "arm": ()}


def _split_ref(r: YamlReader, node: Node, where: str, characters: list[CharacterSpec],
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


def _constraint_ref(r: YamlReader, node: Node, where: str, characters: list[CharacterSpec],
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


def _clip_ref(r: YamlReader, node: Node, where: str, characters: list[CharacterSpec],
              motions: dict[str, NormalizedMotion], optional: bool) -> tuple[int, str | None]:
    who, clip = _split_ref(r, node, where, characters, "motion", optional)
    if clip is not None and clip not in motions:
        hint = did_you_mean(clip, list(motions))
        raise r.fail(node, where, f"unknown motion {clip!r}{hint} (motions: {', '.join(motions)})")
    return who, clip


def _point_ref(r: YamlReader, node: Node, where: str, characters: list[CharacterSpec],
               fraction: float | None) -> tuple[int, BodyPoint]:
    from ecs_anim.core.body_points import body_point

    who, point = _split_ref(r, node, where, characters, "point")
    try:
        return who, body_point(str(point), fraction, as_target=True)
    except ValueError as exc:
        raise r.fail(node, where, str(exc)) from None


def _kind_of(r: YamlReader, node: Node, where: str, kinds: dict[str, Any], what: str) -> str:
    """The kind of a trigger's condition or action: its mapping's first key, one of ``kinds``."""
    if not isinstance(node, yaml.MappingNode) or not node.value:
        raise r.fail(node, where, f"expected a mapping with one of {', '.join(kinds)}")
    kind = str(node.value[0][0].value)
    if kind not in kinds:
        hint = did_you_mean(kind, list(kinds))
        raise r.fail(node.value[0][0], f"{where}.{kind}", f"unknown {what}{hint} (expected one "
                     f"of {', '.join(kinds)})")
    return kind


def _when(r: YamlReader, node: Node, where: str, characters: list[CharacterSpec],
          motions: dict[str, NormalizedMotion], refs: list[tuple[int, str]]) -> Condition:
    from ecs_anim.runtime.triggers import (
        Arrived,
        AtTime,
        ClipEnded,
        ClipStarted,
        ContactBegan,
        Near,
        Reached,
        Removed,
    )

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
    if kind == "arrived":
        steering = characters[who].steering
        if steering is None or not steering.path_m:
            raise r.fail(keys[kind], w, f"{characters[who].name!r} has no path_m: it would "
                         "never arrive (give it one; a path given from code takes a trigger "
                         "from code, Arrived)")
        return Arrived(who)
    return Removed(who)


def _action(r: YamlReader, node: Node, where: str, characters: list[CharacterSpec],
            motions: dict[str, NormalizedMotion], queued: Any, refs: list[tuple[int, str]],
            trigger_names: list[str]) -> Action:
    from ecs_anim.runtime.triggers import (
        Arm,
        MoveTarget,
        Play,
        Remove,
        SetBody,
        SwitchOff,
        SwitchOn,
    )

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
    return SetBody(who, read_morphology(r, keys["morphology"], f"{where}.morphology"),
                   r.number(keys["blend_s"], f"{where}.blend_s", 0.0, 600.0, "s")
                   if "blend_s" in keys else 0.0)


def _triggers(r: YamlReader, node: Node, characters: list[CharacterSpec],
              motions: dict[str, NormalizedMotion], queued: Any,
              refs: list[tuple[int, str]]) -> list[Trigger]:
    """The scenario's ``triggers:`` (docs/scenarios.md, Triggers); a cycle of triggers that
    would fire each other forever in one tick is refused here, at the first one's line."""
    from ecs_anim.runtime.triggers import Trigger, find_cycle

    triggers: list[Trigger] = []
    nodes = r.sequence(node, "triggers", MAX_TRIGGERS, "triggers")
    names: list[str] = []  # every trigger's, first (an arm: action may name a later one)
    seen: set[str] = set()
    for i, tn in enumerate(nodes):
        keys = r.mapping(tn, f"triggers[{i}]", {"name": False, "when": True, "then": True,
                                                 "delay_s": False, "repeat": False, "armed": False})
        name = r.string(keys["name"], f"triggers[{i}].name") if "name" in keys else f"triggers[{i}]"
        if name in seen:
            raise r.fail(keys.get("name", tn), f"triggers[{i}].name",
                         f"another trigger is named {name!r}")
        names.append(name)
        seen.add(name)
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


def scenario_triggers(r: YamlReader, top: dict[str, Node], characters: list[CharacterSpec],
                       motions: dict[str, NormalizedMotion],
                       refs: list[tuple[int, str]]) -> list[Trigger]:
    """The ``triggers:`` of a scenario (none if absent); ``refs`` gets the constraints they name."""
    if "triggers" not in top:
        return []

    clip = partial(motion_name, r, motions=motions)

    def queued(n: Node, w: str) -> tuple[QueuedClip, ...]:
        return queued_clips(r, n, w, clip, MAX_QUEUE - 1)

    return _triggers(r, top["triggers"], characters, motions, queued, refs)


def bind_trigger(trigger: Trigger, entities: list[int], uids: dict[int, int]) -> Trigger:
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
