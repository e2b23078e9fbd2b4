"""The reactions engine: finding a tick's events (edges) and firing the triggers they match.

The triggers' parts are plain data in :mod:`ecs_anim.runtime.triggers`, what their actions do in
:mod:`ecs_anim.runtime.actions`; the systems ApplyReactions and DetectEvents run this engine at
the head and the tail of the schedule.

Events are edges (STYLE 8): a clip started or ended, a foot contact began, a character was
removed, and the edges of the triggers' own conditions (a point came within a distance of
another, a constraint was reached, a time came). :meth:`Simulation.events` returns the list of
the last ``step()``; per-tick data stays in the store.

A :class:`Trigger` is ``when`` (one condition) -> ``then`` (actions), fired once (or on every
edge with ``repeat``), ``delay_s`` after its condition. Conditions are evaluated for all triggers
at once as arrays (every ``Near``'s two points in one numpy computation over the store's
posture); an action acts from the next posture on:

* a condition seen in the posture of tick ``k`` (after ``step()``) fires its actions at once:
  the posture of tick ``k + 1`` shows them (one tick later, the least an event can take);
* ``AtTime(t)`` and a delayed action are applied before the tick whose posture time reaches
  their time, so that posture already shows them;
* an action whose effect is an event (:class:`Play`: a clip starts; :class:`Remove`) may fire
  further triggers at once (chaining). A trigger fires at most once per tick: one that would
  fire again in the same tick (a cycle of triggers firing each other) is skipped with a warning
  and the others go on (a scenario refuses such a cycle at load).

The reactions of one tick see the world as it was when they began (before the tick's systems
for the time triggers and delayed actions, after them for the edges): every condition is
evaluated, and every event made, before any action is applied. They are then applied in a
defined order: before the tick, the time triggers (by trigger index), then the delayed actions
(by due time, then trigger index); after it, the clip and contact events (clips ended, started,
contacts begun, each by store row), then the ``near`` triggers, then the ``reached`` ones (by
trigger index); each action's own events at once, in between. A trigger's actions run in order.

Triggers naming a character that is removed, or one of the constraints removed with it, are
dropped with one warning once the reactions of that tick are done (a trigger whose condition
held at their start still fires); the others go on. An action naming a character or constraint
removed by then is skipped with one warning; the trigger's other actions go on. A trigger made
with ``armed=False`` is not watched until an :class:`Arm` action names it.

Moving targets (:class:`TargetTrack`): a constraint's world target given as keyframes
``(t_s, at_m)``, interpolated linearly in simulation time (held before the first and after the
last), set before every tick.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import point_positions
from ecs_anim.core.errors import EcsAnimError, listed, quoted
from ecs_anim.runtime.kernels.edges import EdgeScratch
from ecs_anim.runtime.kernels.edges import clip_and_contact_edges as compiled_edges
from ecs_anim.runtime.steering import STEER_PATH

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation
    from ecs_anim.runtime.store import CharacterStore
from ecs_anim.runtime.actions import interpolate_keyframes, play_now, switch_off, switch_on
from ecs_anim.runtime.triggers import (
    CONTACT_BEGAN_WEIGHT,
    FEET,
    Action,
    Arm,
    Arrived,
    AtTime,
    ClipEnded,
    ClipStarted,
    Condition,
    ContactBegan,
    Event,
    MoveTarget,
    Near,
    Play,
    Reached,
    Remove,
    Removed,
    SetBody,
    SwitchOff,
    SwitchOn,
    TargetTrack,
    Trigger,
    constraints_named,
    entities_named,
    listens_to,
)

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: Slack on comparing times (s), against rounding of tick times.
TIME_SLACK_S = 1e-9


# --- conditions ---------------------------------------------------------------------------------


# --- actions ------------------------------------------------------------------------------------


@dataclass
class _Compiled:
    """The triggers' conditions as arrays, rebuilt when triggers are added or dropped."""

    near: I64 = field(default_factory=lambda: np.zeros(0, np.int64))  # trigger indices
    near_entities: I64 = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    near_segments: I64 = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    near_fractions: F64 = field(default_factory=lambda: np.zeros((0, 2)))
    near_offsets: F64 = field(default_factory=lambda: np.zeros((0, 2, 3)))
    near_within_m: F64 = field(default_factory=lambda: np.zeros(0))
    reached: I64 = field(default_factory=lambda: np.zeros(0, np.int64))
    reached_uids: I64 = field(default_factory=lambda: np.zeros(0, np.int64))
    reached_within: F64 = field(default_factory=lambda: np.zeros(0))
    timed: I64 = field(default_factory=lambda: np.zeros(0, np.int64))
    timed_at_s: F64 = field(default_factory=lambda: np.zeros(0))
    #: (event kind, entity) -> the triggers waiting for such an event (clips, contacts, removal)
    listeners: dict[tuple[str, int], list[int]] = field(default_factory=dict)
    _listened: dict[str, I64] = field(default_factory=dict)

    def unwatch(self, trigger: int, listened_as: tuple[str, int] | None) -> None:
        """Stop watching ``trigger``'s condition (it fired, once): its row out of the arrays and
        out of the ``listened_as`` listeners, leaving what a rebuild would make (a rebuild goes
        over every trigger: a spike on the tick one fires, 30,000 triggers or 16)."""
        for indices_name, column_names in _CONDITION_COLUMNS:
            indices = getattr(self, indices_name)
            keep = indices != trigger
            if keep.all():
                continue
            setattr(self, indices_name, indices[keep])
            for name in column_names:
                setattr(self, name, getattr(self, name)[keep])
        waiting = self.listeners.get(listened_as) if listened_as is not None else None
        if waiting is not None and trigger in waiting:
            assert listened_as is not None
            rest = [i for i in waiting if i != trigger]  # a new list: an _emit may be going over it
            if rest:
                self.listeners[listened_as] = rest
            else:
                del self.listeners[listened_as]
                self._listened.pop(listened_as[0], None)

    def listened(self, kind: str) -> I64:
        """The entities some trigger waits on for events of ``kind`` (sorted; made once per
        rebuild)."""
        if kind not in self._listened:
            self._listened[kind] = np.unique(np.array([e for k, e in self.listeners if k == kind],
                                                      np.int64))
        return self._listened[kind]


#: Each condition array of :class:`_Compiled` (trigger indices) and its columns, row for row.
_CONDITION_COLUMNS = (
    ("near", ("near_entities", "near_segments", "near_fractions", "near_offsets",
              "near_within_m")),
    ("reached", ("reached_uids", "reached_within")),
    ("timed", ("timed_at_s",)),
)

#: The event kind each condition waiting on one character's events listens for.
_LISTENED_KINDS: dict[type, str] = {ClipStarted: "clip_started", ClipEnded: "clip_ended",
                                    ContactBegan: "contact_began", Arrived: "arrived",
                                    Removed: "removed"}


def _listened_as(condition: Condition) -> tuple[str, int] | None:
    """The (event kind, entity) key of :attr:`_Compiled.listeners` ``condition`` waits under
    (None: a condition of its own, near, reached or a time)."""
    if isinstance(condition, ClipStarted | ClipEnded | ContactBegan | Arrived | Removed):
        return _LISTENED_KINDS[type(condition)], condition.entity
    return None


#: Columns of :func:`clip_and_contact_edges`'s edges: the clip seen last tick was replaced
#: before it ended, the clip ended this tick, a clip started, a foot's contact began (left,
#: right: the last two).
EDGE_REPLACED, EDGE_ENDED, EDGE_STARTED, EDGE_CONTACT = 0, 1, 2, 3


def clip_and_contact_edges(entity: I64, clip: I64, clip_time_s: F64, speed: F64,
                           loop: NDArray[np.bool_], duration_s: F64, contact_weight: F64,
                           dt: float, slack_s: float, began_weight: float, seen_clip: I64,
                           seen_time_s: F64, seen_ended: NDArray[np.bool_],
                           seen_below: NDArray[np.bool_]) -> tuple[NDArray[np.bool_], I64]:
    """The clip and contact edges of each store row in the tick just stepped (numpy; the
    reference of the compiled :func:`ecs_anim.runtime.kernels.edges.clip_and_contact_edges`).

    The store's ``entity``, ``clip``, ``clip_time_s``, ``speed``, ``loop`` (n,) and
    ``contact_weight`` (n, 2); ``duration_s`` each clip's loop period; ``dt`` the tick (s). A
    clip starts when it differs from the one seen or its time went back (beyond ``slack_s``);
    it ends when the pose was sampled at its end and it does not loop; a contact begins when
    its weight reaches ``began_weight``. ``seen_*`` (by entity id) hold what the last tick left
    (clip -1: none seen; ``seen_below`` (entities, 2) whether each foot's weight was below
    ``began_weight``, False for NaN as the comparison: the one bit of the weight an edge
    reads, an eighth of its bytes to read and write every tick) and are updated in place.
    Returns the edges (n, 5) bool, columns :data:`EDGE_REPLACED` ... :data:`EDGE_CONTACT` +
    foot, and the clip seen before (n,)."""
    seen_clip_now, seen_time_now = seen_clip[entity], seen_time_s[entity]
    ended_before = seen_ended[entity]
    new_clip = (clip != seen_clip_now) | (clip_time_s < seen_time_now - slack_s)
    sampled = clip_time_s - dt * speed  # the clip time this tick's pose was at
    at_end = ~loop & (sampled >= duration_s[clip] - slack_s)
    edges = np.zeros((entity.shape[0], 5), bool)
    edges[:, EDGE_REPLACED] = new_clip & (seen_clip_now >= 0) & ~ended_before
    edges[:, EDGE_ENDED] = ~new_clip & at_end & ~ended_before
    edges[:, EDGE_STARTED] = new_clip
    edges[:, EDGE_CONTACT:] = (contact_weight >= began_weight) & seen_below[entity]
    seen_ended[entity] = ~new_clip & (ended_before | at_end)
    seen_clip[entity], seen_time_s[entity] = clip, clip_time_s
    seen_below[entity] = contact_weight < began_weight
    return edges, seen_clip_now


def edges_listed(edges: NDArray[np.bool_]) -> list[I64]:
    """The edges of :func:`clip_and_contact_edges` (n, 5) listed by kind, as the compiled one
    lists them: the rows of each of the first three columns, then each contact's
    ``2 * row + foot`` in row order."""
    rows, feet = np.nonzero(edges[:, EDGE_CONTACT:])
    return [np.flatnonzero(edges[:, k]) for k in range(EDGE_CONTACT)] + [2 * rows + feet]


@dataclass
class _StoreEdges:
    """The clip and contact events of one tick, kept as arrays until someone asks for them
    (a crowd makes hundreds a tick, and usually no trigger waits on most): per kind, the store
    rows, their entities and each one's detail as an index into ``detail_names``; ``names``
    the characters' names by store row then; ``at`` where they go in the tick's event list."""

    edges: list[tuple[str, I64, I64, list[str]]]
    entity: I64
    names: list[str]
    time_s: float
    tick: int
    at: int

    def events(self) -> list[Event]:
        return [Event(kind, int(self.entity[r]), self.names[r], self.time_s, self.tick,
                      detail_names[d])
                for kind, rows, detail, detail_names in self.edges
                for r, d in zip(rows.tolist(), detail.tolist(), strict=True)]


class Reactions:
    """A simulation's triggers, moving targets and the events of its last tick.

    Owned by :class:`~ecs_anim.runtime.simulation.Simulation` (``sim.reactions``), which calls
    :meth:`before_tick` and :meth:`after_tick` around each tick's systems. The previous tick's
    clip, clip time and contact weights are kept per entity (arrays indexed by entity id), so
    detecting an edge is a comparison of whole arrays."""

    def __init__(self) -> None:
        self.triggers: list[Trigger] = []
        #: Each trigger's index by its name (names are unique: Arm names triggers).
        self.by_name: dict[str, int] = {}
        # Per trigger (see the properties of the same names): fired, dropped, holds, armed;
        # grown by doubling, so adding n triggers costs O(n), not O(n^2) (30,000 took 254 s).
        self._flags = np.zeros((4, 0), bool)
        self.tracks: list[TargetTrack] = []
        self._compiled: _Compiled | None = None
        self._pending: list[tuple[float, int]] = []  # (due time, trigger) delayed actions
        self._events: list[Event] = []  # of the tick in progress
        self._last: list[Event] = []  # of the last tick stepped
        # the store edges of the tick in progress / of the last one when no trigger waited
        # on any (made into events only when asked for)
        self._edges_kept: _StoreEdges | None = None
        self._last_edges: _StoreEdges | None = None
        self._edge_scratch = EdgeScratch()  # the compiled edges' arrays, kept tick to tick
        self._fired_this_tick: set[tuple[int, str, int, str]] = set()  # (trigger, event)
        # while a tick's reactions are applied: the triggers to drop once they are done, and
        # the names of the characters removed meanwhile (by entity, for warnings)
        self._reacting = False
        self._to_drop: dict[int, None] = {}
        self._removed_names: dict[int, str] = {}
        self._names_cache: list[str] = []
        self._names_version = -1
        # per entity id: the clip (-1: not seen yet), its time after the last tick, whether its
        # end was reported, whether each foot's contact weight was below CONTACT_BEGAN_WEIGHT
        self._seen_clip = np.zeros(0, np.int64)
        self._seen_time = np.zeros(0)
        self._seen_ended = np.zeros(0, bool)
        self._seen_below = np.zeros((0, 2), bool)
        # per entity id: following a path when the tick began (an arrival is its end)
        self._seen_on_path = np.zeros(0, bool)
        self._paths_seen = False  # any of _seen_on_path of a character still there
        self._grown_version = -1  # the structure version the seen arrays were grown for

    # --- adding ---------------------------------------------------------------------------------

    @property
    def fired(self) -> NDArray[np.bool_]:
        """(triggers,) fired once already (a trigger without repeat); a view, written in place."""
        return self._flags[0, :len(self.triggers)]

    @property
    def dropped(self) -> NDArray[np.bool_]:
        """(triggers,) names a removed character or constraint."""
        return self._flags[1, :len(self.triggers)]

    @property
    def holds(self) -> NDArray[np.bool_]:
        """(triggers,) the condition held at the last evaluation (edges)."""
        return self._flags[2, :len(self.triggers)]

    @property
    def armed(self) -> NDArray[np.bool_]:
        """(triggers,) its condition is watched."""
        return self._flags[3, :len(self.triggers)]

    def add(self, trigger: Trigger) -> int:
        n = len(self.triggers)
        if n == self._flags.shape[1]:
            grown = np.zeros((4, max(16, 2 * n)), bool)
            grown[:, :n] = self._flags
            self._flags = grown
        self._flags[:, n] = (False, False, False, trigger.armed)
        self.triggers.append(trigger)
        self.by_name[trigger.name] = n
        self._compiled = None
        return n

    @property
    def events(self) -> list[Event]:
        """The last tick's events in time order (a sort that keeps the order they happened in
        among those of one time: a character removed by an action is stamped with the time of
        the posture it is first missing from, after the edges that made the action fire)."""
        kept = self._last_edges
        made = list(self._last) if kept is None else \
            self._last[:kept.at] + kept.events() + self._last[kept.at:]
        return sorted(made, key=lambda event: event.time_s)

    # --- the tick -------------------------------------------------------------------------------

    def before_tick(self, sim: Simulation) -> None:
        """Apply the moving targets, the time triggers and the delayed actions due at the
        posture this tick makes (``sim.time_s``)."""
        now = sim.time_s
        if self.tracks:
            self._set_track_targets(sim, now)
        c = self._compile()
        due = c.timed[(c.timed_at_s <= now + TIME_SLACK_S) & ~self.holds[c.timed]]
        ready = [p for p in self._pending if p[0] <= now + TIME_SLACK_S]
        if not (due.size or ready):
            return
        self._pending = [p for p in self._pending if p[0] > now + TIME_SLACK_S]
        self.holds[due] = True
        with self._reactions():
            for i in due:
                self._emit(sim, Event("time", -1, "", now, sim.tick, self.triggers[i].name), i)
            for _, i in sorted(ready):
                if not self.dropped[i]:
                    self._apply(sim, i)

    def after_tick(self, sim: Simulation) -> None:
        """Detect this tick's events in the store and fire the triggers they match."""
        st = sim.store
        if self._grown_version != sim.structure_version:  # (ids come with new characters)
            self._grow(int(st.entity.max()) + 1 if st.n else 0)
            self._grown_version = sim.structure_version
        now, tick = sim.posture_time_s, sim.tick - 1
        # Everything seen before anything is done: an action may remove a character (shifting
        # the store rows after it) or a constraint.
        edges = self._store_edges(sim)
        c = self._compile()
        if not (edges or c.near.size or c.reached.size):  # no event, no condition to evaluate
            self._end_tick()
            return
        names, entity = self._names(sim), st.entity.copy()
        # (the triggers watched as the tick ended: a firing one stops being watched meanwhile)
        near_triggers, reached_triggers = c.near, c.reached
        near = self._near_holds(sim, c) if c.near.size else None
        reached = self._reached_holds(sim, c) if c.reached.size else None
        with self._reactions():
            if any(rows.size for _, rows, _, _ in edges):
                kept = _StoreEdges(edges, entity, names, now, tick, len(self._events))
                if any(c.listened(kind).size > 0  # (isin costs 10 µs even with no one listening)
                       and np.isin(kept.entity[rows], c.listened(kind)).any()
                       for kind, rows, _, _ in edges):
                    for event in kept.events():
                        self._emit(sim, event)
                else:  # nothing to fire: the events are made if someone asks for them
                    self._edges_kept = kept
            if near is not None:
                self._edges(sim, near_triggers, *near, entity, names, "near")
            if reached is not None:
                self._edges(sim, reached_triggers, *reached, entity, names, "reached")
        self._end_tick()

    def _end_tick(self) -> None:
        """The tick's events become the last tick's."""
        self._last, self._events = self._events, []
        self._last_edges, self._edges_kept = self._edges_kept, None
        self._fired_this_tick = set()

    def path_given(self, entity: int) -> None:
        """``entity`` was given a path between two ticks (``Simulation.follow_path``): its
        arrival is an event even in the next tick."""
        self._grow(entity + 1)
        self._seen_on_path[entity] = True
        self._paths_seen = True

    def character_removed(self, sim: Simulation, entity: int, name: str) -> None:
        """After ``Simulation.remove``: the ``removed`` event (its triggers fire), then every
        trigger still naming that character, or a constraint removed with it, is dropped (once
        the reactions under way, if any, are done)."""
        with self._reactions():
            self._removed_names[entity] = name
            self._emit(sim, Event("removed", entity, name, sim.time_s, sim.tick, ""))
            live = set(int(u) for u in sim.constraints.uid)
            gone = []
            for i, t in enumerate(self.triggers):
                if self.dropped[i] or i in self._to_drop or (self.fired[i] and not t.repeat):
                    continue  # done already
                items: list[Condition | Action] = [t.when, *t.then]
                if any(entity in entities_named(x) for x in items) or \
                        any(u not in live for x in items for u in constraints_named(x)):
                    self._to_drop[i] = None
                    gone.append(t.name)
            self.tracks = [k for k in self.tracks if k.uid in live]
            if gone:
                sim.warn(f"character {name!r} removed: triggers {listed(gone)} name it (or its "
                         "constraints) and are dropped; the others go on")

    @contextmanager
    def _reactions(self) -> Iterator[None]:
        """Apply reactions inside (nested: the outermost counts); at its end the triggers
        naming what they removed are dropped."""
        if self._reacting:
            yield
            return
        self._reacting = True
        try:
            yield
        finally:
            self._reacting = False
            if self._to_drop:
                self.dropped[list(self._to_drop)] = True
                self._compiled = None
            self._to_drop, self._removed_names = {}, {}

    # --- edges ----------------------------------------------------------------------------------

    def _grow(self, n_entities: int) -> None:
        have = self._seen_clip.shape[0]
        if n_entities <= have:
            return
        extra = n_entities - have
        self._seen_clip = np.concatenate([self._seen_clip, np.full(extra, -1, np.int64)])
        self._seen_time = np.concatenate([self._seen_time, np.zeros(extra)])
        self._seen_ended = np.concatenate([self._seen_ended, np.zeros(extra, bool)])
        # (an entity not seen yet: its feet's weights below any contact's, as a weight 0)
        self._seen_below = np.concatenate([self._seen_below, np.ones((extra, 2), bool)])
        self._seen_on_path = np.concatenate([self._seen_on_path, np.zeros(extra, bool)])

    def _store_edges(self, sim: Simulation) -> list[tuple[str, I64, I64, list[str]]]:
        """(kind, store rows, details, detail names) of the clip and contact edges of the tick
        just stepped, from the store against the last tick's values (all characters at once:
        :func:`clip_and_contact_edges`, compiled); each event's detail is
        ``detail_names[detail]``. None at all (an empty list) when there is no edge."""
        st, bank = sim.store, sim.bank
        if st.n == 0:
            return []
        args = (st.entity, st.clip, st.clip_time_s, st.speed, st.loop,
                bank.n_frames / bank.fps, st.contact_weight, sim.dt,
                TIME_SLACK_S, CONTACT_BEGAN_WEIGHT, self._seen_clip, self._seen_time,
                self._seen_ended, self._seen_below)
        if sim.compiled:
            listed, replaced_clip = compiled_edges(*args, scratch=self._edge_scratch)
        else:  # the numpy reference while the kernels compile aside (a first run)
            edges, previous_clip = clip_and_contact_edges(*args)
            listed = edges_listed(edges)
            replaced_clip = previous_clip[listed[EDGE_REPLACED]]
        arrived = self._arrived(st)
        if not (arrived[1].size or any(rows.size for rows in listed)):
            return []
        clip_names = list(bank.names)
        out: list[tuple[str, I64, I64, list[str]]] = []
        out.append(("clip_ended", listed[EDGE_REPLACED], replaced_clip, clip_names))
        rows = listed[EDGE_ENDED]
        out.append(("clip_ended", rows, st.clip[rows], clip_names))
        rows = listed[EDGE_STARTED]
        out.append(("clip_started", rows, st.clip[rows], clip_names))
        feet = listed[EDGE_CONTACT]  # 2 * row + foot
        out.append(("contact_began", feet >> 1, feet & 1, list(FEET)))
        out.append(arrived)
        return out

    def _arrived(self, st: CharacterStore) -> tuple[str, I64, I64, list[str]]:
        """The ``arrived`` edges of the tick just stepped: the rows whose path steering
        stopped at its end (its progress there; steer() cancels one short of it)."""
        on_path = st.steer_mode == STEER_PATH
        if not (self._paths_seen or on_path.any()):  # no path then or now: no edge
            return ("arrived", np.zeros(0, np.int64), np.zeros(0, np.int64), [])
        seen = self._seen_on_path[st.entity]
        rows = np.flatnonzero(seen & ~on_path)
        end = st.path_cum_m[rows, np.maximum(st.path_len[rows] - 1, 0)]
        rows = rows[st.path_progress_m[rows] >= end]
        self._seen_on_path[st.entity] = on_path
        self._paths_seen = bool(on_path.any())  # (the others' flags are never read again)
        last = st.path_xy[rows, st.path_len[rows] - 1]
        return ("arrived", rows, np.arange(rows.size),
                [f"({x:.2f}, {y:.2f})" for x, y in last.tolist()])

    def _rows_of(self, sim: Simulation, entities: I64) -> I64:
        """Store rows of entity ids (any shape); -1 where an entity is not in the simulation."""
        st = sim.store
        row_of = np.full(max(int(entities.max(initial=0)), int(st.entity.max(initial=0))) + 1,
                         -1, np.int64)
        row_of[st.entity] = np.arange(st.n)
        return row_of[entities]

    def _near_holds(self, sim: Simulation, c: _Compiled) -> tuple[NDArray[np.bool_], I64]:
        """Whether each Near condition holds in the posture just made (both points of every
        trigger at once), and the store row of its (first) character, the event's subject."""
        posture = sim.store.posture
        holds = np.zeros(c.near.size, bool)
        rows = self._rows_of(sim, c.near_entities)  # (k, 2)
        if posture is None:
            return holds, rows[:, 0]
        ok = np.all(rows >= 0, axis=1)
        points = point_positions(posture, np.where(rows >= 0, rows, 0).reshape(-1),
                                 c.near_segments.reshape(-1), c.near_fractions.reshape(-1),
                                 c.near_offsets.reshape(-1, 3))
        points = points.reshape(-1, 2, 3)
        distance = np.linalg.norm(points[:, 0] - points[:, 1], axis=-1)
        holds = ok & (distance <= c.near_within_m)  # NaN (no posture): False
        return holds, rows[:, 0]

    def _reached_holds(self, sim: Simulation, c: _Compiled) -> tuple[NDArray[np.bool_], I64]:
        """Whether each Reached condition holds after the tick just stepped, and the store row
        of its constraint's owner, the event's subject (-1: the constraint is gone)."""
        table = sim.constraints
        live = np.isin(c.reached_uids, table.uid)
        holds = np.zeros(c.reached.size, bool)
        owner = np.full(c.reached.size, -1, np.int64)
        if live.any():
            rows = table.rows_of(c.reached_uids[live])
            holds[live] = (table.weight[rows] > 0.0) & (table.error[rows] <= c.reached_within[live])
            owner[live] = table.owner[rows]
        return holds, owner

    def _edges(self, sim: Simulation, triggers: I64, holds: NDArray[np.bool_], subjects: I64,
               entity: I64, names: list[str], kind: str) -> None:
        """Fire the triggers whose condition has just begun to hold, in trigger order; each
        event is about the character at store row ``subjects`` (a holding condition's are all
        in the store), whose entities and names are ``entity`` and ``names``, all three as the
        tick ended, before any reaction."""
        rising = holds & ~self.holds[triggers]
        self.holds[triggers] = holds
        rows = subjects[rising].tolist()
        for i, row in zip(triggers[rising].tolist(), rows, strict=True):
            self._emit(sim, Event(kind, int(entity[row]), names[row], sim.posture_time_s,
                                  sim.tick - 1, self.triggers[i].name), i)

    def _names(self, sim: Simulation) -> list[str]:
        """Every character's name by store row (an esper query once per structural change)."""
        if self._names_version != sim.structure_version:
            self._names_cache, self._names_version = sim.names(), sim.structure_version
        return self._names_cache

    # --- firing ---------------------------------------------------------------------------------

    def _emit(self, sim: Simulation, event: Event, source: int | None = None) -> None:
        """Record ``event``; fire the triggers it matches (``source``: the trigger whose own
        condition's edge it is)."""
        self._events.append(event)
        if source is not None:
            self._fire(sim, source, event)
            return
        for i in self._compile().listeners.get((event.kind, event.entity), []):
            if self._matches(self.triggers[i].when, event):
                self._fire(sim, i, event)

    @staticmethod
    def _matches(condition: Condition, event: Event) -> bool:
        if isinstance(condition, ContactBegan):
            return event.kind == "contact_began" and event.entity == condition.entity and \
                condition.foot in (None, event.detail)
        return listens_to(condition, event.kind, event.entity, event.detail or None)

    def _fire(self, sim: Simulation, i: int, event: Event) -> None:
        """Fire trigger ``i`` for ``event``, its condition: its actions now, or delayed."""
        t = self.triggers[i]
        if self.dropped[i] or not self.armed[i] or (self.fired[i] and not t.repeat):
            return
        # Once per tick for each event: a second firing for the same event is a cycle (both
        # feet landing in one tick are two events, each firing a repeating trigger once).
        once = (i, event.kind, event.entity, event.detail)
        if once in self._fired_this_tick:
            sim.warn(f"trigger {t.name!r} would fire again in the same tick (triggers firing each "
                     "other in a cycle): skipped; the others go on")
            return
        self._fired_this_tick.add(once)
        self.fired[i] = True
        if not t.repeat and self._compiled is not None:  # its condition is no longer watched
            self._compiled.unwatch(i, _listened_as(t.when))
        if t.delay_s > 0.0:  # shown from the first posture at or after the condition + delay
            self._pending.append((event.time_s + t.delay_s, i))
        else:
            self._apply(sim, i)

    def _apply(self, sim: Simulation, i: int) -> None:
        """Trigger ``i``'s actions, in order; one naming a character or constraint no longer in
        the simulation is skipped, with a warning."""
        for action in self.triggers[i].then:
            gone = self._gone(sim, action)
            if gone:
                sim.warn(f"trigger {self.triggers[i].name!r}: its {action_key(action)} action names "
                         f"{gone}, removed from the simulation: skipped; the others go on")
                continue
            try:
                self._do(sim, action)
            except EcsAnimError as exc:
                sim.warn(f"trigger {self.triggers[i].name!r}: {exc}; the others go on")

    def _gone(self, sim: Simulation, action: Action) -> str:
        """What ``action`` names that is no longer in the simulation ('' if nothing)."""
        gone = [f"character {self._removed_names.get(e, f'with entity id {e}')!r}"
                for e in entities_named(action) if not np.any(sim.store.entity == e)]
        gone += [f"constraint id {u}" for u in constraints_named(action)
                 if not np.isin(u, sim.constraints.uid)]
        return listed(gone)

    def _do(self, sim: Simulation, a: Action) -> None:
        if isinstance(a, Play):
            play_now(sim, a)
            row = sim.row(a.entity)
            name = self._names(sim)[row]
            st = sim.store
            self._grow(int(st.entity.max()) + 1)
            ended = self._seen_clip[a.entity] >= 0 and not self._seen_ended[a.entity]
            previous = int(self._seen_clip[a.entity])
            self._seen_clip[a.entity] = st.clip[row]
            self._seen_time[a.entity] = st.clip_time_s[row]
            self._seen_ended[a.entity] = False
            if ended:
                self._emit(sim, Event("clip_ended", a.entity, name, sim.time_s, sim.tick,
                                      sim.bank.names[previous]))
            self._emit(sim, Event("clip_started", a.entity, name, sim.time_s, sim.tick, a.clip))
        elif isinstance(a, SwitchOn):
            switch_on(sim, a.uid, sim.time_s, a.for_s)
        elif isinstance(a, SwitchOff):
            switch_off(sim, a.uid, sim.time_s)
        elif isinstance(a, MoveTarget):
            sim.set_target(a.uid, a.target_in_world)
            sim.say_unreachable()
        elif isinstance(a, SetBody):
            sim.set_body(a.entity, a.body, blend_s=a.blend_s)
        elif isinstance(a, Remove):
            sim.remove(a.entity)
        elif isinstance(a, Arm):
            armed = self.by_name.get(a.trigger)
            if armed is None:
                raise EcsAnimError(f"no trigger named {quoted(a.trigger)} to arm")
            self.armed[armed] = True
            self.holds[armed] = False  # a condition already holding is an edge now
            self._compiled = None

    # --- compiled conditions, tracks ------------------------------------------------------------

    def _compile(self) -> _Compiled:
        if self._compiled is not None:
            return self._compiled
        c = _Compiled()
        live = [(i, t.when) for i, t in enumerate(self.triggers) if self.armed[i]
                and not self.dropped[i] and (t.repeat or not self.fired[i])]
        near = [(i, w) for i, w in live if isinstance(w, Near)]
        if near:
            c.near = np.array([i for i, _ in near], np.int64)
            c.near_entities = np.array([(w.entity, w.other) for _, w in near], np.int64)
            c.near_segments = np.array([(w.point.segment, w.other_point.segment) for _, w in near],
                                       np.int64)
            c.near_fractions = np.array([(w.point.fraction, w.other_point.fraction)
                                         for _, w in near])
            c.near_offsets = np.array([(w.point.offset_m, w.other_point.offset_m) for _, w in near])
            c.near_within_m = np.array([w.within_m for _, w in near])
        reached = [(i, w) for i, w in live if isinstance(w, Reached)]
        if reached:
            c.reached = np.array([i for i, _ in reached], np.int64)
            c.reached_uids = np.array([w.uid for _, w in reached], np.int64)
            c.reached_within = np.array([w.within_m for _, w in reached])
        for i, w in live:
            key = _listened_as(w)
            if key is not None:
                c.listeners.setdefault(key, []).append(i)
        timed = [(i, w) for i, w in live if isinstance(w, AtTime)]
        if timed:
            c.timed = np.array([i for i, _ in timed], np.int64)
            c.timed_at_s = np.array([w.time_s for _, w in timed])
        self._compiled = c
        return c

    def _set_track_targets(self, sim: Simulation, now: float) -> None:
        """Every moving target at ``now``, interpolated for all tracks at once."""
        uids = np.array([k.uid for k in self.tracks], np.int64)
        most = max(len(k.times_s) for k in self.tracks)
        times = np.full((len(self.tracks), most), np.inf)
        points = np.zeros((len(self.tracks), most, 3))
        for j, k in enumerate(self.tracks):
            times[j, :len(k.times_s)] = k.times_s
            points[j, :len(k.times_s)] = k.points_m
            points[j, len(k.times_s):] = k.points_m[-1]
        sim.set_targets(uids, interpolate_keyframes(times, points, now))


# --- what the actions do ------------------------------------------------------------------------


def action_key(action: Action) -> str:
    """An action's name as a scenario's ``then:`` gives it: ``switch_on`` for :class:`SwitchOn`."""
    return re.sub(r"(?<!^)(?=[A-Z])", "_", type(action).__name__).lower()
