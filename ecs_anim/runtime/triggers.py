"""What triggers are made of, as plain data: the events a tick can have, the conditions a trigger
waits for, the actions it takes, the trigger itself and a moving target's keyframes; and what
each names (characters, constraints) and sets off (the events an action makes)."""

from __future__ import annotations

from dataclasses import dataclass

from ecs_anim.components import QueuedClip
from ecs_anim.core.body_points import BodyPoint
from ecs_anim.core.morphology import Morphology

#: The kinds of :class:`Event`.
EVENT_KINDS = ("clip_started", "clip_ended", "contact_began", "arrived", "removed", "near",
               "reached", "time")


#: A foot contact has begun when its weight rises through this.
CONTACT_BEGAN_WEIGHT = 0.5


FEET = ("left", "right")


@dataclass(frozen=True)
class Event:
    """Something that happened once: ``kind`` (one of :data:`EVENT_KINDS`) to the character
    ``entity`` (named ``character``; -1 and '' for a time), at simulation time ``time_s`` (the
    posture where it shows), in ``tick`` (the ``step()`` it was produced in, counted from 0).
    ``detail``: the clip (clip_started, clip_ended), the foot (``left`` / ``right``), the last
    waypoint ``(x, y)`` in metres (arrived), or the trigger whose condition this is (near,
    reached, time)."""

    kind: str
    entity: int
    character: str
    time_s: float
    tick: int
    detail: str = ""


@dataclass(frozen=True)
class ClipStarted:
    """``entity`` starts playing ``clip`` (None: any clip), cross-fade included."""

    entity: int
    clip: str | None = None


@dataclass(frozen=True)
class ClipEnded:
    """``entity``'s ``clip`` (None: any) ends: it reaches its end (not looping) or another
    clip takes over."""

    entity: int
    clip: str | None = None


@dataclass(frozen=True)
class Near:
    """``point`` of ``entity`` comes within ``within_m`` of ``other_point`` of ``other``
    (their distance falls to ``within_m`` or below; world metres, each tick's posture)."""

    entity: int
    point: BodyPoint
    other: int
    other_point: BodyPoint
    within_m: float


@dataclass(frozen=True)
class Reached:
    """The constraint ``uid`` is reached: active and its error at most ``within_m`` (metres, or
    radians for an orientation)."""

    uid: int
    within_m: float = 0.001


@dataclass(frozen=True)
class ContactBegan:
    """A foot contact of ``entity`` begins: ``foot`` ``left`` / ``right`` (None: either)."""

    entity: int
    foot: str | None = None


@dataclass(frozen=True)
class Arrived:
    """``entity`` reaches the last waypoint of its path (``Simulation.follow_path``,
    ``walk_to``, a scenario's ``path_m``): steering stops it there (``Simulation.arrived``
    turns true in that tick)."""

    entity: int


@dataclass(frozen=True)
class AtTime:
    """Simulation time reaches ``time_s``."""

    time_s: float


@dataclass(frozen=True)
class Removed:
    """``entity`` is taken out of the simulation."""

    entity: int


Condition = ClipStarted | ClipEnded | Near | Reached | ContactBegan | Arrived | AtTime | Removed


@dataclass(frozen=True)
class Play:
    """``entity`` plays ``clip`` now, cross-faded over ``crossfade_s`` from what it plays,
    starting ``from_s`` into the clip, then the clips of ``then``; it replaces the clips still
    queued."""

    entity: int
    clip: str
    crossfade_s: float = 0.3
    loop: bool = False
    from_s: float = 0.0
    then: tuple[QueuedClip, ...] = ()


@dataclass(frozen=True)
class SwitchOn:
    """Switch the constraint ``uid`` on now, easing in over its own ``ease_in_s``, for
    ``for_s`` seconds (None: until switched off), then easing out over its ``ease_out_s``."""

    uid: int
    for_s: float | None = None


@dataclass(frozen=True)
class SwitchOff:
    """Switch the constraint ``uid`` off now, easing out over its own ``ease_out_s``."""

    uid: int


@dataclass(frozen=True)
class MoveTarget:
    """Move the constraint ``uid``'s target to the world point ``target_in_world`` (m)."""

    uid: int
    target_in_world: tuple[float, float, float]


@dataclass(frozen=True)
class SetBody:
    """Give ``entity`` the body ``body``, blended over ``blend_s`` (``Simulation.set_body``)."""

    entity: int
    body: Morphology
    blend_s: float = 0.0


@dataclass(frozen=True)
class Remove:
    """Take ``entity`` out of the simulation (``Simulation.remove``)."""

    entity: int


@dataclass(frozen=True)
class Arm:
    """Start watching the condition of the trigger named ``trigger`` (one made with
    ``armed=False`` waits for this), e.g. a dodge watched only once the punch is coming."""

    trigger: str


Action = Play | SwitchOn | SwitchOff | MoveTarget | SetBody | Remove | Arm


@dataclass(frozen=True)
class Trigger:
    """``when`` the condition holds (its edge), do ``then`` after ``delay_s``; once, or every
    time with ``repeat``. ``name`` names it in events and warnings. ``armed`` False: its
    condition is not watched until an :class:`Arm` action arms it."""

    name: str
    when: Condition
    then: tuple[Action, ...]
    delay_s: float = 0.0
    repeat: bool = False
    armed: bool = True


@dataclass(frozen=True)
class TargetTrack:
    """A moving world target: the constraint ``uid``'s target at ``times_s`` (k,) is
    ``points_m`` (k, 3), linearly interpolated between, held before the first and after the
    last keyframe."""

    uid: int
    times_s: tuple[float, ...]
    points_m: tuple[tuple[float, float, float], ...]


def entities_named(item: Condition | Action) -> tuple[int, ...]:
    """The characters a condition or an action names."""
    if isinstance(item, Near):
        return (item.entity, item.other)
    entity = getattr(item, "entity", None)
    return () if entity is None else (int(entity),)


def constraints_named(item: Condition | Action) -> tuple[int, ...]:
    """The constraints (ids) a condition or an action names."""
    uid = getattr(item, "uid", None)
    return () if uid is None else (int(uid),)


def event_effects(action: Action) -> list[tuple[str, int, str | None]]:
    """The events an action causes at once, as (kind, entity, clip or None): what may chain."""
    if isinstance(action, Play):
        return [("clip_started", action.entity, action.clip), ("clip_ended", action.entity, None)]
    if isinstance(action, Remove):
        return [("removed", action.entity, None)]
    return []


def listened(condition: Condition) -> tuple[str, int] | None:
    """The (event kind, entity) an action's event must have to match ``condition``; None for a
    condition no action's event can match (a distance, a time, a contact)."""
    for kind, type_ in (("clip_started", ClipStarted), ("clip_ended", ClipEnded),
                        ("removed", Removed), ("arrived", Arrived)):
        if isinstance(condition, type_):
            return kind, condition.entity
    return None


def listens_to(condition: Condition, kind: str, entity: int, clip: str | None) -> bool:
    """Whether an event (kind, entity, clip; clip None: any) can match ``condition``."""
    if listened(condition) != (kind, entity):
        return False
    own = getattr(condition, "clip", None)
    return own is None or clip is None or own == clip


def find_cycle(triggers: list[Trigger]) -> list[int]:
    """Triggers that would fire each other forever in one tick: a cycle of repeating triggers
    without delay, each one's actions causing an event the next one waits for. Returns the
    cycle's indices (empty: none)."""
    live = [i for i, t in enumerate(triggers) if t.delay_s <= 0.0 and t.repeat]
    # Who listens to what, so each action's events look up their listeners (linear in the
    # triggers: comparing every pair took minutes at 30,000).
    listeners: dict[tuple[str, int], list[int]] = {}
    for j in live:
        key = listened(triggers[j].when)
        if key is not None:
            listeners.setdefault(key, []).append(j)
    edges: dict[int, list[int]] = {i: [] for i in live}
    for i in live:
        effects = [e for a in triggers[i].then for e in event_effects(a)]
        edges[i] = list(dict.fromkeys(
            j for e in effects for j in listeners.get((e[0], e[1]), [])
            if listens_to(triggers[j].when, *e)))
    # A depth-first search with its own stack (a chain of thousands of triggers is deeper than
    # Python's recursion allows): each entry is a trigger on the path and its next edge to try.
    state: dict[int, int] = {}  # 1: on the path, 2: done
    for root in live:
        if root in state:
            continue
        state[root] = 1
        path, stack = [root], [(root, 0)]
        while stack:
            i, k = stack[-1]
            if k == len(edges[i]):
                stack.pop()
                path.pop()
                state[i] = 2
                continue
            stack[-1] = (i, k + 1)
            j = edges[i][k]
            if state.get(j) == 1:
                return path[path.index(j):]
            if j not in state:
                state[j] = 1
                path.append(j)
                stack.append((j, 0))
    return []
