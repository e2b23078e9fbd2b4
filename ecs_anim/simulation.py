"""A simulation: one named esper world, a fixed time step, the schedule, the character store.

Nothing is global: each :class:`Simulation` makes its own esper world (a unique name) and
switches to it only for the duration of its own calls, so two simulations in one process, or
two tests, never see each other's entities.
"""

from __future__ import annotations

import itertools
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import esper
import numpy as np
from numpy.typing import NDArray

from .components import (
    Body,
    CharacterRow,
    GroundQuery,
    MotionPlayer,
    Name,
    NormalizedPose,
    Placement,
    Posture,
)
from .errors import EcsAnimError, listed, quoted
from .ground import Ground, Plane
from .morphology import Morphology, leg_length, segment_mass_table
from .motion import NormalizedMotion, motion_problem
from .playback import ClipBank, _wrap, rotate_xy, sample
from .body_points import body_point
from .solver_shell import DEFAULT_SETTINGS, SolverSettings
from .constraint_table import Area, ConstraintTable, Target, add_stored
from .constraints import Activation
from .store import MAX_QUEUE, CharacterStore
from .system_base import System

_counter = itertools.count()
#: Placements, speeds and start times beyond this are refused (metres / seconds).
MAX_COORDINATE_M = 1e5


class Simulation:
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
    """

    def __init__(self, motions: dict[str, NormalizedMotion], ground: Ground | None = None,
                 fps: float = 30.0, window: bool = False, vertebrae: int = 0,
                 rotations: bool = False, solver_settings: SolverSettings = DEFAULT_SETTINGS):
        from .systems import HEADLESS, SCHEDULE

        if not motions:
            raise EcsAnimError("a simulation needs at least one motion")
        for name, motion in motions.items():
            problem = motion_problem(motion)
            if problem:
                raise EcsAnimError(f"motion {quoted(name)}: {problem}")
        if not (np.isfinite(fps) and fps > 0):
            raise EcsAnimError(f"fps must be a positive number, got {fps}")
        self.world = f"ecs_anim-{next(_counter)}-{id(self):x}"
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
        self.constraints = ConstraintTable()
        self.solver_settings = solver_settings
        self.renderer: object | None = None
        self.tables: tuple[Any, ...] = ()  # props for a renderer (scenario ``tables``); never simulated
        self.messages: list[str] = []
        schedule = SCHEDULE if window else HEADLESS
        self.systems: list[System] = []
        with self._active():
            self._environment = esper.create_entity(GroundQuery(ground or Plane()))
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
            return esper.component_for_entity(self._environment, GroundQuery).ground

    def __enter__(self) -> Simulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def _active(self) -> Iterator[None]:
        previous = esper.current_world
        esper.switch_world(self.world)
        try:
            yield
        finally:
            esper.switch_world(previous)

    def close(self) -> None:
        """Delete this simulation's esper world."""
        if self.world in esper.list_worlds():
            if esper.current_world == self.world:
                esper.switch_world("default")
            esper.delete_world(self.world)

    # --- characters -------------------------------------------------------------------------

    def spawn(self, name: str, body: Morphology, player: MotionPlayer,
              placement: Placement = Placement(), team: str = "", com_control: bool = True,
              com_target_xy: tuple[float, float] | None = None) -> int:
        """Add a character; returns its entity. Validates at the boundary (not in the tick).

        ``com_control``: the solver moves the root to keep the centre of mass where the motion
        has it, or over ``com_target_xy`` (world metres) when given."""
        try:
            clip = self.bank.index(player.clip)
            queue = [self.bank.index(q.clip) for q in player.queue]
        except KeyError as exc:
            raise EcsAnimError(f"character {name!r}: {exc.args[0]}") from None
        if len(queue) > MAX_QUEUE:
            raise EcsAnimError(f"character {name!r}: at most {MAX_QUEUE} queued clips, got {len(queue)}")
        values = (*placement.position_m, placement.heading_rad, player.speed, player.start_s,
                  *(com_target_xy or ()))
        if not all(np.isfinite(v) and abs(v) <= MAX_COORDINATE_M for v in values):
            raise EcsAnimError(f"character {name!r}: placement, speed and start must be finite "
                               f"and within {MAX_COORDINATE_M:g}")
        padded = np.zeros(MAX_QUEUE)
        queue_clip, queue_fade, queue_loop = padded.astype(np.int64), padded.copy(), padded.astype(bool)
        for k, q in enumerate(player.queue):
            queue_clip[k], queue_fade[k], queue_loop[k] = queue[k], max(q.crossfade_s, 0.0), q.loop
        with self._active():
            entity = esper.create_entity()
            row = self.store.add_row(
                entity=entity, lengths=body.lengths, clip=clip, clip_time_s=player.start_s,
                speed=player.speed, loop=player.loop, placement_xy=placement.position_m,
                placement_heading=placement.heading_rad, queue_clip=queue_clip,
                queue_fade_s=queue_fade, queue_loop=queue_loop, queue_len=len(queue),
                ground_ref=float(self.ground.height(np.array(placement.position_m, float))),
                segment_mass_kg=segment_mass_table(body)[0],
                segment_com_fraction=segment_mass_table(body)[1], com_control=com_control,
                com_target_xy=com_target_xy if com_target_xy is not None else (np.nan, np.nan),
                com_error_m=np.nan,
            )
            for component in (Name(name, team), Body(body), player, placement, CharacterRow(row),
                              NormalizedPose(row), Posture(row)):
                esper.add_component(entity, component)
        self._add_motion_constraints(entity, name, [player.clip] + [q.clip for q in player.queue])
        return entity

    def _add_motion_constraints(self, entity: int, name: str, clips: list[str]) -> None:
        """The constraints stored with each clip a character plays (other than foot contacts,
        which ground adaptation keeps), active in that clip's own time while it plays."""
        for clip in dict.fromkeys(clips):
            for spec in self.motions[clip].constraints:
                if spec.kind == "foot_contact":
                    continue
                try:
                    add_stored(self.constraints, self.row(entity), spec, f"{name}/{clip}/{spec.name}",
                               clock=self.bank.index(clip))
                except ValueError as exc:
                    raise EcsAnimError(f"motion {clip!r}: {exc}") from None

    def row(self, entity: int) -> int:
        with self._active():
            try:
                return esper.component_for_entity(entity, CharacterRow).row
            except KeyError:
                raise EcsAnimError(f"no character with entity id {entity!r} in this simulation") from None

    def set_body(self, entity: int, body: Morphology) -> None:
        """Replace a character's morphology while it plays (paper §6).

        The root path is stored in leg lengths, so a new leg length would move the character
        along its path; the placement is shifted so it stays where it is, and its feet re-plant.
        """
        st = self.store
        row = self.row(entity)
        with self._active():
            esper.add_component(entity, Body(body))
        old_leg, new_leg = leg_length(st.lengths[row]), body.leg_length
        if st.poses.root_position.shape[0] == st.n and self.tick > 0:
            for xy, heading in ((st.placement_xy, st.placement_heading),
                                (st.fade_placement_xy, st.fade_placement_heading)):
                world = st.poses.root_position[row, :2] * old_leg
                unplaced = rotate_xy(world - xy[row], -heading[row]) / old_leg
                xy[row] += world - (rotate_xy(unplaced * new_leg, heading[row]) + xy[row])
        st.lengths[row] = body.lengths
        st.segment_mass_kg[row], st.segment_com_fraction[row] = segment_mass_table(body)[:2]
        st.locked[row] = False

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
                    for component in (CharacterRow, NormalizedPose, Posture):
                        esper.add_component(other, component(character_row.row - 1))
        self.store.remove_row(row)
        removed = self.constraints.remove_character(row)
        if removed:
            message = (f"warning: t={self.time_s:.3f} s: character {name!r} removed with its "
                       f"constraints {listed(removed)}")
            self.messages.append(message)
            print(message, file=sys.stderr)

    def constraint_index(self, entity: int, name: str) -> int:
        """The id of the constraint ``name`` of a character (its name as the scenario gives it, or
        as :meth:`add_constraint` got it), for :meth:`set_target`; the first if two share it."""
        row = self.row(entity)
        table = self.constraints
        mine = np.flatnonzero(table.owner == row)
        found = [k for k in mine if table.names[k] == name]
        if not found:
            raise EcsAnimError(f"no constraint {quoted(name)} on this character (it has: "
                               f"{listed(table.names[k] for k in mine) or 'none'})")
        return int(table.uid[found[0]])

    def names(self) -> list[str]:
        with self._active():
            by_row = {r.row: n.name for _, (r, n) in esper.get_components(CharacterRow, Name)}
        return [by_row[i] for i in range(self.store.n)]

    def leg_length(self) -> NDArray[np.float64]:
        """(n,) each character's leg length (mean thigh + shank), metres."""
        return leg_length(self.store.lengths)

    def start_next_clips(self, rows: NDArray[np.int64]) -> None:
        """Begin the next queued clip of these characters (all at once), cross-fading from the
        current one and continuing its root path, heading included. Footprints are released so
        the incoming motion's steps lay new ones."""
        st, bank = self.store, self.bank
        head = st.queue_head[rows]
        new_clip, fade = st.queue_clip[rows, head], st.queue_fade_s[rows, head]
        new_loop = st.queue_loop[rows, head]
        old = sample(bank, st.clip[rows], st.clip_time_s[rows], st.loop[rows])
        new = sample(bank, new_clip, np.zeros(rows.size), new_loop)
        leg = leg_length(st.lengths[rows])[:, None]
        heading = st.placement_heading[rows]
        old_xy = rotate_xy(old.root_position[:, :2] * leg, heading) + st.placement_xy[rows]
        new_heading = _wrap(old.root_heading + heading - new.root_heading)
        st.fade_placement_xy[rows] = st.placement_xy[rows]
        st.fade_placement_heading[rows] = heading
        st.placement_heading[rows] = new_heading
        st.placement_xy[rows] = old_xy - rotate_xy(new.root_position[:, :2] * leg, new_heading)
        st.fade_clip[rows], st.fade_time_s[rows] = st.clip[rows], st.clip_time_s[rows]
        st.fade_loop[rows] = st.loop[rows]
        st.fade_s[rows], st.fade_elapsed_s[rows] = np.maximum(fade, 0.0), 0.0
        st.clip[rows], st.clip_time_s[rows], st.loop[rows] = new_clip, 0.0, new_loop
        st.queue_head[rows] += 1
        st.locked[rows] = False

    def add_constraint(self, entity: int, name: str, point: str, priority: float = 0.0,
                       activation: Activation = Activation(0.0, 1e9),
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
        with ``fraction`` along it and ``offset_m`` in its frame (:mod:`ecs_anim.body_points`).
        ``kind``: position, distance (``distance_m``), area (``area``, placed at the target),
        orientation (``axis`` of the segment along the world direction ``target_in_world``, or
        looking at the target point). ``chain``: the groups allowed to move (default the
        point's own). Returns its id for :meth:`set_target`. Validated here, never in the
        tick; errors are :class:`EcsAnimError` naming the constraint."""
        values = [priority] + list(target_in_world or ())
        if not all(np.isfinite(v) for v in values):
            raise EcsAnimError(f"constraint {name!r}: priority and target must be finite")
        table, row = self.constraints, self.row(entity)
        if any(table.names[k] == name for k in np.flatnonzero(table.owner == row)):
            raise EcsAnimError(f"constraint {quoted(name)}: this character has one of that name "
                               "already (constraint_index finds constraints by name)")
        try:
            body = body_point(point, fraction, offset_m, segment=kind == "orientation")
            if target_entity is not None:
                target = Target(row=self.row(target_entity),
                                point=body_point(target_point or "", target_fraction, target_offset_m,
                                                 as_target=True))
            else:
                target = Target(world_m=target_in_world)
            return self.constraints.add(name, self.row(entity), kind, body, target, priority,
                                        activation, chain, distance_m, area, axis, clock)
        except ValueError as exc:
            message = str(exc)
            if not message.startswith("constraint "):
                message = f"constraint {name!r}: {message}"
            raise EcsAnimError(message) from None

    def set_target(self, uid: int, target_in_world: tuple[float, float, float]) -> None:
        """Move a constraint's target (its id from :meth:`add_constraint` or
        :meth:`constraint_index`) from code; a non-finite target disables it at the next tick
        (with a warning) rather than reaching a pose."""
        self.set_targets(np.array([uid]), np.asarray([target_in_world], dtype=np.float64))

    def set_targets(self, uids: NDArray[np.int64], targets_in_world: NDArray[np.float64]) -> None:
        """Move many constraints' targets at once: ``uids`` (k,) ids, ``targets_in_world`` (k, 3)."""
        try:
            self.constraints.set_targets(uids, targets_in_world)
        except ValueError as exc:
            raise EcsAnimError(str(exc)) from None

    def report_disabled(self, indices: NDArray[np.int64]) -> None:
        for i in indices:
            message = (f"warning: t={self.time_s:.3f} s: constraint "
                       f"{self.constraints.names[int(i)]!r} has a non-finite target and is "
                       "switched off; the others go on")
            self.messages.append(message)
            print(message, file=sys.stderr)

    def report_frozen(self, rows: NDArray[np.int64]) -> None:
        """A character's pose went non-finite: it keeps its last good posture; say so once."""
        names = self.names()
        for r in rows:
            message = (f"warning: t={self.time_s:.3f} s: character {names[int(r)]!r} got a "
                       "non-finite pose and holds its last good posture; the others go on")
            self.messages.append(message)
            print(message, file=sys.stderr)

    # --- running ----------------------------------------------------------------------------

    def step(self) -> None:
        """Advance one fixed tick through the schedule."""
        with self._active():
            esper.process(self.dt)
        self.tick += 1

    def system_seconds(self) -> dict[str, float]:
        """Wall seconds spent in each system so far."""
        return {type(s).__name__: s.seconds for s in self.systems}
