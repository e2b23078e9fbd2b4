"""A simulation: one named esper world, a fixed time step, the schedule, the character store.

Nothing is global: each :class:`Simulation` makes its own esper world (a unique name) and
switches to it only for the duration of its own calls, so two simulations in one process, or
two tests, never see each other's entities.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from typing import Any, Self, TypeVar

import esper
import numpy as np
from numpy.typing import NDArray

from ecs_anim.components import (
    BodyBlend,
    CharacterRow,
    Constraint,
    GroundQuery,
    MotionPlayer,
    Name,
    NormalizedPose,
    Placement,
    Posture,
)
from ecs_anim.core.body_points import body_point
from ecs_anim.core.checks import as_triple, check_value, conforms, found, real_array, real_number
from ecs_anim.core.errors import EcsAnimError, UsageError, did_you_mean, listed, quoted
from ecs_anim.core.ground import Ground, Plane
from ecs_anim.core.morphology import Morphology, leg_length
from ecs_anim.motion.clip import NormalizedMotion, motion_problem
from ecs_anim.motion.constraint_table import (
    TARGET_WORLD,
    Area,
    ConstraintTable,
    Target,
    add_stored,
)
from ecs_anim.motion.constraints import Activation
from ecs_anim.motion.sampling import ClipBank
from ecs_anim.runtime import kernels
from ecs_anim.runtime.actions import check_track, check_trigger
from ecs_anim.runtime.body_change import mass_tables, start_blend
from ecs_anim.runtime.events import Reactions
from ecs_anim.runtime.feasibility import Feasibility, body_lengths, feasibility
from ecs_anim.runtime.recorder import Recorder
from ecs_anim.runtime.steering import DEFAULT_STEERING
from ecs_anim.runtime.steering_api import SteeringCalls
from ecs_anim.runtime.store import MAX_QUEUE, CharacterStore
from ecs_anim.runtime.system_base import System
from ecs_anim.runtime.triggers import Event, TargetTrack, Trigger
from ecs_anim.runtime.update_rate import UpdateRate
from ecs_anim.solver.budget import SolverReport
from ecs_anim.solver.shell import DEFAULT_SETTINGS, SolverSettings
from ecs_anim.systems import HEADLESS, SCHEDULE, ConstraintSolve, PostureConvert

C = TypeVar("C")
#: Defaults: a character at the world origin heading along +x; a constraint always active.
ORIGIN = Placement()
ALWAYS = Activation(0.0, 1e9)

_counter = itertools.count()
#: Run-time warnings (:meth:`Simulation.warn`) go to this logger.
LOG = logging.getLogger("ecs_anim")
#: Placements, speeds and start times beyond this are refused (metres / seconds).
MAX_COORDINATE_M = 1e5
#: The longest time a simulation takes in (s; a day): durations, delays and blends beyond it
#: are refused as typos.
MAX_DURATION_S = 86400.0
#: What a closed simulation answers to any use.
CLOSED = "this simulation is closed (close() or the end of its with block deleted its world)"


class Simulation(SteeringCalls):
    """Characters playing normalized motions on a ground, stepped at a fixed rate.

    Parameters
    ----------
    motions : name -> motion, the clips characters may play.
    ground : the ground (default: the plane z = 0).
    fps : simulation ticks per second.
    window : also schedule Render (a viewer sets ``renderer``).
    vertebrae : if > 0, PostureConvert also resamples each spine into this many vertebra joints
        (``store.vertebrae``, (n, vertebrae, 3)) for output skeletons with more spine joints.
    rotations : PostureConvert also gives local joint rotations (``store.local_rotations``),
        which BVH export and skinned rendering need; positions alone cost about half as much.
    solver_settings : the constraint solver's iterations and tolerances
        (:class:`ecs_anim.solver.shell.SolverSettings`).
    """

    def __init__(self, motions: dict[str, NormalizedMotion], ground: Ground | None = None,
                 fps: float = 30.0, window: bool = False, vertebrae: int = 0,
                 rotations: bool = False, solver_settings: SolverSettings = DEFAULT_SETTINGS):
        if not motions:
            raise EcsAnimError("a simulation needs at least one motion")
        for name, motion in motions.items():
            problem = motion_problem(motion)
            if problem:
                raise EcsAnimError(f"motion {quoted(name)}: {problem}")
        if not (np.isfinite(fps) and fps > 0):
            raise EcsAnimError(f"fps must be a positive number, got {fps}")
        self.world = f"ecs_anim-{next(_counter)}-{id(self):x}"
        self.closed = False
        if vertebrae < 0:
            raise EcsAnimError(f"vertebrae must be >= 0, got {vertebrae}")
        self.vertebrae = int(vertebrae)
        self.rotations = bool(rotations)
        self.dt = 1.0 / fps
        self.fps = fps
        self.tick = 0
        self.bank = ClipBank.from_motions(motions)
        self.motions = dict(motions)
        self.store = CharacterStore()
        #: Bumped by every structural change (a character spawned or removed, a component
        #: added, replaced or removed): the systems' cached rows are recomputed when it moves.
        self.structure_version = 0
        #: The grounds characters stand on: [0] the environment's, then characters' own.
        self.grounds: list[Ground] = [ground or Plane()]
        self.constraints = ConstraintTable()
        self.solver_settings = solver_settings
        self.steering_settings = DEFAULT_STEERING  # ecs_anim.runtime.steering.SteeringSettings
        self.renderer: object | None = None
        self.tables: tuple[Any, ...] = ()  # props for a renderer (scenario ``tables``); never simulated
        self.messages: list[str] = []
        #: The constraints the last feasibility estimate found out of reach (ids; None: none
        #: made yet).
        self._unreachable: frozenset[int] | None = None
        #: What each constraint's last estimate depended on: (their ids, :meth:`_reach_keys`).
        self._estimated: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None
        #: Triggers, moving targets and the last tick's events (:mod:`ecs_anim.runtime.events`).
        self.reactions = Reactions()
        #: The recorders collecting each tick (:meth:`record`), in the order made.
        self.recorders: list[Recorder] = []
        #: Every how many ticks each character is played, grounded and posed: every tick but
        #: under a frame budget that cannot hold otherwise (:mod:`ecs_anim.runtime.update_rate`).
        self.update_rate = UpdateRate()
        #: Whether the systems tick on the compiled kernels (every one in memory before the
        #: first tick: no tick loads one); False while they compile aside on a first run
        #: (``kernels.compile_aside``): the systems run their numpy references, and
        #: :meth:`step` switches to the kernels between two ticks once they are in the cache.
        self.compiled = kernels.load_kernels()
        schedule = SCHEDULE if window else HEADLESS
        self.systems: list[System] = []
        with self._active():
            self._environment = esper.create_entity(GroundQuery(self.grounds[0]))
            for order, cls in enumerate(schedule):
                system = cls(self)
                # esper runs higher priorities first: derive them from the declared order.
                esper.add_processor(system, priority=len(schedule) - order)
                self.systems.append(system)

    @property
    def time_s(self) -> float:
        """Simulated time of the posture the next :meth:`step` produces (s)."""
        return self.tick * self.dt

    @property
    def posture_time_s(self) -> float:
        """Simulated time of the posture now in the store: the last tick stepped (s)."""
        return max(self.tick - 1, 0) * self.dt

    @property
    def ground(self) -> Ground:
        """The ground, from the environment entity's GroundQuery component."""
        with self._active():
            query: GroundQuery = esper.component_for_entity(self._environment, GroundQuery)
        return query.ground

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check_open(self) -> None:
        """Raise :class:`UsageError` if :meth:`close` deleted this simulation's world."""
        if self.closed:
            raise UsageError(CLOSED)

    @contextmanager
    def _active(self) -> Iterator[None]:
        self._check_open()
        previous = esper.current_world
        esper.switch_world(self.world)
        try:
            yield
        finally:
            esper.switch_world(previous)

    def close(self) -> None:
        """Delete this simulation's esper world; any later use raises :class:`UsageError` (closing
        again does nothing)."""
        self.closed = True
        if self.world in esper.list_worlds():
            if esper.current_world == self.world:
                esper.switch_world("default")
            esper.delete_world(self.world)

    # --- characters -------------------------------------------------------------------------

    def spawn(self, name: str, body: Morphology, player: MotionPlayer,
              placement: Placement = ORIGIN, team: str = "", com_control: bool = True,
              com_target_xy: tuple[float, float] | None = None,
              ground: Ground | None = None) -> int:
        """Add a character; returns its entity. Validates at the boundary (not in the tick).

        ``com_control``: the solver moves the root to keep the centre of mass where the motion
        has it, or over ``com_target_xy`` (world metres) when given. ``ground``: a ground of
        the character's own (default: the environment's). Many at once: :meth:`spawn_many`."""
        return int(self.spawn_many([name], [body], [player], [placement], [team], [com_control],
                                   [com_target_xy], [ground])[0])

    def spawn_many(self, names: Sequence[str], bodies: Sequence[Morphology],
                   players: Sequence[MotionPlayer], placements: Sequence[Placement] | None = None,
                   teams: Sequence[str] | None = None, com_control: Sequence[bool] | None = None,
                   com_target_xy: Sequence[tuple[float, float] | None] | None = None,
                   grounds: Sequence[Ground | None] | None = None) -> NDArray[np.int64]:
        """Add many characters at once (one store append, one structural change); the
        arguments are :meth:`spawn`'s, one per character (``None``: every character the
        default). Returns their entities (k,). All are validated before any is added (but a
        malformed constraint stored with a clip is reported once they are, naming it)."""
        self._check_open()
        for what, given_list in (("names", names), ("bodies", bodies), ("players", players)):
            if isinstance(given_list, (str, bytes)) or not isinstance(given_list, (Sequence,
                                                                                   np.ndarray)):
                raise UsageError(f"spawn_many: {what} must be a list, got {found(given_list)}")
        k = len(names)
        if k == 0:
            return np.zeros(0, np.int64)
        placements = placements if placements is not None else [Placement()] * k
        teams = teams if teams is not None else [""] * k
        com_control = com_control if com_control is not None else [True] * k
        com_target_xy = com_target_xy if com_target_xy is not None else [None] * k
        grounds = grounds if grounds is not None else [None] * k
        given = (bodies, players, placements, teams, com_control, com_target_xy, grounds)
        if any(isinstance(g, (str, bytes)) or not isinstance(g, (Sequence, np.ndarray))
               for g in given):
            raise UsageError("spawn_many: bodies, players, placements, teams, com_control, "
                             "com_target_xy and grounds must be lists, one item per name")
        if any(len(g) != k for g in given):
            raise EcsAnimError(f"spawn_many: {k} names but {[len(g) for g in given]} bodies, "
                               "players, placements, teams, com_control, com_target_xy, grounds")
        hints: tuple[Any, ...] = (Morphology, MotionPlayer, Placement, str, bool,
                                  tuple[float, float] | None, Ground | None)
        for i, name in enumerate(names):
            check_value(name, str, f"character {i}: name")
            for what, items, hint in zip(("body", "player", "placement", "team", "com_control",
                                          "com_target_xy", "ground"), given, hints, strict=True):
                check_value(items[i], hint, f"character {quoted(name)}: {what}")
        queue_clip = np.zeros((k, MAX_QUEUE), np.int64)
        queue_fade, queue_loop = np.zeros((k, MAX_QUEUE)), np.zeros((k, MAX_QUEUE), bool)
        clip, queue_len = np.zeros(k, np.int64), np.zeros(k, np.int64)
        for i, (name, player) in enumerate(zip(names, players, strict=True)):
            try:
                clip[i] = self.bank.index(player.clip)
                queue = [self.bank.index(q.clip) for q in player.queue]
            except KeyError as exc:
                raise EcsAnimError(f"character {name!r}: {exc.args[0]}") from None
            if len(queue) > MAX_QUEUE:
                raise EcsAnimError(f"character {name!r}: at most {MAX_QUEUE} queued clips, "
                                   f"got {len(queue)}")
            queue_len[i] = len(queue)
            for j, q in enumerate(player.queue):
                queue_clip[i, j], queue_fade[i, j], queue_loop[i, j] = (
                    queue[j], max(q.crossfade_s, 0.0), q.loop)
        xy = np.array([p.position_m for p in placements], dtype=np.float64).reshape(k, 2)
        heading = np.array([p.heading_rad for p in placements], dtype=np.float64)
        speed = np.array([p.speed for p in players], dtype=np.float64)
        start = np.array([p.start_s for p in players], dtype=np.float64)
        target = np.array([t if t is not None else (np.nan, np.nan) for t in com_target_xy],
                          dtype=np.float64).reshape(k, 2)
        given_target = np.array([t is not None for t in com_target_xy], bool)
        values = np.concatenate([xy, heading[:, None], speed[:, None], start[:, None],
                                 np.where(given_target[:, None], target, 0.0)], 1)
        bad = ~np.all(np.isfinite(values) & (np.abs(values) <= MAX_COORDINATE_M), axis=1)
        if bad.any():
            raise EcsAnimError(f"character {names[int(np.argmax(bad))]!r}: placement, speed and "
                               f"start must be finite and within {MAX_COORDINATE_M:g}")
        known = list(self.grounds)  # grown here, kept only once every check has passed
        ground_index = np.array([self._ground_slot(g, known) for g in grounds], np.int64)
        ground_ref = np.zeros(k)
        for slot in np.unique(ground_index):
            mine = ground_index == slot
            ground_ref[mine] = self._ground_heights(known[slot], xy[mine], "ground")
        masses, fractions = mass_tables(list(bodies))
        self.grounds[:] = known
        store = self.store
        first = store.n
        with self._active():
            entities = np.array([esper.create_entity() for _ in range(k)], np.int64)
            store.add_rows(
                k, entity=entities, lengths=np.array([b.lengths for b in bodies]).reshape(k, -1),
                clip=clip, clip_time_s=start, speed=speed,
                loop=np.array([p.loop for p in players], bool), placement_xy=xy,
                placement_heading=heading, queue_clip=queue_clip, queue_fade_s=queue_fade,
                queue_loop=queue_loop, queue_len=queue_len, ground_ref=ground_ref,
                segment_mass_kg=masses, segment_com_fraction=fractions,
                com_control=np.array(com_control, bool), com_target_xy=target,
                com_error_m=np.nan, ground_index=ground_index, gait_clip=-1, sole_roll=0.5)
            for i in range(k):
                entity = int(entities[i])
                esper.add_component(entity, Name(names[i], teams[i]))
                esper.add_component(entity, bodies[i])
                esper.add_component(entity, players[i])
                esper.add_component(entity, placements[i])
                esper.add_component(entity, CharacterRow(first + i))
                ground = grounds[i]
                if ground is not None:
                    esper.add_component(entity, GroundQuery(ground))
        self.structure_version += 1
        for i, player in enumerate(players):
            clips = [player.clip] + [q.clip for q in player.queue]
            if any(spec.kind != "foot_contact" for c in clips for spec in self.motions[c].constraints):
                self._add_motion_constraints(int(entities[i]), names[i], clips)
        return entities

    def _ground_slot(self, ground: Ground | None, grounds: list[Ground]) -> int:
        """The index of ``ground`` in ``grounds`` (:attr:`grounds` or a copy; 0: the
        environment's), appended to it if new."""
        if ground is None:
            return 0
        for slot, known in enumerate(grounds):
            if known is ground:
                return slot
        grounds.append(ground)
        return len(grounds) - 1

    @staticmethod
    def _ground_heights(ground: Ground, xy: NDArray[np.float64], what: str) -> NDArray[np.float64]:
        """``ground.height(xy)`` (k,) for points ``xy`` (k, 2), checked: a ground answering
        something else than k finite heights is refused (UsageError) before it is used."""
        heights = np.asarray(ground.height(xy))
        if heights.shape != xy.shape[:-1] or heights.dtype.kind not in "iuf" \
                or not np.all(np.isfinite(heights)):
            raise UsageError(f"{what}: {type(ground).__name__}.height must give one finite height "
                             f"per point, gave {found(heights)}")
        return heights.astype(np.float64)

    def _add_motion_constraints(self, entity: int, name: str, clips: list[str]) -> None:
        """The constraints stored with each clip a character plays (other than foot contacts,
        which ground adaptation keeps), active in that clip's own time while it plays."""
        for clip in dict.fromkeys(clips):
            for spec in self.motions[clip].constraints:
                if spec.kind == "foot_contact":
                    continue
                full = f"{name}/{clip}/{spec.name}"
                try:
                    uid = add_stored(self.constraints, self.row(entity), spec, full,
                                     clock=self.bank.index(clip))
                except ValueError as exc:
                    raise EcsAnimError(f"motion {clip!r}: {exc}") from None
                self._constraint_added(entity, uid, full)

    def _constraint_added(self, entity: int, uid: int, name: str) -> None:
        """Replace the character's Constraint component by one with this constraint too."""
        with self._active():
            current = esper.try_component(entity, Constraint) or Constraint((), ())
            esper.add_component(entity, Constraint(current.uids + (uid,), current.names + (name,)))
        self.structure_version += 1

    def _update_constraint_components(self) -> None:
        """Give every character its Constraint component from the table (its uids and names),
        or take it away when it has none left; a structural change when one changed."""
        table = self.constraints
        mine: dict[int, tuple[list[int], list[str]]] = {}
        for k in range(table.m):
            uids, names = mine.setdefault(int(table.owner[k]), ([], []))
            uids.append(int(table.uid[k]))
            names.append(table.names[k])
        changed = False
        with self._active():
            for entity, handle in esper.get_component(CharacterRow):
                uids, names = mine.get(handle.row, ([], []))
                wanted = Constraint(tuple(uids), tuple(names)) if uids else None
                current = esper.try_component(entity, Constraint)
                if current == wanted or current is None:  # None: taken away (remove_component)
                    continue
                changed = True
                if wanted is None:
                    esper.remove_component(entity, Constraint)
                else:
                    esper.add_component(entity, wanted)
        if changed:
            self.structure_version += 1

    def row(self, entity: int) -> int:
        """The character's row in :attr:`store` (``store.positions[row]``); rows move down when a
        character before it is removed, entities do not."""
        with self._active():
            try:
                handle: CharacterRow = esper.component_for_entity(entity, CharacterRow)
                return handle.row
            except KeyError:
                raise EcsAnimError(f"no character with entity id {entity!r} in this simulation") from None

    def rows_with(self, *components: type) -> NDArray[np.int64]:
        """(r,) sorted store rows of the characters that have every one of ``components``
        (an esper query; systems cache it per :attr:`structure_version`)."""
        with self._active():
            rows = [handle.row for _, (handle, *_) in esper.get_components(CharacterRow, *components)]
        return np.sort(np.array(rows, dtype=np.int64))

    def rows_and_components(self, component: type[C]) -> tuple[NDArray[np.int64], list[C]]:
        """The store rows of the characters having ``component`` (sorted) and their components."""
        with self._active():
            found = sorted((handle.row, c) for _, (handle, c) in
                           esper.get_components(CharacterRow, component))
        return np.array([r for r, _ in found], dtype=np.int64), [c for _, c in found]

    # --- components and systems of the user's own (esper's API, on this simulation's world) ---

    def add_component(self, entity: int, component: object) -> None:
        """Give a character ``component`` (replacing its component of the same type): a
        structural change, so every system's rows follow from the next tick. A component of the
        user's own type is read by the user's own systems (:meth:`add_system`)."""
        self.row(entity)
        if isinstance(component, type):
            raise EcsAnimError(f"add_component: expected a component object, found the class "
                               f"{component.__name__} (call it: {component.__name__}(...))")
        if isinstance(component, (CharacterRow, Name)):
            raise EcsAnimError(f"add_component: {type(component).__name__} is the simulation's own "
                               "(spawn and remove set it)")
        if type(component).__module__ == "builtins":
            raise UsageError(f"add_component: expected a component object (an instance of a class "
                             f"of its own, e.g. a dataclass), got {found(component)}")
        if isinstance(component, (GroundQuery, MotionPlayer, Placement)):
            check_value(component, type(component), "add_component")
        with self._active():
            esper.add_component(entity, component)
        self.structure_version += 1

    def remove_component(self, entity: int, component_type: type) -> None:
        """Take a character's component of ``component_type`` away: the systems whose query
        needs it leave the character out from the next tick (without a ``MotionPlayer`` it
        plays nothing and holds its pose; without a ``Constraint`` it is not solved)."""
        self.row(entity)
        if not isinstance(component_type, type):
            raise UsageError(f"remove_component: expected a component type (a class), got "
                             f"{found(component_type)}")
        if component_type in (CharacterRow, Name):
            raise EcsAnimError(f"remove_component: {component_type.__name__} is the simulation's "
                               "own (use remove to take a character out)")
        with self._active():
            if not esper.has_component(entity, component_type):
                raise EcsAnimError(f"remove_component: this character has no "
                                   f"{component_type.__name__} component")
            esper.remove_component(entity, component_type)
        self.structure_version += 1

    def component(self, entity: int, component_type: type[C]) -> C | None:
        """The character's component of ``component_type``, or None when it has none."""
        self.row(entity)
        with self._active():
            return esper.try_component(entity, component_type)

    def query(self, *component_types: type) -> list[tuple[int, tuple[Any, ...]]]:
        """The characters having every one of ``component_types``, in store row order:
        ``[(entity, (component, ...)), ...]`` (esper's ``get_components``)."""
        if not component_types:
            raise EcsAnimError("query: name at least one component type")
        found: list[tuple[int, int, tuple[Any, ...]]] = []
        with self._active():
            every: list[tuple[int, Any]] = esper.get_components(CharacterRow, *component_types)
            for entity, components in every:
                found.append((components[0].row, entity, tuple(components[1:])))
        return [(entity, components) for _, entity, components in sorted(found, key=lambda f: f[0])]

    def add_system(self, system: type[System], *, after: type[System] | None = None,
                   before: type[System] | None = None) -> System:
        """Put a system of the user's own (a :class:`~ecs_anim.runtime.system_base.System`
        subclass: its ``query``, ``reads``, ``writes`` and ``run``) into the schedule, right
        after the system of type ``after`` or right before ``before`` (default: after
        PostureConvert, before Render, where the tick's posture is complete). Returns the
        system made for this simulation; ``sim.systems`` is the schedule in order."""
        if not (isinstance(system, type) and issubclass(system, System)):
            raise UsageError(f"add_system: expected a System subclass, found {system!r}")
        self._check_open()
        for what, declared, hint in (("query", system.query, tuple[type, ...]),
                                     ("reads", system.reads, tuple[str, ...]),
                                     ("writes", system.writes, tuple[str, ...])):
            if not conforms(declared, hint):
                raise UsageError(f"add_system: {system.__name__}.{what} must be a tuple of "
                                 f"{'component types' if what == 'query' else 'store field names'}"
                                 f", got {found(declared)}")
        if not all(callable(hook) for hook in system.on_structure_change):
            raise UsageError(f"add_system: {system.__name__}.on_structure_change must hold functions")
        for what, anchor_given in (("after", after), ("before", before)):
            if anchor_given is not None and not isinstance(anchor_given, type):
                raise UsageError(f"add_system: {what} must be a System class of the schedule, got "
                                 f"{found(anchor_given)}")
        if after is not None and before is not None:
            raise EcsAnimError("add_system: give after or before, not both")
        kinds = [type(s) for s in self.systems]
        if system in kinds:
            raise EcsAnimError(f"add_system: {system.__name__} is in the schedule already")
        anchor = after if after is not None else before
        if anchor is None:
            anchor, after = PostureConvert, PostureConvert
        if anchor not in kinds:
            names = [k.__name__ for k in kinds]
            raise EcsAnimError(f"add_system: {getattr(anchor, '__name__', anchor)!r} is not in this "
                               f"simulation's schedule ({listed(names)})")
        at = kinds.index(anchor) + (1 if after is not None else 0)
        made = system(self)
        self.systems.insert(at, made)
        with self._active():
            for existing in self.systems:
                if existing is not made:
                    esper.remove_processor(type(existing))
            for order, existing in enumerate(self.systems):
                # esper runs higher priorities first: derive them from the declared order.
                esper.add_processor(existing, priority=len(self.systems) - order)
        return made

    def pose(self, entity: int) -> NormalizedPose:
        """A character's normalized pose this tick (views of the store, until the next tick)."""
        row = self.row(entity)
        return NormalizedPose(row, self.store.poses.take(slice(row, row + 1)))

    def posture(self, entity: int) -> Posture:
        """A character's world posture this tick (views of the store, until the next tick)."""
        row, st = self.row(entity), self.store
        return Posture(row, st.positions[row], st.local_rotations[row])

    def body(self, entity: int) -> Morphology:
        """A character's body: its Morphology component, as :meth:`spawn` or :meth:`set_body`
        last gave it (while a blend runs, the body it blends into)."""
        self.row(entity)
        with self._active():
            body: Morphology = esper.component_for_entity(entity, Morphology)
        return body

    def set_body(self, entity: int, body: Morphology, blend_s: float = 0.0) -> None:
        """Replace a character's morphology while it plays (paper §6): its Morphology component.

        It takes effect on the next tick (MorphologyAdapt, :mod:`ecs_anim.runtime.body_change`): the
        character grows or shrinks where it stands. ``blend_s`` 0: at once, its feet re-plant;
        > 0: its segment lengths and masses blend into the new body's over ``blend_s`` seconds
        (a smoothstep), planted feet staying on their footprints (a BodyBlend component)."""
        row = self.row(entity)
        check_value(body, Morphology, "set_body")
        blend_s = real_number(blend_s, "set_body: blend_s")
        if not (np.isfinite(blend_s) and 0.0 <= blend_s <= MAX_DURATION_S):
            raise EcsAnimError(f"blend_s must be a finite number of seconds >= 0, got {blend_s}")
        with self._active():
            if blend_s > 0.0:
                esper.add_component(entity, start_blend(self, row, self.time_s, blend_s))
            elif esper.has_component(entity, BodyBlend):
                esper.remove_component(entity, BodyBlend)
            esper.add_component(entity, body)
        self.structure_version += 1
        table = self.constraints
        if np.any((table.owner == row) | ((table.target_kind != TARGET_WORLD)
                                          & (table.target_row == row))):
            self.say_unreachable()

    def set_ground(self, entity: int, ground: Ground | None) -> None:
        """Give a character a ground of its own (its GroundQuery component), or ``None``: back
        to the environment's. GroundAdapt reads it from the next tick."""
        row = self.row(entity)
        check_value(ground, Ground | None, "set_ground")
        known = list(self.grounds)
        slot = self._ground_slot(ground, known)
        if ground is not None:
            self._ground_heights(ground, self.store.placement_xy[row:row + 1], "set_ground")
        with self._active():
            if ground is None:
                if esper.has_component(entity, GroundQuery):
                    esper.remove_component(entity, GroundQuery)
            else:
                esper.add_component(entity, GroundQuery(ground))
        self.grounds[:] = known
        self.store.ground_index[row] = slot
        self.structure_version += 1

    def remove(self, entity: int) -> None:
        """Take a character out of the simulation (between ticks), with its constraints and
        every constraint of another character aiming at a point on it; one warning names those
        constraints. The other characters go on, and the ids :meth:`add_constraint` returned for
        their constraints stay valid; a removed constraint's id is refused from then on."""
        row = self.row(entity)
        with self._active():
            name = esper.component_for_entity(entity, Name).name
            esper.delete_entity(entity, immediate=True)
            for other, character_row in list(esper.get_component(CharacterRow)):
                if character_row.row > row:
                    esper.add_component(other, CharacterRow(character_row.row - 1))
        self.store.remove_row(row)
        removed = self.constraints.remove_character(row)
        self.structure_version += 1
        self._update_constraint_components()
        if removed:
            self.warn(f"character {name!r} removed with its constraints {listed(removed)}")
        self.reactions.character_removed(self, entity, name)

    # --- looking characters and constraints up by name ----------------------------------------

    def entity(self, name: str) -> int:
        """The entity of the character named ``name`` (as the scenario or :meth:`spawn` named
        it). Raises :class:`EcsAnimError` listing the characters (with the closest name) when
        none is, or when several are (spawn does not require unique names: keep the entities
        it returned then)."""
        names = self.names()
        rows = [row for row, known in enumerate(names) if known == name]
        if not rows:
            raise EcsAnimError(f"no character {quoted(name)} in this simulation (characters: "
                               f"{listed(names) or 'none'}){did_you_mean(name, names)}")
        if len(rows) > 1:
            raise EcsAnimError(f"{len(rows)} characters are named {quoted(name)}: use the entities "
                               "spawn returned")
        return int(self.store.entity[rows[0]])

    def constraint_index(self, entity: int, name: str) -> int:
        """The id of a character's constraint ``name``, for :meth:`set_target`: its name as the
        scenario gives it or :meth:`add_constraint` got it, and ``"<character>/<clip>/<name>"``
        for one stored with a clip it plays. Names are unique per character (add_constraint
        refuses a second one), so ``(entity, name)`` is one constraint; an unknown name raises
        :class:`EcsAnimError` listing the character's constraints, with the closest name."""
        row = self.row(entity)
        table = self.constraints
        mine = np.flatnonzero(table.owner == row)
        names = [table.names[k] for k in mine]
        if name not in names:
            raise EcsAnimError(f"no constraint {quoted(name)} on this character (it has: "
                               f"{listed(names) or 'none'}){did_you_mean(name, names)}")
        return int(table.uid[mine[names.index(name)]])

    def names(self) -> list[str]:
        """Every character's name, in store row order (``names()[i]`` is row ``i`` of
        :attr:`store`, e.g. ``store.positions[i]``)."""
        with self._active():
            by_row = {r.row: n.name for _, (r, n) in esper.get_components(CharacterRow, Name)}
        return [by_row[i] for i in range(self.store.n)]

    def leg_length(self) -> NDArray[np.float64]:
        """(n,) each character's leg length (mean thigh + shank), metres."""
        return leg_length(self.store.lengths)

    def add_constraint(self, entity: int, name: str, point: str, priority: float = 0.0,
                       activation: Activation = ALWAYS,
                       target_in_world: tuple[float, float, float] | None = None,
                       target_entity: int | None = None, target_point: str | None = None, *,
                       kind: str = "position", chain: tuple[str, ...] | None = None,
                       fraction: float | None = None,
                       offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
                       target_fraction: float | None = None,
                       target_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
                       distance_m: float = 0.0, area: Area | None = None,
                       axis: tuple[float, float, float] = (0.0, 0.0, 1.0), clock: int = -1) -> int:
        """Constrain a point of a character to a world point or to a body point of a character
        (another one, read from its previous posture every tick, or itself).

        ``point`` / ``target_point``: a joint (``"wrist_r"``) or a segment (``"forearm_r"``)
        with ``fraction`` along it and ``offset_m`` in its frame (:mod:`ecs_anim.core.body_points`).
        ``kind``: position, distance (``distance_m``), area (``area``, placed at the target),
        orientation (``axis`` of the segment along the world direction ``target_in_world``, or
        looking at the target point). ``chain``: the groups allowed to move (default the
        point's own). Returns its id for :meth:`set_target`. Validated here, never in the
        tick; errors are :class:`EcsAnimError` naming the constraint."""
        check_value(name, str, "add_constraint: name")
        table, row = self.constraints, self.row(entity)
        for what, value, hint in (("point", point, str), ("kind", kind, str),
                                  ("target_point", target_point, str | None),
                                  ("target_entity", target_entity, int | None),
                                  ("fraction", fraction, float | None),
                                  ("target_fraction", target_fraction, float | None),
                                  ("activation", activation, Activation),
                                  ("area", area, Area | None), ("clock", clock, int)):
            check_value(value, hint, f"constraint {quoted(name)}: {what}")
        world = None if target_in_world is None else real_array(
            target_in_world, (3,), f"constraint {quoted(name)}: target_in_world")
        if not np.isfinite(real_number(priority, f"constraint {quoted(name)}: priority")) or \
                (world is not None and not np.all(np.isfinite(world))):
            raise EcsAnimError(f"constraint {name!r}: priority and target must be finite")
        offsets = [real_array(v, (3,), f"constraint {quoted(name)}: {what}") for what, v in
                   (("offset_m", offset_m), ("target_offset_m", target_offset_m))]
        if any(table.names[k] == name for k in np.flatnonzero(table.owner == row)):
            raise EcsAnimError(f"constraint {quoted(name)}: this character has one of that name "
                               "already (constraint_index finds constraints by name)")
        try:
            body = body_point(point, fraction, as_triple(offsets[0]), segment=kind == "orientation")
            if target_entity is not None:
                target = Target(row=self.row(target_entity),
                                point=body_point(target_point or "", target_fraction,
                                                 as_triple(offsets[1]), as_target=True))
            else:
                target = Target(world_m=None if world is None else as_triple(world))
            uid = self.constraints.add(name, self.row(entity), kind, body, target, priority,
                                       activation, chain, distance_m, area, axis, clock)
        except ValueError as exc:
            message = str(exc)
            if not message.startswith("constraint "):
                message = f"constraint {name!r}: {message}"
            raise UsageError(message) from None
        self._constraint_added(entity, uid, name)
        return uid

    def set_target(self, uid: int, target_in_world: tuple[float, float, float]) -> None:
        """Move a constraint's target (its id from :meth:`add_constraint` or
        :meth:`constraint_index`) from code; a target that is not finite or beyond 1,000 km
        disables it at the next tick (with a warning) rather than reaching a pose."""
        check_value(uid, int, "set_target: uid")
        self.set_targets(np.array([uid], np.int64),
                         real_array(target_in_world, (3,), "set_target: target_in_world")[None])

    def set_targets(self, uids: NDArray[np.int64], targets_in_world: NDArray[np.float64]) -> None:
        """Move many constraints' targets at once: ``uids`` (k,) ids, ``targets_in_world`` (k, 3).
        Anything else (other shapes, texts) is refused with nothing moved."""
        self._check_open()
        try:
            self.constraints.set_targets(uids, targets_in_world)
        except ValueError as exc:
            raise UsageError(str(exc)) from None

    def warn(self, message: str) -> None:
        """A run-time warning: ``"warning: t=<s> s: <message>"`` kept in :attr:`messages` and
        logged (level WARNING) to the ``ecs_anim`` logger, which prints it on stderr unless the
        application configured logging otherwise (the command line prints the line alone)."""
        line = f"warning: t={self.time_s:.3f} s: {message}"
        self.messages.append(line)
        LOG.warning(line)

    def report_disabled(self, indices: NDArray[np.int64]) -> None:
        """Warn once (:meth:`warn`) for each constraint switched off this tick for a target that
        is not finite or beyond 1,000 km (:data:`ecs_anim.solver.shell.MAX_TARGET_M`): ``indices``
        (k,) rows of :attr:`constraints`. A new target (:meth:`set_target`) switches it on."""
        for i in indices:
            self.warn(f"constraint {self.constraints.names[int(i)]!r} has a target that is not "
                      "finite or beyond 1,000 km and is switched off until a new target is set; "
                      "the others go on")

    def report_frozen(self, rows: NDArray[np.int64]) -> None:
        """A character's pose went non-finite: it keeps its last good posture until its pose is
        finite again; say so once."""
        names = self.names()
        for r in rows:
            self.warn(f"character {names[int(r)]!r} got a non-finite pose and holds its last "
                      "good posture until its pose is finite again; the others go on")

    # --- feasibility (ecs_anim.runtime.feasibility) -------------------------------------------

    def feasibility(self) -> list[Feasibility]:
        """Whether each constraint's body can reach its target at all, estimated now from the
        bodies, their stances and clips, and the ground (:mod:`ecs_anim.runtime.feasibility`):
        one :class:`~ecs_anim.runtime.feasibility.Feasibility` per constraint, in the order
        they were added; ``.line`` says it in one line, ``.reachable`` whether it can."""
        self._check_open()
        estimates = feasibility(self)
        self._unreachable = frozenset(f.uid for f in estimates if not f.reachable)
        self._estimated = (self.constraints.uid.copy(), self._reach_keys())
        return estimates

    def unreachable(self) -> frozenset[int]:
        """The ids of the constraints the last estimate (:meth:`feasibility`, made now if none
        was) found out of reach: what the viewer marks."""
        if self._unreachable is None:
            self.feasibility()
        return self._unreachable or frozenset()

    def say_unreachable(self) -> None:
        """Estimate again the constraints whose target, point or bodies changed since the last
        estimate (:meth:`_reach_keys`; every one when none was made) and warn (:meth:`warn`)
        once for each that is out of reach now and was not then: after a body change
        (:meth:`set_body`) or a target a trigger moves (``MoveTarget``). The others keep their
        last estimate (a full one cost 18 ms at the fight's 16 constraints; one constraint
        with a world target, its character's poses alone)."""
        table = self.constraints
        keys = self._reach_keys()
        again = np.arange(table.m)
        if self._estimated is not None and self._unreachable is not None:
            uid, before = self._estimated
            at = np.minimum(np.searchsorted(uid, table.uid), max(uid.size - 1, 0))
            kept = np.zeros(table.m, bool)
            if uid.size:
                same = (keys == before[at]) | (np.isnan(keys) & np.isnan(before[at]))
                kept = (uid[at] == table.uid) & same.all(axis=1)
            again = np.flatnonzero(~kept)
        known = self._unreachable or frozenset()
        estimates = feasibility(self, again)
        for estimate in estimates:
            if not estimate.reachable and estimate.uid not in known:
                self.warn(estimate.line)
        # Those not estimated again keep theirs; a constraint removed since is gone.
        kept_uids = np.delete(table.uid, again)
        before = np.fromiter(known, np.int64, len(known))
        self._unreachable = frozenset(before[np.isin(before, kept_uids)].tolist()) \
            | {f.uid for f in estimates if not f.reachable}
        self._estimated = (table.uid.copy(), keys)

    def _reach_keys(self) -> NDArray[np.float64]:
        """(m, K) what each constraint's estimate depends on but the clock: its row of the
        table (point, chain, clock and activation, target, distance, area) and the lengths of
        its own and its target's bodies (their Morphology components, as the estimate takes
        them). :meth:`say_unreachable` estimates again the rows that differ."""
        table = self.constraints
        lengths = body_lengths(self)
        target_row = np.where(table.target_kind != TARGET_WORLD, table.target_row, table.owner)
        columns = [table.owner, table.kind, table.segment, table.fraction, table.offset,
                   table.chain, table.clock, table.activation, table.target_kind,
                   table.target_world, target_row, table.target_segment, table.target_fraction,
                   table.target_offset, table.distance_m, table.area_shape, table.area_low,
                   table.area_high, table.area_radius, table.area_inside,
                   lengths[table.owner], lengths[target_row]]
        keys: NDArray[np.float64] = np.column_stack(columns).astype(np.float64)
        return keys

    # --- events and triggers (ecs_anim.runtime.events) -----------------------------------------------

    def events(self) -> list[Event]:
        """What happened in the last :meth:`step` (edges: clips started and ended, foot contacts
        begun, characters removed, triggers' conditions met), in order; also those between it and
        the step before (a character removed from code)."""
        return self.reactions.events

    def add_trigger(self, trigger: Trigger) -> int:
        """Add a trigger (:class:`ecs_anim.runtime.triggers.Trigger`): ``when`` its condition begins to
        hold, its actions run (``delay_s`` later). Everything it names is checked here; returns
        its index."""
        self._check_open()
        check_value(trigger, Trigger, "add_trigger")
        check_trigger(self, trigger)
        return self.reactions.add(trigger)

    def add_target_track(self, uid: int, times_s: Sequence[float],
                         points_m: Sequence[tuple[float, float, float]]) -> None:
        """Move the constraint ``uid``'s world target along keyframes: at ``times_s`` (k,)
        (increasing, simulation seconds) it is at ``points_m`` (k, 3), linearly interpolated
        between them, held before the first and after the last; set before every tick."""
        self._check_open()
        check_value(uid, int, "add_target_track: uid")
        times = real_array(times_s, (None,), "add_target_track: times_s")
        points = real_array(points_m, (times.shape[0], 3), "add_target_track: points_m")
        track = TargetTrack(int(uid), tuple(float(t) for t in times),
                            tuple(as_triple(p) for p in points))
        check_track(self, track)
        self.reactions.tracks.append(track)

    # --- running ----------------------------------------------------------------------------

    def step(self) -> None:
        """Advance one fixed tick through the schedule (``systems``, in order): triggers due,
        clips chosen, played, adapted, solved and converted, then the clock moves and the
        tick's events fire their triggers (DetectEvents)."""
        self._check_open()
        if not self.compiled:
            # Steered characters wait for the kernels: local avoidance has no numpy reference,
            # and a crowd's paths part on the references' 1e-15 differences (docs/performance.md).
            self.compiled = kernels.poll_kernels(wait=bool(np.any(self.store.steer_mode != 0)))
        with self._active():
            esper.process(self.dt)
        for recorder in self.recorders:
            recorder.collect()

    def record(self, entities: Sequence[int] | None = None) -> Recorder:
        """Start recording every tick for export (:class:`~ecs_anim.runtime.recorder.Recorder`):
        each posture from the next :meth:`step` on (joint positions, local rotations, segment
        lengths, planted feet) of the characters ``entities`` (None: every character, those
        spawned later too), followed by entity across removals, and the ticks' events.
        ``rec.save(folder)`` writes what ``ecs-anim run --export`` writes. Turns
        :attr:`rotations` on (BVH and glTF need them)."""
        self._check_open()
        recorder = Recorder(self, entities)
        self.rotations = True
        self.recorders.append(recorder)
        return recorder

    def solver_report(self) -> SolverReport | None:
        """What the constraint solver did in the last tick and what the frame budget
        (``SolverSettings.budget_ms``) cut: :class:`ecs_anim.solver.budget.SolverReport`; None
        before the first tick or when no constraint was solved."""
        for system in self.systems:
            if isinstance(system, ConstraintSolve):
                return system.report
        return None

    def set_solver_focus(self, focus_in_world: Sequence[float] | NDArray[np.float64] | None) -> None:
        """Where the frame budget keeps its iterations longest ((3,) m, world; the viewer gives
        its camera's eye): the characters furthest from it are cut first. None: no focus."""
        focus = None if focus_in_world is None else as_triple(
            real_array(focus_in_world, (3,), "set_solver_focus"))
        try:
            self.solver_settings = replace(self.solver_settings, focus_in_world=focus)
        except ValueError as exc:
            raise EcsAnimError(f"set_solver_focus: {exc}") from None

    def system_seconds(self) -> dict[str, float]:
        """Wall seconds spent in each system so far."""
        return {type(s).__name__: s.seconds for s in self.systems}
